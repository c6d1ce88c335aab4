"""ARFlow's clean-reaction predictor G(x_t, t, c): a Transformer decoder over the frames of x_t.

Paper (appendix E): x_t goes through a linear layer to width d and gets a positional embedding;
the time t and the optional condition c are projected to d by feed-forward networks and
combined into a token z; 8 decoder layers of width 512 (appendix F) predict x1_hat; the online
variant hides the future with attention masks, the offline one attends to everything
(section 4.2: "an 8-layer Transformer encoder"). Our reading of the layout, which the paper
leaves open: z is added to every frame token and is the first memory token; the memory also
holds the actor's frames (cross-attention to x0, the action), so the reaction sees the action
explicitly and not only through x_t.

Online (``causal=True``): frame i attends to x_t frames <= i and actor frames <= i, so its
prediction never depends on the future. Padding (``frame_mask`` False) is never attended to.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from intermask.utils.layers import Attention


def sinusoidal_embedding(positions: torch.Tensor, dim: int) -> torch.Tensor:
    """(...) positions (frames, or scaled times) -> (..., dim) sin/cos features."""
    half = dim // 2
    frequencies = torch.exp(
        -math.log(10000.0) * torch.arange(half, device=positions.device, dtype=torch.float32) / half
    )
    angles = positions.float()[..., None] * frequencies
    embedding = torch.cat((angles.sin(), angles.cos()), dim=-1)
    if dim % 2:
        embedding = F.pad(embedding, (0, 1))
    return embedding


class DecoderBlock(nn.Module):
    """Pre-norm self-attention, cross-attention to the memory, feed-forward."""

    def __init__(self, *, width: int, heads: int, ff: int, dropout: float) -> None:
        super().__init__()
        self.norm_self = nn.LayerNorm(width)
        self.self_attention = Attention(width=width, heads=heads, dropout=dropout)
        self.norm_cross = nn.LayerNorm(width)
        self.cross_attention = Attention(width=width, heads=heads, dropout=dropout)
        self.norm_ff = nn.LayerNorm(width)
        self.ff = nn.Sequential(
            nn.Linear(width, ff), nn.GELU(), nn.Dropout(dropout), nn.Linear(ff, width)
        )
        self.dropout = nn.Dropout(dropout)

    def forward(
        self,
        x: torch.Tensor,
        memory: torch.Tensor,
        self_mask: torch.Tensor,
        cross_mask: torch.Tensor,
    ) -> torch.Tensor:
        h = self.norm_self(x)
        x = x + self.dropout(self.self_attention(h, h, self_mask))
        x = x + self.dropout(self.cross_attention(self.norm_cross(x), memory, cross_mask))
        return x + self.dropout(self.ff(self.norm_ff(x)))


def attention_masks(frame_mask: torch.Tensor, *, causal: bool) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, T) valid frames -> self (B, 1, T, T) and cross (B, 1, T, 1 + T) masks, True = attend.

    Keys on padding are hidden; with ``causal`` so are keys after the query frame. The memory's
    first token (z: time and condition) is always visible. A padded query still sees frame 0,
    so no softmax runs over nothing.
    """
    frames = frame_mask.shape[1]
    keys = frame_mask[:, None, None, :]  # (B, 1, 1, T)
    if causal:
        order = torch.arange(frames, device=frame_mask.device)
        keys = keys & (order[None, :] <= order[:, None])[None, None]  # (B, 1, T, T)
    self_mask = keys.expand(-1, 1, frames, frames)
    z_column = self_mask.new_ones(self_mask.shape[0], 1, frames, 1)
    return self_mask, torch.cat((z_column, self_mask), dim=-1)


class ReactionDecoder(nn.Module):
    """x1_hat = G(x_t, t, c) with cross-attention to the actor's frames.

    Args:
        feature_dim: D of the flat per-frame vectors (262 InterHuman, 336 Inter-X).
        width, depth, heads, ff, dropout: the Transformer (paper: width 512, 8 layers).
        causal: online (True) or offline (False) variant.
        text_dim: width of the pooled frozen text feature; None = no text condition.
        time_scale: t in [0, 1] is embedded as ``time_scale * t`` (the paper's 1000 steps).
    """

    def __init__(
        self,
        *,
        feature_dim: int,
        width: int = 512,
        depth: int = 8,
        heads: int = 4,
        ff: int = 1024,
        dropout: float = 0.1,
        causal: bool = True,
        text_dim: int | None = None,
        time_scale: float = 1000.0,
    ) -> None:
        super().__init__()
        if min(feature_dim, width, depth, heads, ff) < 1:
            raise ValueError(
                f"feature_dim, width, depth, heads and ff must be >= 1, got {feature_dim}, "
                f"{width}, {depth}, {heads}, {ff}"
            )
        self.feature_dim, self.width, self.causal = feature_dim, width, causal
        self.text_dim, self.time_scale = text_dim, time_scale
        self.input_projection = nn.Linear(feature_dim, width)
        self.actor_projection = nn.Linear(feature_dim, width)
        self.time_mlp = nn.Sequential(nn.Linear(width, width), nn.SiLU(), nn.Linear(width, width))
        self.text_mlp: nn.Module | None = None
        if text_dim is not None:
            self.text_mlp = nn.Sequential(
                nn.Linear(text_dim, width), nn.SiLU(), nn.Linear(width, width)
            )
            # the dropped / absent condition of classifier-free training
            self.null_text = nn.Parameter(torch.zeros(width))
        self.blocks = nn.ModuleList(
            DecoderBlock(width=width, heads=heads, ff=ff, dropout=dropout) for _ in range(depth)
        )
        self.final_norm = nn.LayerNorm(width)
        self.output_projection = nn.Linear(width, feature_dim)

    def condition(
        self, t: torch.Tensor, text: torch.Tensor | None, drop: torch.Tensor | None
    ) -> torch.Tensor:
        """(B,) times, (B, text_dim) pooled text or None, (B,) bool drop -> (B, D) token z."""
        z = self.time_mlp(sinusoidal_embedding(t * self.time_scale, self.width))
        if self.text_mlp is None:
            if text is not None:
                raise ValueError("this network has no text condition (text_dim=None), got text")
            return z
        null = self.null_text.expand_as(z)
        if text is None:
            return z + null
        if text.shape != (t.shape[0], self.text_dim):
            raise ValueError(
                f"text must be (B, {self.text_dim}) pooled features, got {tuple(text.shape)}"
            )
        embedded = self.text_mlp(text.to(z.dtype))
        if drop is not None:
            embedded = torch.where(drop[:, None], null, embedded)
        return z + embedded

    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        actor: torch.Tensor,
        frame_mask: torch.Tensor,
        text: torch.Tensor | None = None,
        drop: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """x_t, actor (B, T, D); t (B,) in [0, 1]; frame_mask (B, T) bool; text (B, text_dim)
        or None; drop (B,) bool (null condition) or None -> x1_hat (B, T, D)."""
        if x_t.ndim != 3 or x_t.shape[-1] != self.feature_dim or actor.shape != x_t.shape:
            raise ValueError(
                f"x_t and actor must both be (B, T, {self.feature_dim}), got "
                f"{tuple(x_t.shape)} and {tuple(actor.shape)}"
            )
        if frame_mask.shape != x_t.shape[:2] or frame_mask.dtype != torch.bool:
            raise ValueError(
                f"frame_mask must be bool {tuple(x_t.shape[:2])}, got {frame_mask.dtype} "
                f"{tuple(frame_mask.shape)}"
            )
        if not bool(frame_mask[:, 0].all()):
            raise ValueError("every sample needs at least one valid frame (length >= 1)")
        t = torch.as_tensor(t, device=x_t.device, dtype=torch.float32).expand(x_t.shape[0])
        positions = sinusoidal_embedding(
            torch.arange(x_t.shape[1], device=x_t.device), self.width
        ).to(x_t.dtype)  # (T, D)
        z = self.condition(t, text, drop)  # (B, D)
        x = self.input_projection(x_t) + positions + z[:, None]
        memory = torch.cat((z[:, None], self.actor_projection(actor) + positions), dim=1)
        self_mask, cross_mask = attention_masks(frame_mask, causal=self.causal)
        for block in self.blocks:
            x = block(x, memory, self_mask, cross_mask)
        return self.output_projection(self.final_norm(x))
