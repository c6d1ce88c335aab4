"""Plausibility statistics of two-person joint sequences, for logging generated samples next to
the ground truth (a generator whose samples drift, float or stretch their bones shows it here
long before FID is computed)."""

from __future__ import annotations

import torch

from intermask.motion.kinematics import bone_lengths
from intermask.motion.masks import length_mask
from intermask.motion.skeleton import FOOT_JOINTS

UP_AXIS = 1  # joints are Y-up throughout the package


def _masked_mean(values: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of (B, T, ...) values over the frames where mask (B, T) holds."""
    mask = mask.reshape(*mask.shape, *([1] * (values.ndim - 2))).expand_as(values)
    return values[mask].mean()


def interaction_statistics(
    joints: torch.Tensor, lengths: torch.Tensor, *, fps: float
) -> dict[str, float]:
    """(B, T, 2, 22, 3) joints in metres and (B,) valid frames -> scalar statistics:

    - ``joint_speed``: mean joint speed (m/s);
    - ``root_distance``: mean horizontal distance between the two pelvises (m);
    - ``bone_length_std``: mean over bones of each bone's length deviation within a clip (mm);
      a rigid skeleton gives 0;
    - ``foot_height``: mean height of the lowest foot joint above the floor y = 0 (m).
    """
    if joints.ndim != 5 or joints.shape[2:] != (2, 22, 3):
        raise ValueError(f"joints must be (B, T, 2, 22, 3), got {tuple(joints.shape)}")
    if bool((lengths < 2).any()):
        raise ValueError(f"every clip needs at least 2 frames, got lengths {lengths.tolist()}")
    joints = joints.float()
    frames = joints.shape[1]
    mask = length_mask(lengths.to(joints.device), frames)
    step_mask = mask[:, 1:] & mask[:, :-1]
    speed = torch.linalg.vector_norm(joints[:, 1:] - joints[:, :-1], dim=-1) * fps
    horizontal = joints[:, :, :, 0, :].clone()
    horizontal[..., UP_AXIS] = 0.0
    root_distance = torch.linalg.vector_norm(horizontal[:, :, 0] - horizontal[:, :, 1], dim=-1)
    bones = bone_lengths(joints)  # (B, T, 2, 21)
    weights = mask[..., None, None].float()
    count = weights.sum(1, keepdim=True)
    mean_length = (bones * weights).sum(1, keepdim=True) / count
    bone_std = (((bones - mean_length).square() * weights).sum(1) / count[:, 0]).sqrt()
    feet = joints[..., list(FOOT_JOINTS), UP_AXIS].amin(-1)  # (B, T, 2)
    return {
        "joint_speed": float(_masked_mean(speed, step_mask)),
        "root_distance": float(_masked_mean(root_distance, mask)),
        "bone_length_std": float(bone_std.mean() * 1000.0),
        "foot_height": float(_masked_mean(feet, mask)),
    }
