"""Turn a :class:`~intermask.data.synthetic.scene.Scene` into joint rotations and positions.

Pass 1 poses root, legs (sagittal IK against the ground), spine and head of both people with
relaxed arms; pass 2 solves every arm against its palm target (which may depend on the partner's
pass-1 body) and runs forward kinematics again. All positions come from
:func:`intermask.motion.kinematics.forward_kinematics`, so bone lengths never change.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from intermask.data.synthetic.body import BodyShape, hand_positions
from intermask.data.synthetic.ik import leg_reach, solve_arm, solve_leg
from intermask.data.synthetic.primitives import gait, still_gait
from intermask.data.synthetic.scene import ArmPlan, PersonPlan, Scene, Stage
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.rotations import rotation_about_axis
from intermask.motion.skeleton import NUM_JOINTS

_SPINE_SHARE = {3: 0.35, 6: 0.35, 9: 0.30}  # a bend spreads over spine1..3
_HEAD_SHARE = {12: 0.5, 15: 0.5}  # and over neck and head
_ARM_SWING = 0.45  # palm travel per metre of opposite-side foot lead while walking
_STANCE = 1e-6  # a foot lower than this above its rest height bears weight


class PersonMotion(NamedTuple):
    positions: torch.Tensor  # (T, 22, 3) Y-up world joints
    local_rotations: torch.Tensor  # (T, 22, 3, 3); row 0 is the root's world orientation
    hands: torch.Tensor  # (T, 40, 3) finger joints and tips (see body.hand_positions)


class _Pass1(NamedTuple):
    local: torch.Tensor  # (T, 22, 3, 3)
    root: torch.Tensor  # (T, 3)
    positions: torch.Tensor  # (T, 22, 3)
    rotations: torch.Tensor  # (T, 22, 3, 3) world
    swing: torch.Tensor  # (2, T) walking arm swing of the left / right palm (m, forward)


def _euler_matrices(angles: torch.Tensor) -> torch.Tensor:
    """(..., 3) bends (x, y, z) -> (..., 3, 3) = Rx Ry Rz."""
    rx = rotation_about_axis(angles[..., 0], "x")
    ry = rotation_about_axis(angles[..., 1], "y")
    rz = rotation_about_axis(angles[..., 2], "z")
    return rx @ ry @ rz


def _legs(
    plan: PersonPlan, t: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Leg pitches (T, 2, 3) [hip, knee, ankle] per side, pelvis height (T,), pelvis travel (T,)
    and the walking arm swing (2, T): each palm moves with the opposite foot."""
    body, offsets = plan.body, plan.body.offsets
    steps = gait(t, plan.walk) if plan.walk is not None else still_gait(t)
    ground_to_ankle = -float(offsets[10, 1])  # a flat foot puts the foot joint on the ground
    lift = steps.lift + plan.foot_lift
    height = body.standing_root_height - plan.dip
    dz, hips = [], []
    for side in (0, 1):
        hip, thigh, shin = offsets[1 + side], offsets[4 + side], offsets[7 + side]
        dz.append(thigh[2] + shin[2] + steps.feet[side] - steps.pelvis + plan.foot_forward[side])
        hips.append(hip)
        # A weight-bearing foot must stay reachable: lower the pelvis rather than lift the foot.
        reach = leg_reach(thigh, shin) * (1 - 1e-6)
        limit = ground_to_ankle - hip[1] + torch.sqrt((reach**2 - dz[side] ** 2).clamp_min(1e-6))
        height = torch.where(lift[side] < _STANCE, torch.minimum(height, limit), height)
    angles = []
    for side in (0, 1):
        dy = ground_to_ankle + lift[side] - (height + hips[side][1])
        solved = solve_leg(torch.stack((dy, dz[side]), -1), offsets[4 + side], offsets[7 + side])
        angles.append(torch.stack(solved, -1))
    swing = torch.stack([(steps.feet[1 - side] - steps.pelvis) * _ARM_SWING for side in (0, 1)])
    return torch.stack(angles, 1), height, steps.pelvis, swing


def _pass1(plan: PersonPlan, t: torch.Tensor) -> _Pass1:
    legs, height, travel, swing = _legs(plan, t)
    euler = torch.zeros(len(t), NUM_JOINTS, 3, dtype=torch.float64)
    for joint, share in _SPINE_SHARE.items():
        euler[:, joint] = plan.spine * share
    for joint, share in _HEAD_SHARE.items():
        euler[:, joint] = plan.head * share
    for side in (0, 1):
        for k, joint in enumerate((1, 4, 7)):
            euler[:, joint + side, 0] = legs[:, side, k]
    local = _euler_matrices(euler)
    for side in (0, 1):
        # Twist first, then pitch inside the twisted leg: the ankle still levels the sole.
        local[:, 1 + side] = rotation_about_axis(plan.hip_yaw[side], "y") @ local[:, 1 + side]
    local[:, 0] = rotation_about_axis(plan.yaw, "y")
    # The walk runs along the facing it starts with (turns happen before, while standing).
    heading = plan.yaw[_walk_start_frame(plan, t)]
    x = plan.position[0] + torch.sin(heading) * travel + plan.root_shift[:, 0]
    z = plan.position[1] + torch.cos(heading) * travel + plan.root_shift[:, 1]
    root = torch.stack((x, height, z), -1)
    fk = forward_kinematics(local, root, plan.body.offsets)
    return _Pass1(local, root, fk.positions, fk.global_rotations, swing)


def _walk_start_frame(plan: PersonPlan, t: torch.Tensor) -> int:
    if plan.walk is None:
        return 0
    return int(
        torch.searchsorted(t, torch.tensor(plan.walk.start, dtype=t.dtype)).clamp_max(len(t) - 1)
    )


def _palm_target(
    arm: ArmPlan, shoulder: torch.Tensor, frame: torch.Tensor, stage: Stage
) -> tuple[torch.Tensor, torch.Tensor]:
    """Blend the local gesture (in `frame`, (T, 3, 3)) and the world cues -> world palm target
    (T, 3) and elbow pole direction (T, 3)."""
    local = shoulder + (frame @ arm.local[..., None])[..., 0]
    if not arm.cues:
        return local, (frame @ arm.pole[..., None])[..., 0]
    weights = torch.stack([cue.weight for cue in arm.cues])  # (K, T)
    total = weights.sum(0)
    weights = weights / total.clamp_min(1.0)  # overlapping cues share, never overshoot
    rest = (1 - total.clamp_max(1.0))[:, None]
    target = rest * local
    pole = rest * arm.pole
    for cue, weight in zip(arm.cues, weights, strict=True):
        target = target + weight[:, None] * cue.target(stage)
        pole = pole + weight[:, None] * torch.tensor(cue.pole, dtype=torch.float64)
    return target, (frame @ pole[..., None])[..., 0]


def _pass2(plan: PersonPlan, first: _Pass1, stage: Stage) -> PersonMotion:
    body: BodyShape = plan.body
    local = first.local.clone()
    # Gestures live in the heading frame (root yaw only): a hanging arm keeps hanging when the
    # person bows, and a raised hand stays raised when they lean.
    heading = first.rotations[:, 0]
    for side, arm in enumerate(plan.arms):
        shoulder = first.positions[:, 16 + side]
        swing = torch.zeros_like(arm.local)
        swing[:, 2] = first.swing[side]
        swung = ArmPlan(local=arm.local + swing, pole=arm.pole, cues=arm.cues)
        target, pole = _palm_target(swung, shoulder, heading, stage)
        lower_bone = body.offsets[20 + side] + body.hand[side, :15].mean(0)
        solved = solve_arm(shoulder, target, pole, body.offsets[18 + side], lower_bone)
        local[:, 16 + side] = first.rotations[:, 13 + side].transpose(-1, -2) @ solved.upper
        local[:, 18 + side] = solved.upper.transpose(-1, -2) @ solved.lower
        local[:, 20 + side] = torch.eye(3, dtype=torch.float64)
    fk = forward_kinematics(local, first.root, body.offsets)
    hands = hand_positions(fk.positions[:, 20:22], fk.global_rotations[:, 20:22], body)
    return PersonMotion(positions=fk.positions, local_rotations=local, hands=hands)


def realize(scene: Scene) -> tuple[PersonMotion, PersonMotion]:
    """Pose both people of a scene ([actor, reactor] order)."""
    first = [_pass1(plan, scene.t) for plan in scene.persons]
    stage = Stage(
        positions=torch.stack([f.positions for f in first]),
        chest=torch.stack([f.rotations[:, 9] for f in first]),
    )
    actor, reactor = (_pass2(plan, f, stage) for plan, f in zip(scene.persons, first, strict=True))
    return actor, reactor
