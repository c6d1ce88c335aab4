"""Test motions built with forward kinematics of the SMPL skeleton (valid rotations, rigid bones).

Imported by the tests as a plain module (tests/motion is on sys.path under pytest's default
import mode); the fixtures live in conftest.py.

Everything here is independent of intermask.motion.interhuman: the raw rows are assembled by hand
with an explicit Y-up -> Z-up matrix.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from intermask.motion.kinematics import forward_kinematics
from intermask.motion.rotations import axis_angle_to_matrix, matrix_to_rot6d, rotation_about_axis
from intermask.motion.skeleton import NUM_JOINTS, REST_OFFSETS

# Y-up (x, y, z) -> Z-up (x, -z, y): the inverse of the InterHuman axis change (x, y, z) -> (x, z, -y).
YUP_TO_ZUP = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]], dtype=torch.float64)


class SkeletonMotion(NamedTuple):
    local_rotations: torch.Tensor  # (T, 22, 3, 3); row 0 = root orientation in the Y-up world
    root_position: torch.Tensor  # (T, 3) Y-up
    positions: torch.Tensor  # (T, 22, 3) Y-up world
    raw: torch.Tensor  # (T, 492) InterHuman raw rows (Z-up), hands filled with random valid data


def raw_rows(
    local_rotations: torch.Tensor, positions: torch.Tensor, generator: torch.Generator
) -> torch.Tensor:
    """Assemble (T, 492) raw rows: 62 Z-up joint positions, then 51 6D local rotations."""
    frames = positions.shape[0]
    body = positions @ YUP_TO_ZUP.T  # (T, 22, 3)
    wrists = body[:, [20] * 15 + [21] * 15, :]  # hand joints 22..51 near the left/right wrists
    hands = torch.cat((wrists, body[:, [20] * 5 + [21] * 5, :]), dim=1)  # + 5 + 5 finger tips
    hands = hands + 0.05 * torch.rand(frames, 40, 3, generator=generator, dtype=torch.float64)
    hand_rotations = axis_angle_to_matrix(
        0.3 * torch.randn(frames, 30, 3, generator=generator, dtype=torch.float64)
    )
    rotations = torch.cat((local_rotations[:, 1:], hand_rotations), dim=1)  # joints 1..51
    return torch.cat(
        (
            body.reshape(frames, -1),
            hands.reshape(frames, -1),
            matrix_to_rot6d(rotations).reshape(frames, -1),
        ),
        dim=-1,
    )


def build_motion(
    local_rotations: torch.Tensor, root_position: torch.Tensor, generator: torch.Generator
) -> SkeletonMotion:
    positions = forward_kinematics(local_rotations, root_position, REST_OFFSETS.double()).positions
    return SkeletonMotion(
        local_rotations, root_position, positions, raw_rows(local_rotations, positions, generator)
    )


def random_motion(
    generator: torch.Generator,
    frames: int = 24,
    yaw: float | None = None,
    root_xz: tuple[float, float] | None = None,
) -> SkeletonMotion:
    """A smooth random motion: drifting root, yawed body, every joint rotating slowly."""

    def uniform(*shape: int, scale: float = 1.0) -> torch.Tensor:
        return scale * (2 * torch.rand(*shape, generator=generator, dtype=torch.float64) - 1)

    time = torch.arange(frames, dtype=torch.float64)[:, None, None]
    axis_angle = uniform(1, NUM_JOINTS, 3, scale=0.4) + time * uniform(1, NUM_JOINTS, 3, scale=0.03)
    axis_angle[:, 0] *= 0.3  # keep the root roughly upright so the person stands
    local = axis_angle_to_matrix(axis_angle)
    yaw_angle = float(uniform(1, scale=3.1)) if yaw is None else yaw
    yaw_rotation = rotation_about_axis(yaw_angle + 0.05 * time[:, 0, 0], "y")
    local[:, 0] = yaw_rotation @ local[:, 0]
    start = uniform(2, scale=2.0) if root_xz is None else torch.tensor(root_xz, dtype=torch.float64)
    drift = time[:, 0] * uniform(1, 3, scale=0.02)
    root = torch.stack(
        (start[0] + drift[:, 0], 0.9 + 0.05 * drift[:, 1], start[1] + drift[:, 2]), dim=-1
    )
    return build_motion(local, root, generator)
