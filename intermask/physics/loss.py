"""Differentiable penetration loss: the reactor's points against the actor's capsule body.

ARFlow (section 3.2, eq. 10) guides sampling with L_pene = sum_{i,h} -min(SDF_actor(joint), zeta)
over the reactor's joints i and frames h. Since -min(s, zeta) = relu(zeta - s) - zeta, the loss
here is relu(zeta - SDF) (same gradient, zero when every point keeps the safe distance), over the
joints plus points spread along the bones so that a forearm crossing a torso between two joints
is seen too. The SDF is the capsule proxy of intermask.physics.capsules, not a mesh.
"""

from __future__ import annotations

from typing import Literal

import torch

from intermask.motion.skeleton import BONES, NUM_JOINTS
from intermask.physics.capsules import (
    BodyProxy,
    body_capsules,
    check_finite,
    full_precision,
    signed_distance,
)

DEFAULT_ZETA = 0.5  # metres; ARFlow implementation details: safe distance zeta = 0.5
DEFAULT_POINTS_PER_BONE = 2


def bone_point_weights(points_per_bone: int) -> torch.Tensor:
    """(22 + 21 * points_per_bone, 22): rows mix joints into the sample points.

    The joints themselves, then `points_per_bone` evenly spaced interior points of every bone.
    """
    if points_per_bone < 0:
        raise ValueError(f"points_per_bone must be >= 0, got {points_per_bone}")
    rows = [torch.eye(NUM_JOINTS)]
    fractions = torch.arange(1, points_per_bone + 1) / (points_per_bone + 1)
    for parent, child in BONES:
        weights = torch.zeros(points_per_bone, NUM_JOINTS)
        weights[:, parent] = 1.0 - fractions
        weights[:, child] = fractions
        rows.append(weights)
    return torch.cat(rows)


def bone_sample_points(
    joints: torch.Tensor, *, points_per_bone: int = DEFAULT_POINTS_PER_BONE
) -> torch.Tensor:
    """(..., 22, 3) joints -> (..., 22 + 21 * points_per_bone, 3) joints and bone points."""
    if joints.ndim < 2 or tuple(joints.shape[-2:]) != (NUM_JOINTS, 3):
        raise ValueError(
            f"bone_sample_points: expected joints of shape (..., 22, 3), got {tuple(joints.shape)}"
        )
    joints = full_precision(joints)
    with torch.autocast(joints.device.type, enabled=False):  # keep metre coordinates exact
        return torch.einsum(
            "nj,...jc->...nc", bone_point_weights(points_per_bone).to(joints), joints
        )


def penetration_loss(
    reactor_joints: torch.Tensor,
    actor_joints: torch.Tensor,
    *,
    zeta: float = DEFAULT_ZETA,
    proxy: BodyProxy | None = None,
    points_per_bone: int = DEFAULT_POINTS_PER_BONE,
    frame_mask: torch.Tensor | None = None,
    detach_actor: bool = True,
    reduction: Literal["mean", "sum"] = "mean",
) -> torch.Tensor:
    """relu(zeta - SDF_actor(point)) over the reactor's sample points: a scalar.

    reactor_joints, actor_joints: (B, T, 22, 3) in metres (any leading dims, one shape).
    frame_mask: (B, T) bool; False frames (padding) contribute nothing.
    detach_actor: gradients reach the reactor only (ARFlow guides the reaction, not the action).
    reduction: "mean" over valid frames and points; "sum" over them, as ARFlow's eq. 10 (each
    sample then gets a gradient that does not shrink with the batch size).
    """
    if reactor_joints.shape != actor_joints.shape or tuple(reactor_joints.shape[-2:]) != (
        NUM_JOINTS,
        3,
    ):
        raise ValueError(
            "penetration_loss: reactor_joints and actor_joints must both be (..., 22, 3) of one "
            f"shape, got {tuple(reactor_joints.shape)} and {tuple(actor_joints.shape)}"
        )
    if not zeta >= 0:
        raise ValueError(f"penetration_loss: zeta must be >= 0 metres, got {zeta}")
    if reduction not in ("mean", "sum"):
        raise ValueError(f"penetration_loss: reduction must be 'mean' or 'sum', got {reduction!r}")
    leading = reactor_joints.shape[:-2]
    if frame_mask is not None and (frame_mask.dtype != torch.bool or frame_mask.shape != leading):
        raise ValueError(
            f"penetration_loss: frame_mask must be a bool tensor of shape {tuple(leading)}, got "
            f"{frame_mask.dtype} {tuple(frame_mask.shape)}"
        )
    check_finite(reactor_joints.detach(), "penetration_loss: reactor_joints")
    check_finite(actor_joints.detach(), "penetration_loss: actor_joints")
    actor = actor_joints.detach() if detach_actor else actor_joints
    points = bone_sample_points(reactor_joints, points_per_bone=points_per_bone)  # (..., N, 3)
    distance = signed_distance(points, body_capsules(actor, proxy))  # (..., N)
    penalty = torch.relu(zeta - distance)
    if frame_mask is not None:
        penalty = penalty * frame_mask[..., None].to(penalty)
        frames = frame_mask.sum()
    else:
        frames = torch.tensor(leading.numel(), device=penalty.device)
    total = penalty.sum()
    if reduction == "sum":
        return total
    return total / (frames * points.shape[-2]).clamp_min(1)
