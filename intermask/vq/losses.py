"""VQ-VAE training losses (InterMask eq. 2 and appendix B, eq. 9).

Reconstruction runs on normalized features; every geometric term runs on de-normalized values
(metres, rotation matrices). The reference computes bone lengths and the geodesic term on
normalized values, which mixes per-dimension scales into a geometric quantity; we do not.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from types import MappingProxyType
from typing import Literal, NamedTuple

import torch
import torch.nn.functional as F

from intermask.motion.kinematics import bone_lengths
from intermask.motion.rotations import geodesic_angle, rot6d_to_matrix
from intermask.motion.skeleton import FOOT_JOINTS, JOINT_NAMES
from intermask.vq.views import Geometry

LossKind = Literal["smooth_l1", "l1", "l2"]
# the joints an ``arms`` loss weighs: the ones a contact (handshake, push, pass) is made with
ARM_JOINTS: tuple[int, ...] = tuple(
    JOINT_NAMES.index(name) for name in ("l_elbow", "r_elbow", "l_wrist", "r_wrist")
)
# the joints a ``torso`` loss weighs: the upper spine, neck and head, whose lean is a bow's pitch
TORSO_JOINTS: tuple[int, ...] = tuple(
    JOINT_NAMES.index(name) for name in ("spine3", "neck", "head")
)
# the joints a ``legs`` loss weighs: the knees and ankles, whose rise off the ground is a kick
LEG_JOINTS: tuple[int, ...] = tuple(
    JOINT_NAMES.index(name) for name in ("l_knee", "r_knee", "l_ankle", "r_ankle")
)
# each pelvis-relative term (a LossWeights and a LossTerms field) and the joints it weighs
PELVIS_RELATIVE_TERMS: Mapping[str, tuple[int, ...]] = MappingProxyType(
    {"arms": ARM_JOINTS, "torso": TORSO_JOINTS, "legs": LEG_JOINTS}
)


@dataclass(frozen=True)
class LossWeights:
    """Defaults: InterHuman (paper Table 5: velocity 100, foot contact 500, bone length 5;
    reference: reconstruction 1, positions 1, geodesic 0.01; commitment beta 0.02)."""

    reconstruction: float = 1.0
    positions: float = 1.0
    velocity: float = 100.0
    bone_length: float = 5.0
    geodesic: float = 0.01
    foot_contact: float = 500.0
    commitment: float = 0.02
    # not in the paper (0 = off): the elbows' and wrists' positions relative to the pelvis, so
    # an arm reaching for the partner costs more than its share of the 22-joint position term
    arms: float = 0.0
    # not in the paper (0 = off): the upper spine's, neck's and head's positions relative to the
    # pelvis, so a bow's lean (0.2 rad, a head 0.15 m forward) is not within the code error
    torso: float = 0.0
    # not in the paper (0 = off): the knees' and ankles' positions relative to the pelvis, so a
    # kick (an ankle 0.3-0.5 m above the other, in a few frames of 1% of the windows) is not
    # averaged away by the standing legs of every other window
    legs: float = 0.0


class LossTerms(NamedTuple):
    total: torch.Tensor
    reconstruction: torch.Tensor
    positions: torch.Tensor
    velocity: torch.Tensor
    bone_length: torch.Tensor
    geodesic: torch.Tensor
    foot_contact: torch.Tensor
    commitment: torch.Tensor
    arms: torch.Tensor
    torso: torch.Tensor
    legs: torch.Tensor


def elementwise_loss(
    prediction: torch.Tensor, target: torch.Tensor, kind: LossKind
) -> torch.Tensor:
    if kind == "smooth_l1":
        return F.smooth_l1_loss(prediction, target, reduction="none")
    if kind == "l1":
        return (prediction - target).abs()
    if kind == "l2":
        return (prediction - target).square()
    raise ValueError(f"unknown loss kind {kind!r}; expected 'smooth_l1', 'l1' or 'l2'")


def _masked_mean(values: torch.Tensor, frame_mask: torch.Tensor) -> torch.Tensor:
    """Mean of (B, T, ...) values over valid frames (frame_mask (B, T) bool)."""
    mask = frame_mask.reshape(*frame_mask.shape, *([1] * (values.ndim - 2))).to(values.dtype)
    per_frame = values[0, 0].numel()
    return (values * mask).sum() / (mask.sum() * per_frame).clamp_min(1.0)


def vq_losses(
    *,
    prediction: torch.Tensor,
    target: torch.Tensor,
    predicted_geometry: Geometry,
    target_geometry: Geometry,
    reconstruction_mask: torch.Tensor,
    frame_mask: torch.Tensor,
    commit_loss: torch.Tensor,
    weights: LossWeights,
    kind: LossKind = "smooth_l1",
    measure_unweighted: bool = True,
) -> LossTerms:
    """All VQ-VAE loss terms and their weighted sum.

    prediction, target: (B, T, *F) normalized features; reconstruction_mask: (*F) bool;
    frame_mask: (B, T) bool, False on padding; geometries from the representation view.
    Terms whose geometry is missing (Inter-X without a body model) are 0. A geodesic, arms,
    torso or legs term of weight 0 is measured without a graph, and only when ``measure_unweighted``
    (else 0): the geodesic costs ~12% of a CPU demo step for nothing the optimizer uses.
    """
    zero = prediction.new_zeros(())
    reconstruction = _masked_mean(
        elementwise_loss(prediction, target, kind)[..., reconstruction_mask], frame_mask
    )
    geodesic = _measured(  # mean rotation error in radians
        weights.geodesic,
        measure_unweighted,
        zero,
        lambda: _masked_mean(
            geodesic_angle(
                rot6d_to_matrix(predicted_geometry.rot6d), rot6d_to_matrix(target_geometry.rot6d)
            ),
            frame_mask,
        ),
    )
    joints = _joint_terms(
        predicted_geometry,
        target_geometry,
        frame_mask=frame_mask,
        weights=weights,
        kind=kind,
        measure_unweighted=measure_unweighted,
        zero=zero,
    )
    total = (
        weights.reconstruction * reconstruction
        + weights.positions * joints.positions
        + weights.velocity * joints.velocity
        + weights.bone_length * joints.bone_length
        + weights.geodesic * geodesic
        + weights.foot_contact * joints.foot_contact
        + weights.commitment * commit_loss
    )
    for name, term in joints.relative.items():  # one by one, in order: the same rounding as ever
        total = total + getattr(weights, name) * term
    return LossTerms(
        total=total,
        reconstruction=reconstruction,
        positions=joints.positions,
        velocity=joints.velocity,
        bone_length=joints.bone_length,
        geodesic=geodesic,
        foot_contact=joints.foot_contact,
        commitment=commit_loss,
        **joints.relative,
    )


class _JointTerms(NamedTuple):
    """The loss terms on joint positions (unweighted)."""

    positions: torch.Tensor
    velocity: torch.Tensor
    bone_length: torch.Tensor
    foot_contact: torch.Tensor
    relative: dict[str, torch.Tensor]  # PELVIS_RELATIVE_TERMS name -> term, in that order


def _joint_terms(
    predicted_geometry: Geometry,
    target_geometry: Geometry,
    *,
    frame_mask: torch.Tensor,
    weights: LossWeights,
    kind: LossKind,
    measure_unweighted: bool,
    zero: torch.Tensor,
) -> _JointTerms:
    """Positions, velocity, bone length, foot contact and the pelvis-relative terms of
    :func:`vq_losses`: all ``zero`` without positions on both sides, foot contact ``zero``
    without the target's contact labels."""
    relative = dict.fromkeys(PELVIS_RELATIVE_TERMS, zero)
    if predicted_geometry.positions is None or target_geometry.positions is None:
        return _JointTerms(zero, zero, zero, zero, relative)
    predicted, real = predicted_geometry.positions, target_geometry.positions
    positions = _masked_mean(elementwise_loss(predicted, real, kind), frame_mask)
    step_mask = frame_mask[:, 1:] & frame_mask[:, :-1]
    predicted_step, real_step = predicted[:, 1:] - predicted[:, :-1], real[:, 1:] - real[:, :-1]
    velocity = _masked_mean(elementwise_loss(predicted_step, real_step, kind), step_mask)
    for name, joints in PELVIS_RELATIVE_TERMS.items():
        relative[name] = _measured(
            getattr(weights, name),
            measure_unweighted,
            zero,
            partial(_pelvis_relative, predicted, real, joints, kind, frame_mask),
        )
    bones = _masked_mean(
        elementwise_loss(bone_lengths(predicted), bone_lengths(real), kind), frame_mask
    )
    foot_contact = zero
    if target_geometry.contacts is not None:
        # planted feet (GT label) must not slide in the reconstruction
        feet_step = predicted_step[:, :, list(FOOT_JOINTS)]  # (B, T-1, 4, 3)
        planted = target_geometry.contacts[:, :-1, :, None]
        foot_contact = _masked_mean(
            elementwise_loss(feet_step * planted, torch.zeros_like(feet_step), kind), step_mask
        )
    return _JointTerms(positions, velocity, bones, foot_contact, relative)


def _measured(
    weight: float, measure_unweighted: bool, zero: torch.Tensor, term: Callable[[], torch.Tensor]
) -> torch.Tensor:
    """``term()`` with a graph when ``weight`` is not 0; without one when it is 0 and
    ``measure_unweighted`` (a logged value only); else ``zero``, not computed at all."""
    if not (weight or measure_unweighted):
        return zero
    with torch.set_grad_enabled(torch.is_grad_enabled() and bool(weight)):
        return term()


def _pelvis_relative(
    predicted: torch.Tensor,
    real: torch.Tensor,
    joints: tuple[int, ...],
    kind: LossKind,
    frame_mask: torch.Tensor,
) -> torch.Tensor:
    """Loss of the (B, T, 22, 3) positions of ``joints`` relative to the pelvis."""
    index = list(joints)
    return _masked_mean(
        elementwise_loss(
            predicted[:, :, index] - predicted[:, :, :1], real[:, :, index] - real[:, :, :1], kind
        ),
        frame_mask,
    )
