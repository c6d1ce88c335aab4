"""MoMask's generators over residual-VQ tokens (Guo et al. 2024, sections 3.2-3.4).

The masked transformer generates the base layer (layer 0) of 1D motion tokens by iterative
mask-predict; the residual transformer then predicts layers 1..Q-1, one pass per layer. Both are
conditioned on a caption's sentence-level text feature and trained with classifier-free guidance.

Shapes: ``B`` batch, ``T'`` token steps (one per 4 frames), ``Q`` quantizer layers (6 in the
paper), ``K`` codes per layer (512), ``E`` code-embedding width, ``D`` transformer width,
``D_text`` text-feature width. Token maps are ``(B, T')`` per layer, ``(B, Q, T')`` for several
layers, and ``(B, Q, 1, T')`` where they meet :meth:`MotionVQVAE.decode` (one token row); ``-1``
marks padding.
"""

from intermask.momask.model import MaskedTransformer, ResidualTransformer, sentence_features
from intermask.momask.sampler import MoMaskSample, MoMaskSampler, decode_base, decode_residual

__all__ = [
    "MaskedTransformer",
    "MoMaskSample",
    "MoMaskSampler",
    "ResidualTransformer",
    "decode_base",
    "decode_residual",
    "sentence_features",
]
