"""Closed-form two-bone inverse kinematics for legs (sagittal plane) and arms (3D).

Positions then come from forward kinematics of the solved rotations, so bone lengths are those of
the body by construction; IK only decides where the feet and palms go.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F

_EPS = 1e-9


class LegAngles(NamedTuple):
    hip: torch.Tensor  # (...) rotation about the body x axis (negative = leg forward)
    knee: torch.Tensor  # (...) positive = flexion
    ankle: torch.Tensor  # (...) keeps the sole level


def _planar_angle(z: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Angle of the (z, y) vector, counter-clockwise from +z (forward) towards +y (up)."""
    return torch.atan2(y, z)


def leg_reach(thigh: torch.Tensor, shin: torch.Tensor) -> torch.Tensor:
    """Longest hip->ankle distance in the sagittal plane without hyperextending the knee:
    the rest-pose leg (SMPL's rest knee is already slightly flexed)."""
    return torch.linalg.vector_norm((thigh + shin)[..., 1:], dim=-1)


def solve_leg(target: torch.Tensor, thigh: torch.Tensor, shin: torch.Tensor) -> LegAngles:
    """Hip/knee/ankle pitch putting the ankle at `target`.

    target: (..., 2) ankle minus hip as (y, z) in the pelvis frame; thigh, shin: (3,) rest offsets
    of knee and ankle. Rotations about x leave the lateral coordinate alone, so only (y, z) of
    the offsets matter. Unreachable targets are clamped: the leg points at them, knee straight.
    """
    t_y, t_z = thigh[1], thigh[2]
    s_y, s_z = shin[1], shin[2]
    a = torch.hypot(t_y, t_z)
    b = torch.hypot(s_y, s_z)
    rest_bend = _planar_angle(s_z, s_y) - _planar_angle(t_z, t_y)  # < 0: the rest knee is flexed
    longest = leg_reach(thigh, shin)
    distance = torch.linalg.vector_norm(target, dim=-1).clamp((a - b).abs() + 1e-6, longest)
    cos_bend = ((distance.square() - a * a - b * b) / (2 * a * b)).clamp(-1.0, 1.0)
    bend = torch.acos(cos_bend)  # angle between thigh and shin directions, 0 = straight
    knee_planar = -bend - rest_bend  # the shin turns backwards (clockwise in (z, y))
    leg_z = t_z + torch.cos(knee_planar) * s_z - torch.sin(knee_planar) * s_y
    leg_y = t_y + torch.sin(knee_planar) * s_z + torch.cos(knee_planar) * s_y
    hip_planar = _planar_angle(target[..., 1], target[..., 0]) - _planar_angle(leg_z, leg_y)
    # A rotation by theta about +x turns (z, y) clockwise by theta: planar angle = -theta.
    hip, knee = -hip_planar, -knee_planar
    return LegAngles(hip=hip, knee=knee, ankle=-(hip + knee))


def _frame(primary: torch.Tensor, secondary: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) orthonormal frame with columns [primary, secondary, primary x secondary]."""
    return torch.stack((primary, secondary, torch.linalg.cross(primary, secondary, dim=-1)), dim=-1)


class ArmSolution(NamedTuple):
    upper: torch.Tensor  # (..., 3, 3) world rotation of the shoulder joint frame
    lower: torch.Tensor  # (..., 3, 3) world rotation of the elbow joint frame


def solve_arm(
    shoulder: torch.Tensor,
    target: torch.Tensor,
    pole: torch.Tensor,
    upper_bone: torch.Tensor,
    lower_bone: torch.Tensor,
) -> ArmSolution:
    """World frames of shoulder and elbow that put the palm at `target`.

    shoulder, target, pole: (..., 3) world shoulder position, palm target and a direction the
    elbow should bulge towards; upper_bone: (3,) elbow offset in the shoulder frame; lower_bone:
    (3,) palm centre in the elbow frame (wrist offset + hand centre, the wrist kept straight).
    The elbow is a hinge: in the rest frame it bends about r x (+Z), so the forearm folds to the
    front of the body; the upper-arm twist follows from where the elbow points.
    """
    a = torch.linalg.vector_norm(upper_bone)
    b = torch.linalg.vector_norm(lower_bone, dim=-1, keepdim=True)
    reach = target - shoulder
    distance = torch.linalg.vector_norm(reach, dim=-1, keepdim=True)
    direction = reach / distance.clamp_min(_EPS)
    distance = distance.clamp((a - b).abs() + 1e-4, (a + b) * (1 - 1e-6))
    side = F.normalize(
        pole - (pole * direction).sum(-1, keepdim=True) * direction, dim=-1, eps=_EPS
    )
    cos_shoulder = ((a * a + distance.square() - b * b) / (2 * a * distance)).clamp(-1.0, 1.0)
    sin_shoulder = torch.sqrt((1 - cos_shoulder.square()).clamp_min(0.0))
    upper_dir = cos_shoulder * direction + sin_shoulder * side
    elbow = shoulder + a * upper_dir
    lower_dir = F.normalize(shoulder + distance * direction - elbow, dim=-1, eps=_EPS)
    hinge = F.normalize(torch.linalg.cross(side, direction, dim=-1), dim=-1, eps=_EPS)
    forward = upper_bone.new_tensor([0.0, 0.0, 1.0])
    rest_upper, rest_lower = F.normalize(upper_bone, dim=-1), F.normalize(lower_bone, dim=-1)
    upper_rest = _frame(
        rest_upper, F.normalize(torch.linalg.cross(rest_upper, forward, dim=-1), dim=-1)
    )
    lower_rest = _frame(
        rest_lower,
        F.normalize(torch.linalg.cross(rest_lower, forward.expand_as(rest_lower), dim=-1), dim=-1),
    )
    upper = _frame(upper_dir, hinge) @ upper_rest.transpose(-1, -2)
    lower = _frame(lower_dir, hinge) @ lower_rest.transpose(-1, -2)
    return ArmSolution(upper=upper, lower=lower)
