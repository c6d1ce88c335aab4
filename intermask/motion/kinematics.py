"""Forward kinematics over a parent-indexed skeleton."""

from __future__ import annotations

from typing import NamedTuple

import torch

from intermask.motion.skeleton import PARENTS


class FKResult(NamedTuple):
    positions: torch.Tensor  # (..., J, 3) world joint positions
    global_rotations: torch.Tensor  # (..., J, 3, 3) world orientation of each joint's frame


def forward_kinematics(
    local_rotations: torch.Tensor,
    root_position: torch.Tensor,
    offsets: torch.Tensor,
    parents: tuple[int, ...] = PARENTS,
) -> FKResult:
    """Pose a skeleton.

    Args:
        local_rotations: (..., J, 3, 3) rotation of each joint relative to its parent; row 0 is the
            global orientation of the root.
        root_position: (..., 3) world position of joint 0.
        offsets: (J, 3) or (..., J, 3) rest-pose offset of each joint from its parent.
        parents: parent index per joint, parents[0] = -1, parents[j] < j.
    """
    num_joints = len(parents)
    if local_rotations.shape[-3:] != (num_joints, 3, 3):
        raise ValueError(
            f"local_rotations: expected (..., {num_joints}, 3, 3), got {tuple(local_rotations.shape)}"
        )
    if offsets.shape[-2:] != (num_joints, 3):
        raise ValueError(f"offsets: expected (..., {num_joints}, 3), got {tuple(offsets.shape)}")
    if root_position.shape[-1] != 3:
        raise ValueError(f"root_position: expected (..., 3), got {tuple(root_position.shape)}")
    offsets = offsets.to(local_rotations)
    # The joint loop walks the tree (22 steps); everything inside is batched over (...).
    rotations = [local_rotations[..., 0, :, :]]
    positions = [root_position.to(local_rotations).expand(rotations[0].shape[:-1])]
    for joint in range(1, num_joints):
        parent = parents[joint]
        parent_rotation = rotations[parent]
        offset = offsets[..., joint, :].expand(positions[parent].shape)
        positions.append(positions[parent] + (parent_rotation @ offset[..., None])[..., 0])
        rotations.append(parent_rotation @ local_rotations[..., joint, :, :])
    return FKResult(torch.stack(positions, dim=-2), torch.stack(rotations, dim=-3))


def bone_lengths(positions: torch.Tensor, parents: tuple[int, ...] = PARENTS) -> torch.Tensor:
    """(..., J, 3) joint positions -> (..., J-1) length of the bone ending at each joint 1..J-1."""
    children = torch.arange(1, len(parents), device=positions.device)
    parent_index = torch.tensor(parents[1:], device=positions.device)
    return torch.linalg.vector_norm(
        positions[..., children, :] - positions[..., parent_index, :], dim=-1
    )
