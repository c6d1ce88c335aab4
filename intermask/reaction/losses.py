"""ARFlow's training losses: x1 reconstruction (eq. 5) and the interaction loss (eq. 6).

L_inter compares actor-reactor relations of the ground-truth reaction with those of the
prediction, the actor being the same ground truth in both (following ReGenNet):
    theta: distances between every reactor joint and every actor joint (22 x 22 per frame),
    q:     the reactor's root orientation in the actor's root frame (R_a^T R_r),
    gamma: the reactor's root position in the actor's root frame (R_a^T (p_r - p_a)).
Root frames come from the joints (hips and spine), so both representations share one code path.
The paper sums squares and divides by the frames H; we average every term over its elements and
the valid frames instead, so that the three terms and the reconstruction (a per-dimension mean)
keep comparable scales with lambda_inter = 1.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F

from intermask.motion.skeleton import JOINT_NAMES

_PELVIS, _L_HIP, _R_HIP, _SPINE1 = (
    JOINT_NAMES.index(name) for name in ("pelvis", "l_hip", "r_hip", "spine1")
)
_EPS = 1e-9  # inside square roots: distances of coinciding joints (padding) keep finite gradients


class InteractionTerms(NamedTuple):
    total: torch.Tensor  # () distance + orientation + translation
    distance: torch.Tensor  # () relative joint distances (theta)
    orientation: torch.Tensor  # () relative root orientation (q)
    translation: torch.Tensor  # () relative root translation (gamma)


def masked_mean(values: torch.Tensor, frame_mask: torch.Tensor) -> torch.Tensor:
    """Mean of (B, T, ...) values over the valid frames of (B, T) ``frame_mask`` and the
    trailing elements; padding never reaches the result (not even as NaN * 0)."""
    if values.shape[:2] != frame_mask.shape:
        raise ValueError(
            f"values {tuple(values.shape)} and frame_mask {tuple(frame_mask.shape)} disagree on (B, T)"
        )
    mask = frame_mask.reshape(*frame_mask.shape, *([1] * (values.ndim - 2)))
    chosen = torch.where(mask, values, torch.zeros_like(values))
    count = frame_mask.sum() * (values[0, 0].numel())
    return chosen.sum() / count.clamp_min(1)


def reconstruction_loss(
    x1_hat: torch.Tensor, x1: torch.Tensor, frame_mask: torch.Tensor
) -> torch.Tensor:
    """L_fm (eq. 5): mean squared error of (B, T, D) predictions over valid frames."""
    return masked_mean((x1_hat - x1).square(), frame_mask)


def root_frames(joints: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) joints -> (..., 3, 3) root frames, columns (left, up, forward).

    left = l_hip - r_hip; up = pelvis -> spine1 made orthogonal to it; forward = left x up.
    """
    left = F.normalize(joints[..., _L_HIP, :] - joints[..., _R_HIP, :], dim=-1, eps=1e-6)
    spine = joints[..., _SPINE1, :] - joints[..., _PELVIS, :]
    up = F.normalize(spine - (spine * left).sum(-1, keepdim=True) * left, dim=-1, eps=1e-6)
    forward = torch.linalg.cross(left, up, dim=-1)
    return torch.stack((left, up, forward), dim=-1)


def relative_joint_distances(reactor: torch.Tensor, actor: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) each -> (..., 22, 22) distances reactor joint i to actor joint j."""
    difference = reactor[..., :, None, :] - actor[..., None, :, :]
    return (difference.square().sum(-1) + _EPS).sqrt()


def relative_root_orientation(reactor: torch.Tensor, actor: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) each -> (..., 3, 3) R_actor^T R_reactor."""
    return root_frames(actor).transpose(-1, -2) @ root_frames(reactor)


def relative_root_translation(reactor: torch.Tensor, actor: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) each -> (..., 3) reactor pelvis in the actor's root frame."""
    offset = reactor[..., _PELVIS, :] - actor[..., _PELVIS, :]
    return (root_frames(actor).transpose(-1, -2) @ offset[..., None])[..., 0]


def interaction_loss(
    predicted: torch.Tensor,
    target: torch.Tensor,
    actor: torch.Tensor,
    frame_mask: torch.Tensor,
) -> InteractionTerms:
    """L_inter (eq. 6) of (B, T, 22, 3) predicted / ground-truth reactor joints against the
    (B, T, 22, 3) actor joints, averaged over the (B, T) valid frames."""
    if not predicted.shape == target.shape == actor.shape or predicted.shape[-2:] != (22, 3):
        raise ValueError(
            "predicted, target and actor must all be (B, T, 22, 3), got "
            f"{tuple(predicted.shape)}, {tuple(target.shape)} and {tuple(actor.shape)}"
        )
    terms = []
    for relation in (
        relative_joint_distances,
        relative_root_orientation,
        relative_root_translation,
    ):
        difference = relation(predicted, actor) - relation(target, actor)
        terms.append(masked_mean(difference.square(), frame_mask))
    distance, orientation, translation = terms
    return InteractionTerms(
        distance + orientation + translation, distance, orientation, translation
    )
