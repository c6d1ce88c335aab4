"""The Inter-M Transformer generator network (InterMask section 3.2).

Shapes: ``B`` batch, ``rows`` body-part rows of a token map (5), ``T'`` token steps (frames / 4),
``N = rows * T'`` tokens per person, ``K`` codebook size, ``D`` width, ``L`` text tokens.
"""

from intermask.interm.model import InterMOutput, InterMTransformer, TextFeatures
from intermask.interm.tokens import Vocabulary, build_sequence, split_sequence

__all__ = [
    "InterMOutput",
    "InterMTransformer",
    "TextFeatures",
    "Vocabulary",
    "build_sequence",
    "split_sequence",
]
