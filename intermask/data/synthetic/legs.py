"""Pelvis and legs of one person: where the feet are, how the pelvis sways, and 3D leg IK.

The feet come first: the gait (or stillness) fixes each toe joint on the ground and each foot's
orientation (facing, toe-out, heel-off and heel-strike pitch). The pelvis then sways on top of the
plain walking pelvis (weight shift over the stance foot, swing-side drop, turn with the forward
leg, idle drift) and is lowered wherever a weight-bearing foot would be out of reach. Last, each
leg is solved from the swayed pelvis to its ankle: the hip gets twist, abduction and flexion, the
knee flexion and a tibial twist about the shin (which does not move the ankle), and the ankle
whatever rotation puts the foot in its planned orientation. Planted toes therefore stay exactly
where the gait put them, whatever the pelvis does.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from intermask.data.synthetic.ik import leg_reach, solve_leg
from intermask.data.synthetic.primitives import Gait, Walk, gait, smoothstep, still_gait
from intermask.data.synthetic.scene import PersonPlan
from intermask.data.synthetic.secondary import Secondary, about, euler_matrices, twist

_ARM_SWING = 0.45  # palm travel per metre of opposite-side foot lead while walking
_STANCE = 1e-6  # a foot lower than this above its rest height bears weight
_LIFTED = 0.05  # m of foot lift at which the pelvis has fully shifted over the other foot
_TOE_FLEX = 0.8  # share of the foot pitch the toes bend back: they stay flat on the ground
_SIGN = (1.0, -1.0)  # body-frame x sign of the left / right side


class Legs(NamedTuple):
    root: torch.Tensor  # (T, 3) world pelvis position
    pelvis: torch.Tensor  # (T, 3, 3) world pelvis orientation
    joints: dict[int, torch.Tensor]  # joint -> (T, 3, 3) local rotation, legs and feet
    swing: torch.Tensor  # (2, T) walking arm swing of the left / right palm (m, forward)
    pelvis_turn: torch.Tensor  # (T,) gait part of the pelvis yaw, for the chest to undo


def _ry(angle: torch.Tensor) -> torch.Tensor:
    return about(angle, 1)


def foot_pitch(steps: Gait, walk: Walk | None, sec: Secondary) -> torch.Tensor:
    """(2, T) left/right foot pitch (+x: heel up) rolling over the toe joint while walking.

    Step i swings one foot while the other stands. The standing foot lifts its heel over the
    second half of the step when it swings next; the swinging foot starts from that pitch, levels
    out, and lifts its toes just before landing flat (zero pitch at touch-down, so it never slides).
    """
    if walk is None:
        return torch.zeros_like(steps.lift)
    index = steps.phase.floor().clamp(0, walk.steps - 1)
    u = steps.phase - index
    lead_swings = (index.long() % 2) == 0
    next_swing = (index + 1 <= walk.steps - 1).to(u.dtype)  # the standing foot swings next
    stance = sec.heel_off * next_swing * smoothstep((u - 0.4) / 0.6)
    takeoff = sec.heel_off * (index >= 1).to(u.dtype) * (1 - smoothstep(u / 0.5))
    swinging = takeoff - sec.heel_strike * torch.sin(torch.pi * u).square() * u
    lead = torch.where(lead_swings, swinging, stance)
    trail = torch.where(lead_swings, stance, swinging)
    return torch.stack((lead, trail) if walk.lead == 0 else (trail, lead))


def _walk_start_frame(plan: PersonPlan, t: torch.Tensor) -> int:
    if plan.walk is None:
        return 0
    return int(
        torch.searchsorted(t, torch.tensor(plan.walk.start, dtype=t.dtype)).clamp_max(len(t) - 1)
    )


def _pelvis(
    plan: PersonPlan, lift: torch.Tensor, forward: torch.Tensor, sec: Secondary
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pelvis bends (T, 3), its gait yaw (T,) and shift (T, 3) in the heading frame."""
    loaded = smoothstep(lift / _LIFTED)  # (2, T): 1 while that foot is in the air
    off = loaded[1] - loaded[0]  # > 0: the right foot is up, the weight is on the left
    turn = -sec.gait_yaw * (forward[0] - forward[1])  # the hip of the leading leg comes forward
    bends = sec.pelvis.clone()
    bends[:, 1] += turn
    bends[:, 2] += sec.gait_roll * off  # +z lifts the left hip: the swing (right) side drops
    shift = torch.zeros(len(off), 3, dtype=off.dtype)
    shift[:, 0] = sec.gait_sway * off + sec.pelvis_shift[:, 0]  # +x: over the left foot
    shift[:, 2] = sec.pelvis_shift[:, 1]
    return bends, turn, shift


def pose_legs(plan: PersonPlan, t: torch.Tensor, sec: Secondary) -> Legs:
    """Root position and orientation and the local rotations of joints 1, 2, 4, 5, 7, 8, 10, 11."""
    body, offsets = plan.body, plan.body.offsets
    steps = gait(t, plan.walk) if plan.walk is not None else still_gait(t)
    lift = steps.lift + plan.foot_lift
    forward = steps.feet + plan.foot_forward
    heading = _ry(plan.yaw)  # (T, 3, 3)
    # The walk runs along the facing it starts with (turns happen before, while standing).
    walk_heading = plan.yaw[_walk_start_frame(plan, t)]
    base = torch.stack(
        (
            plan.position[0] + torch.sin(walk_heading) * steps.pelvis + plan.root_shift[:, 0],
            torch.zeros_like(t),
            plan.position[1] + torch.cos(walk_heading) * steps.pelvis + plan.root_shift[:, 1],
        ),
        -1,
    )
    bends, turn, shift = _pelvis(plan, lift, forward, sec)
    pelvis = heading @ euler_matrices(bends)
    root = base + (heading @ shift[..., None])[..., 0]
    height = torch.full_like(t, body.standing_root_height) - plan.dip - sec.soft_knees
    pitch = foot_pitch(steps, plan.walk, sec)
    ankles, feet, twists = [], [], []
    for side in (0, 1):
        hip, thigh, shin, toe = (offsets[j + side] for j in (1, 4, 7, 10))
        lateral = thigh[0] + shin[0]  # ankle x in the hip frame: x rotations keep it
        # Where the plain sagittal leg would put the ankle, then the toe joint: on the ground.
        dz = thigh[2] + shin[2] + forward[side] - steps.pelvis
        leg = torch.stack((torch.full_like(dz, float(lateral)), torch.zeros_like(dz), dz), -1)
        leg = (_ry(plan.hip_yaw[side]) @ leg[..., None])[..., 0]
        flat = base + (heading @ (hip + leg)[..., None])[..., 0]
        flat[:, 1] = -toe[1] + lift[side]  # a flat foot puts the toe joint on the ground
        facing = _ry(plan.yaw + plan.hip_yaw[side] + _SIGN[side] * sec.toe_out)
        toe_point = flat + (facing @ toe)
        foot = (
            facing
            @ about(pitch[side], 0)
            @ about(torch.tensor(sec.foot_tilt[side], dtype=t.dtype), 2)
        )
        ankles.append(toe_point - (foot @ toe))  # the foot rolls over its toe joint
        feet.append(foot)
        # A weight-bearing foot must stay reachable: lower the pelvis rather than lift the foot.
        reach = torch.sqrt(leg_reach(thigh, shin) ** 2 + lateral**2) * (1 - 1e-6)
        hip_world = pelvis @ hip  # (T, 3) hip relative to the root
        gap = ankles[side] - root - hip_world
        across = gap[:, 0].square() + gap[:, 2].square()
        limit = (
            ankles[side][:, 1] - hip_world[:, 1] + torch.sqrt((reach**2 - across).clamp_min(1e-6))
        )
        height = torch.where(lift[side] < _STANCE, torch.minimum(height, limit), height)
        twists.append(plan.hip_yaw[side] + _SIGN[side] * (0.5 * sec.toe_out + sec.hip_twist[side]))
    root = root.clone()
    root[:, 1] = height
    joints: dict[int, torch.Tensor] = {}
    for side in (0, 1):
        joints.update(
            _solve_side(side, offsets, root, pelvis, ankles[side], feet[side], twists[side], sec)
        )
        joints[10 + side] = about(-_TOE_FLEX * pitch[side], 0) @ euler_matrices(sec.toes[side])
    swing = torch.stack([(steps.feet[1 - side] - steps.pelvis) * _ARM_SWING for side in (0, 1)])
    return Legs(root=root, pelvis=pelvis, joints=joints, swing=swing, pelvis_turn=turn)


def _solve_side(
    side: int,
    offsets: torch.Tensor,
    root: torch.Tensor,
    pelvis: torch.Tensor,
    ankle: torch.Tensor,
    foot: torch.Tensor,
    hip_twist: torch.Tensor,
    sec: Secondary,
) -> dict[int, torch.Tensor]:
    """Hip = Ry(twist) Rz(abduction) Rx(flexion), knee = Rx(flexion) then a tibial twist, ankle =
    the rest of the way to the foot orientation. The sagittal solver handles flexion once the
    twist is undone and the abduction swings the leg's lateral offset onto the target's."""
    hip, thigh, shin = offsets[1 + side], offsets[4 + side], offsets[7 + side]
    lateral = thigh[0] + shin[0]
    target = (pelvis.transpose(-1, -2) @ (ankle - root)[..., None])[..., 0] - hip
    untwisted = (_ry(-hip_twist) @ target[..., None])[..., 0]
    x, y, z = untwisted.unbind(-1)
    down = -torch.sqrt((x.square() + y.square() - lateral**2).clamp_min(1e-9))
    angles = solve_leg(torch.stack((down, z), -1), thigh, shin)
    abduction = torch.atan2(y, x) - torch.atan2(down, lateral.expand_as(down))
    hip_rotation = _ry(hip_twist) @ about(abduction, 2) @ about(angles.hip, 0)
    # Screw-home: the tibia turns inwards as the knee flexes; about the shin axis the ankle stays.
    tibia = _SIGN[side] * (sec.knee_twist[side] - sec.screw_home * angles.knee)
    knee = about(angles.knee, 0) @ twist(-shin.expand(len(tibia), 3), tibia)
    ankle_rotation = (pelvis @ hip_rotation @ knee).transpose(-1, -2) @ foot
    return {1 + side: hip_rotation, 4 + side: knee, 7 + side: ankle_rotation}
