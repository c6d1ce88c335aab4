"""AdaLN-Zero conditioned sub-layers and the Inter-M block (InterMask section 3.2.2, figure 2c).

Every attention and FFN sub-layer follows DiT's AdaLN-Zero (Peebles & Xie 2023):
``x + gate(c) * f(LN(x) * (1 + scale(c)) + shift(c))`` with a LayerNorm without affine
parameters (eps 1e-6) and shift/scale/gate regressed from the condition ``c`` by SiLU + Linear,
zero-initialised, so every sub-layer starts as the identity.
"""

from __future__ import annotations

import torch
from torch import nn

from intermask.interm.attention import MultiHeadAttention, SpatioTemporalAttention


def modulate(x: torch.Tensor, shift: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """(B, S, D) tokens, (B, D) shift and scale -> x * (1 + scale) + shift, in one pass."""
    return torch.addcmul(shift[:, None, :], x, 1 + scale[:, None, :])


def gated(x: torch.Tensor, gate: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """(B, S, D) residual, (B, D) gate, (B, S, D) branch -> x + gate * h, in one pass."""
    return torch.addcmul(x, gate[:, None, :], h)


def adaptive_norm(width: int) -> nn.LayerNorm:
    return nn.LayerNorm(width, elementwise_affine=False, eps=1e-6)


class AdaLNModulation(nn.Module):
    """(B, D) condition -> ``chunks`` (B, D) modulation vectors, all zero at initialisation."""

    def __init__(self, *, width: int, chunks: int) -> None:
        super().__init__()
        self.chunks = chunks
        self.linear = nn.Linear(width, chunks * width)
        self.reset_parameters()

    def reset_parameters(self) -> None:
        nn.init.zeros_(self.linear.weight)
        nn.init.zeros_(self.linear.bias)

    def forward(self, c: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return self.linear(nn.functional.silu(c)).chunk(self.chunks, dim=-1)


class SelfAttentionLayer(nn.Module):
    """AdaLN-Zero self attention over (B, S, D) with a (B, S) key padding mask (eq. 4)."""

    def __init__(self, *, width: int, heads: int, dropout: float) -> None:
        super().__init__()
        self.norm = adaptive_norm(width)
        self.modulation = AdaLNModulation(width=width, chunks=3)
        self.attention = MultiHeadAttention(width=width, heads=heads, dropout=dropout)
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, c: torch.Tensor, padding: torch.Tensor) -> torch.Tensor:
        shift, scale, gate = self.modulation(c)
        h = self.attention(modulate(self.norm(x), shift, scale), key_padding_mask=padding)
        return gated(x, gate, self.dropout(h))


class FeedForwardLayer(nn.Module):
    """AdaLN-Zero FFN: Linear -> GELU -> Dropout -> Linear on (B, S, D)."""

    def __init__(self, *, width: int, ff: int, dropout: float) -> None:
        super().__init__()
        self.norm = adaptive_norm(width)
        self.modulation = AdaLNModulation(width=width, chunks=3)
        self.net = nn.Sequential(
            nn.Linear(width, ff), nn.GELU(), nn.Dropout(dropout), nn.Linear(ff, width)
        )
        self.dropout = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
        shift, scale, gate = self.modulation(c)
        return gated(x, gate, self.dropout(self.net(modulate(self.norm(x), shift, scale))))


class SpatioTemporalLayer(nn.Module):
    """AdaLN-Zero spatio-temporal attention, branches summed: e = x + g_s e' + g_t e'' (eq. 6).

    ``double_residual_quirk`` reproduces the reference, which adds the residual inside both
    branches before summing them and so counts the input twice (2x + g_s e' + g_t e'').
    """

    def __init__(
        self, *, width: int, heads: int, dropout: float, double_residual_quirk: bool = False
    ) -> None:
        super().__init__()
        self.double_residual_quirk = double_residual_quirk
        self.norm = adaptive_norm(width)
        self.modulation = AdaLNModulation(width=width, chunks=6)
        self.attention = SpatioTemporalAttention(width=width, heads=heads, dropout=dropout)
        self.dropout = nn.Dropout(dropout)

    def forward(
        self, x: torch.Tensor, c: torch.Tensor, padding: torch.Tensor, *, rows: int
    ) -> torch.Tensor:
        """(P, rows * T', D) one person per row of the batch, (P, D) condition, (P, rows * T')."""
        shift_s, scale_s, gate_s, shift_t, scale_t, gate_t = self.modulation(c)
        normed = self.norm(x)
        out = self.attention(
            modulate(normed, shift_s, scale_s),
            modulate(normed, shift_t, scale_t),
            padding,
            rows=rows,
        )
        residual = 2 * x if self.double_residual_quirk else x
        spatial = gated(residual, gate_s, self.dropout(out.spatial))
        return gated(spatial, gate_t, self.dropout(out.temporal))


class CrossAttentionLayer(nn.Module):
    """AdaLN-Zero cross attention: x queries ``context`` (the other person, eq. 7).

    Queries and keys/values get their own norm modulation (shift/scale), one gate: five chunks,
    as in the reference.
    """

    def __init__(self, *, width: int, heads: int, dropout: float) -> None:
        super().__init__()
        self.norm = adaptive_norm(width)
        self.context_norm = adaptive_norm(width)
        self.modulation = AdaLNModulation(width=width, chunks=5)
        self.attention = MultiHeadAttention(width=width, heads=heads, dropout=dropout)
        self.dropout = nn.Dropout(dropout)

    def forward(
        self, x: torch.Tensor, context: torch.Tensor, c: torch.Tensor, context_padding: torch.Tensor
    ) -> torch.Tensor:
        shift, scale, shift_ctx, scale_ctx, gate = self.modulation(c)
        h = self.attention(
            modulate(self.norm(x), shift, scale),
            modulate(self.context_norm(context), shift_ctx, scale_ctx),
            key_padding_mask=context_padding,
        )
        return gated(x, gate, self.dropout(h))


class InterMBlock(nn.Module):
    """One Inter-M block on the ``[A, SEP, B]`` sequence (B, 2N + 1, D).

    (1) self attention over the whole sequence -> (2) FFN -> split A / SEP / B -> (3) shared
    spatio-temporal attention per person -> (4) shared cross attention, each person querying the
    other -> (5) shared FFN -> re-join with [SEP]. Both persons run through (3)-(5) stacked on the
    batch axis with the same weights, so swapping A and B swaps the outputs.

    The ``use_*`` switches are the Table 3 ablations; a disabled sub-layer is not built.
    ``cross_context_quirk`` makes the keys/values of cross attention the other person's
    embeddings from *before* spatio-temporal attention, as the reference code does; by default
    both sides come after it, as eq. 7 reads.

    :meth:`forward_alternative` is the same block for alternative modeling (appendix E): only
    one person's stream passes (1)-(5), and (4) reads a fixed context.
    """

    def __init__(
        self,
        *,
        width: int,
        heads: int,
        ff: int,
        dropout: float,
        use_self_attention: bool = True,
        use_spatio_temporal_attention: bool = True,
        use_cross_attention: bool = True,
        double_residual_quirk: bool = False,
        cross_context_quirk: bool = False,
    ) -> None:
        super().__init__()
        attention = {"width": width, "heads": heads, "dropout": dropout}
        self.self_attention = SelfAttentionLayer(**attention) if use_self_attention else None
        self.joint_ffn = FeedForwardLayer(width=width, ff=ff, dropout=dropout)
        self.spatio_temporal = (
            SpatioTemporalLayer(**attention, double_residual_quirk=double_residual_quirk)
            if use_spatio_temporal_attention
            else None
        )
        self.cross_attention = CrossAttentionLayer(**attention) if use_cross_attention else None
        self.person_ffn = FeedForwardLayer(width=width, ff=ff, dropout=dropout)
        self.cross_context_quirk = cross_context_quirk

    def forward(
        self, x: torch.Tensor, c: torch.Tensor, padding: torch.Tensor, *, rows: int
    ) -> torch.Tensor:
        """(B, 2N + 1, D) sequence, (B, D) condition, (B, 2N + 1) key padding -> (B, 2N + 1, D)."""
        if self.self_attention is not None:
            x = self.self_attention(x, c, padding)
        x = self.joint_ffn(x, c)

        n = (x.shape[1] - 1) // 2
        a, sep, b = x.split([n, 1, n], dim=1)
        pad_a, _, pad_b = padding.split([n, 1, n], dim=1)
        persons = torch.cat([a, b], dim=0)  # (2B, N, D): A's batch then B's batch
        person_padding = torch.cat([pad_a, pad_b], dim=0)
        other_padding = torch.cat([pad_b, pad_a], dim=0)
        cc = torch.cat([c, c], dim=0)

        before = persons
        if self.spatio_temporal is not None:
            persons = self.spatio_temporal(persons, cc, person_padding, rows=rows)
        if self.cross_attention is not None:
            source = before if self.cross_context_quirk else persons
            other = source.roll(shifts=a.shape[0], dims=0)  # row i holds the partner of row i
            persons = self.cross_attention(persons, other, cc, other_padding)
        persons = self.person_ffn(persons, cc)

        a, b = persons.chunk(2, dim=0)
        return torch.cat([a, sep, b], dim=1)

    def forward_alternative(
        self,
        x: torch.Tensor,
        context: torch.Tensor,
        c: torch.Tensor,
        padding: torch.Tensor,
        context_padding: torch.Tensor,
        *,
        rows: int,
    ) -> torch.Tensor:
        """Alternative modeling (appendix E, figure 8a): the predicted person's stream only.

        (G, N, D) stream ``x`` of the predicted person, (G, N, D) ``context`` (the other
        person's input embeddings, the same tensor in every block: it is never updated),
        (G, D) condition, (G, N) key padding of each -> (G, N, D). Self attention (1) covers
        the predicted person's tokens only; the other person enters through (4) alone.
        """
        if self.cross_attention is None:
            raise RuntimeError("alternative modeling needs the cross-attention sub-layer")
        if self.self_attention is not None:
            x = self.self_attention(x, c, padding)
        x = self.joint_ffn(x, c)
        if self.spatio_temporal is not None:
            x = self.spatio_temporal(x, c, padding, rows=rows)
        x = self.cross_attention(x, context, c, context_padding)
        return self.person_ffn(x, c)
