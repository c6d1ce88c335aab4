"""Known body parameters that the fit must find again (shared by the body tests)."""

from __future__ import annotations

import math

import torch

from intermask.body.fit import BodyParams
from intermask.motion.rotations import axis_angle_to_matrix


def known_params(frames: int = 30, *, seed: int = 0) -> BodyParams:
    """Two moving bodies of random shape: person 1 has its back to +Z (turned 180 degrees about
    Y), person 2 lies on its back (turned -90 degrees about X); both walk along x and z."""
    generator = torch.Generator().manual_seed(seed)
    t = torch.linspace(0.0, 1.0, frames, dtype=torch.float64)
    mean = 0.4 * torch.randn(2, 1, 22, 3, generator=generator, dtype=torch.float64)
    swing = 0.3 * torch.randn(2, 1, 22, 3, generator=generator, dtype=torch.float64)
    axis_angle = mean + swing * torch.sin(2 * math.pi * t)[None, :, None, None]
    axis_angle[0, :, 0] = torch.tensor([0.0, math.pi, 0.0], dtype=torch.float64)
    axis_angle[1, :, 0] = torch.tensor([-math.pi / 2, 0.0, 0.0], dtype=torch.float64)
    path = torch.stack((t, 0.0 * t, 0.5 * t), -1)
    transl = torch.tensor([[0.0, 1.2, 0.0], [0.6, 0.5, 0.2]], dtype=torch.float64)[:, None] + path
    hands = axis_angle_to_matrix(
        0.2 * torch.randn(2, frames, 30, 3, generator=generator, dtype=torch.float64)
    )
    betas = torch.randn(2, 10, generator=generator, dtype=torch.float64)
    return BodyParams(betas, axis_angle_to_matrix(axis_angle), hands, transl)
