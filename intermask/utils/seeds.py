"""Torch generators keyed by integers: the same keys give the same stream in every process."""

from __future__ import annotations

import numpy as np
import torch


def keyed_generator(*keys: int, device: torch.device | str = "cpu") -> torch.Generator:
    """A torch generator on ``device`` seeded from ``SeedSequence(keys)`` (independent streams
    for different keys)."""
    state = np.random.SeedSequence([int(k) for k in keys]).generate_state(1, dtype=np.uint64)[0]
    return torch.Generator(device=device).manual_seed(int(state) & 0x7FFF_FFFF_FFFF_FFFF)
