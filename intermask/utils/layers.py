"""Small network pieces shared by several models."""

from __future__ import annotations

from torch import nn


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
