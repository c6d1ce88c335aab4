"""Small network pieces shared by several models."""

from __future__ import annotations

from contextlib import nullcontext

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn
from torch.nn.attention import SDPBackend, sdpa_kernel

# SDPA kernels a masked attention may use: all but cuDNN's. With a mask, flash attention is not
# eligible and PyTorch (2.11, H200, bf16) picks cuDNN's kernel, which took 91 ms of a 128-sample
# paper-size Inter-M pass where the memory-efficient kernel took 67 ms (same masks, same shapes;
# docs/performance.md). fp32 never reaches cuDNN's kernel, and CPUs have no such kernel: there
# nothing changes (the switch is only made on CUDA). Unmasked attention keeps PyTorch's own choice.
MASKED_BACKENDS = (SDPBackend.FLASH_ATTENTION, SDPBackend.EFFICIENT_ATTENTION, SDPBackend.MATH)


class Attention(nn.Module):
    """Multi-head scaled dot-product attention (SDPA) with a packed key/value projection.

    The core of Inter-M's attentions (which add key padding) and of ARFlow's decoder (which
    passes causal and padding masks).
    """

    def __init__(self, *, width: int, heads: int, dropout: float) -> None:
        super().__init__()
        if width % heads:
            raise ValueError(f"width {width} is not divisible by {heads} heads")
        self.heads, self.dropout = heads, dropout
        self.query = nn.Linear(width, width)
        self.key_value = nn.Linear(width, 2 * width)
        self.out = nn.Linear(width, width)

    def forward(
        self,
        x: torch.Tensor,
        context: torch.Tensor | None = None,
        mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """(B, S_q, D) queries, (B, S_k, D) keys/values (default ``x``) -> (B, S_q, D).

        ``mask``: bool, broadcastable to (B, heads, S_q, S_k), True = may attend.
        """
        context = x if context is None else context
        q = rearrange(self.query(x), "b s (h d) -> b h s d", h=self.heads)
        k, v = rearrange(
            self.key_value(context), "b s (two h d) -> two b h s d", two=2, h=self.heads
        )
        dropout = self.dropout if self.training else 0.0
        kernels = (
            sdpa_kernel(list(MASKED_BACKENDS)) if mask is not None and q.is_cuda else nullcontext()
        )
        with kernels:
            out = F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=dropout)
        return self.out(rearrange(out, "b h s d -> b s (h d)"))


def post_norm_gelu_encoder(
    *, width: int, layers: int, heads: int, ff: int, dropout: float
) -> nn.TransformerEncoder:
    """Post-norm GELU ``nn.TransformerEncoder``, batch first: the text stacks of Inter-M and of
    InterGen's InterCLIP (their reference layer settings)."""
    layer = nn.TransformerEncoderLayer(
        d_model=width,
        nhead=heads,
        dim_feedforward=ff,
        dropout=dropout,
        activation="gelu",
        batch_first=True,
        norm_first=False,
    )
    return nn.TransformerEncoder(layer, num_layers=layers, enable_nested_tensor=False)
