"""Turn a :class:`~intermask.data.synthetic.scene.Scene` into joint rotations and positions.

Pass 1 poses pelvis and legs (:mod:`~intermask.data.synthetic.legs`: planted feet, 3D leg IK),
spine and head of both people with relaxed arms; pass 2 turns the head towards the partner,
shrugs the collars with the arms, and solves every arm against its palm target (which may depend
on the partner's pass-1 body), then runs forward kinematics again. Secondary motion
(:mod:`~intermask.data.synthetic.secondary`) is added before each solve, so it never pulls a
planted foot or a touching palm away. All positions come from
:func:`intermask.motion.kinematics.forward_kinematics`, so bone lengths never change.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import torch

from intermask.data.synthetic.body import BodyShape, hand_positions
from intermask.data.synthetic.ik import solve_arm
from intermask.data.synthetic.legs import pose_legs
from intermask.data.synthetic.scene import ArmPlan, PersonPlan, Scene, Stage
from intermask.data.synthetic.secondary import (
    Secondary,
    about,
    collar_bends,
    euler_matrices,
    look_at,
    sample_secondary,
    twist,
)
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.skeleton import NUM_JOINTS

_SPINE_SHARE = {3: 0.35, 6: 0.35, 9: 0.30}  # a bend spreads over spine1..3
_HEAD_SHARE = {12: 0.5, 15: 0.5}  # and over neck and head
_LOOK_SHARE = {12: 0.4, 15: 0.6}  # the head itself turns most when looking round


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


def _pass1(plan: PersonPlan, t: torch.Tensor, sec: Secondary) -> _Pass1:
    legs = pose_legs(plan, t, sec)
    euler = torch.zeros(len(t), NUM_JOINTS, 3, dtype=torch.float64)
    for k, (joint, share) in enumerate(_SPINE_SHARE.items()):
        euler[:, joint] = plan.spine * share + sec.spine[k]
        # The chest turns back against the walking pelvis, so the shoulders keep facing ahead.
        euler[:, joint, 1] -= sec.counter_rotation * share * legs.pelvis_turn
    for k, (joint, share) in enumerate(_HEAD_SHARE.items()):
        euler[:, joint] = plan.head * share + sec.neck_head[k]
    local = euler_matrices(euler)
    local[:, 0] = legs.pelvis
    for joint, rotation in legs.joints.items():
        local[:, joint] = rotation
    fk = forward_kinematics(local, legs.root, plan.body.offsets)
    return _Pass1(local, legs.root, fk.positions, fk.global_rotations, legs.swing)


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


def _pass2(
    plan: PersonPlan, first: _Pass1, stage: Stage, sec: Secondary, partner_head: torch.Tensor
) -> PersonMotion:
    body: BodyShape = plan.body
    local = first.local.clone()
    chest = first.rotations[:, 9]
    gaze = look_at(first.positions[:, 15], partner_head, chest, sec)
    for joint, share in _LOOK_SHARE.items():
        local[:, joint] = euler_matrices(gaze * share) @ local[:, joint]
    # Gestures live in the heading frame (facing only): a hanging arm keeps hanging when the
    # person bows or the pelvis sways, and a raised hand stays raised when they lean.
    heading = about(plan.yaw, 1)
    for side, arm in enumerate(plan.arms):
        swing = torch.zeros_like(arm.local)
        swing[:, 2] = first.swing[side]
        swung = ArmPlan(local=arm.local + swing, pole=arm.pole + sec.pole[side], cues=arm.cues)
        # The collar follows where the palm is going, which moves the shoulder the arm hangs from.
        target, _ = _palm_target(swung, first.positions[:, 16 + side], heading, stage)
        reach = (target - first.positions[:, 16 + side]) / body.reach
        collar = euler_matrices(collar_bends(reach, heading, side, sec))
        local[:, 13 + side] = collar
        collar_world = chest @ collar
        shoulder = first.positions[:, 13 + side] + collar_world @ body.offsets[16 + side]
        target, pole = _palm_target(swung, shoulder, heading, stage)
        # A bent wrist moves the palm: the forearm aims at the palm centre as the wrist holds it.
        wrist = euler_matrices(sec.wrist[side])
        lower_bone = body.offsets[20 + side] + wrist @ body.hand[side, :15].mean(0)
        solved = solve_arm(shoulder, target, pole, body.offsets[18 + side], lower_bone)
        # Pronation turns the forearm about the elbow->palm line: the palm centre stays put.
        forearm = solved.lower @ twist(lower_bone, sec.pronation[side])
        local[:, 16 + side] = collar_world.transpose(-1, -2) @ solved.upper
        local[:, 18 + side] = solved.upper.transpose(-1, -2) @ forearm
        local[:, 20 + side] = wrist
    fk = forward_kinematics(local, first.root, body.offsets)
    hands = hand_positions(fk.positions[:, 20:22], fk.global_rotations[:, 20:22], body)
    return PersonMotion(positions=fk.positions, local_rotations=local, hands=hands)


def realize(scene: Scene, rng: np.random.Generator) -> tuple[PersonMotion, PersonMotion]:
    """Pose both people of a scene ([actor, reactor] order); rng draws their secondary motion."""
    secondary = [sample_secondary(rng, scene.t, plan.body.stature) for plan in scene.persons]
    first = [_pass1(plan, scene.t, sec) for plan, sec in zip(scene.persons, secondary, strict=True)]
    stage = Stage(
        positions=torch.stack([f.positions for f in first]),
        chest=torch.stack([f.rotations[:, 9] for f in first]),
    )
    actor, reactor = (
        _pass2(plan, f, stage, sec, first[1 - k].positions[:, 15])
        for k, (plan, f, sec) in enumerate(zip(scene.persons, first, secondary, strict=True))
    )
    return actor, reactor
