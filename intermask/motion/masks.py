"""Valid positions of padded batches: the one place lengths become masks (frames or token steps)."""

from __future__ import annotations

import torch


def length_mask(lengths: torch.Tensor, size: int) -> torch.Tensor:
    """(B,) lengths -> (B, size) bool, True at the positions before each length."""
    positions = torch.arange(size, device=lengths.device)
    return positions[None, :] < lengths[:, None]
