"""The Inter-M Transformer generator network (InterMask section 3.2).

Shapes: ``B`` batch, ``rows`` body-part rows of a token map (5), ``T'`` token steps (frames / 4),
``N = rows * T'`` tokens per person, ``K`` codebook size, ``D`` width, ``L`` text tokens.
"""

from intermask.interm.decoding import Edit, generate
from intermask.interm.masking import (
    bert_corruption,
    cosine_schedule,
    interaction_masking,
    random_masking,
    step_unroll_mask,
    training_mask,
)
from intermask.interm.model import InterMOutput, InterMTransformer, TextFeatures
from intermask.interm.tokens import Vocabulary, build_sequence, split_sequence

__all__ = [
    "Edit",
    "InterMOutput",
    "InterMTransformer",
    "TextFeatures",
    "Vocabulary",
    "bert_corruption",
    "build_sequence",
    "cosine_schedule",
    "generate",
    "interaction_masking",
    "random_masking",
    "split_sequence",
    "step_unroll_mask",
    "training_mask",
]
