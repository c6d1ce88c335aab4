"""Multi-head attention with key padding, and the three ways Inter-M uses it.

All three are the same :class:`MultiHeadAttention` applied to differently grouped sequences, so
no Python loop runs over persons, rows or time (InterMask section 3.2.2):

* self attention: the whole ``[A, SEP, B]`` sequence (eq. 4);
* spatio-temporal attention: spatial groups are the ``rows`` tokens of one time step, temporal
  groups the ``T'`` tokens of one row (eq. 5); both persons are stacked on the batch axis;
* cross attention: each person's tokens query the other person's tokens, all of them (eq. 7).

Key-padding masks follow ``nn.MultiheadAttention``: True marks a padded key.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch
from einops import rearrange
from torch import nn

from intermask.utils.layers import Attention


class MultiHeadAttention(Attention):
    """:class:`~intermask.utils.layers.Attention` over (G, S, D) groups with an optional
    (G, S_k) key padding, initialised like ``nn.MultiheadAttention`` (the reference's layer).

    Groups whose keys are all padded (a padded time step in spatial attention, an empty clip)
    would give NaN from a softmax over nothing; they attend to every key instead and their
    output is set to zero. Only padded queries are in such groups, so nothing valid changes.
    """

    def __init__(self, *, width: int, heads: int, dropout: float) -> None:
        super().__init__(width=width, heads=heads, dropout=dropout)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        # Xavier-uniform over the packed (3D, D) projection and zero biases, as
        # nn.MultiheadAttention initialises its in-projection.
        width = self.out.in_features
        bound = math.sqrt(6.0 / (width + 3 * width))
        for linear in (self.query, self.key_value):
            nn.init.uniform_(linear.weight, -bound, bound)
            nn.init.zeros_(linear.bias)
        nn.init.zeros_(self.out.bias)

    def forward(
        self,
        x: torch.Tensor,
        context: torch.Tensor | None = None,
        key_padding_mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(G, S_q, D) queries, (G, S_k, D) keys/values (default ``x``) -> (G, S_q, D)."""
        if key_padding_mask is None:
            return super().forward(x, context)
        keep = ~key_padding_mask  # (G, S_k), True = attend (SDPA convention)
        empty = ~keep.any(dim=-1)  # (G,)
        out = super().forward(x, context, (keep | empty[:, None])[:, None, None, :])
        return out.masked_fill(empty[:, None, None], 0.0)


class SpatioTemporalOutput(NamedTuple):
    spatial: torch.Tensor  # (P, rows * T', D) e'_p of eq. 5
    temporal: torch.Tensor  # (P, rows * T', D) e''_p of eq. 5


class SpatioTemporalAttention(nn.Module):
    """Spatial attention over the rows of each time step and temporal attention along each row.

    Inputs are per-person token embeddings ``(P, rows * T', D)`` flattened joint-major (P is
    batch x persons); the two branches take separately modulated inputs (their own AdaLN), so
    both are arguments. The caller sums the branch outputs (eq. 6).
    """

    def __init__(self, *, width: int, heads: int, dropout: float) -> None:
        super().__init__()
        self.spatial = MultiHeadAttention(width=width, heads=heads, dropout=dropout)
        self.temporal = MultiHeadAttention(width=width, heads=heads, dropout=dropout)

    def forward(
        self,
        spatial_input: torch.Tensor,
        temporal_input: torch.Tensor,
        key_padding_mask: torch.Tensor,
        *,
        rows: int,
    ) -> SpatioTemporalOutput:
        """(P, rows * T', D) inputs and (P, rows * T') padding -> both branches, (P, rows * T', D)."""
        persons = spatial_input.shape[0]
        spatial = self.spatial(
            rearrange(spatial_input, "p (r t) d -> (p t) r d", r=rows),
            key_padding_mask=rearrange(key_padding_mask, "p (r t) -> (p t) r", r=rows),
        )
        temporal = self.temporal(
            rearrange(temporal_input, "p (r t) d -> (p r) t d", r=rows),
            key_padding_mask=rearrange(key_padding_mask, "p (r t) -> (p r) t", r=rows),
        )
        return SpatioTemporalOutput(
            rearrange(spatial, "(p t) r d -> p (r t) d", p=persons),
            rearrange(temporal, "(p r) t d -> p (r t) d", p=persons),
        )
