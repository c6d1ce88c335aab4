"""Interactions at a distance or with near misses: wave, bow, punch/dodge, kick/block, dance.

Wave and bow keep the two people well apart (> 1.7 m); the punch is aimed at where the reactor's
head was and stops short; the kick stops at the reactor's guard.
Scene frame: actor at the origin facing +Z, reactor ahead facing -Z (see choreography.py).
"""

from __future__ import annotations

import math

import torch

from intermask.data.synthetic.body import SIDE_SIGN
from intermask.data.synthetic.choreography import Setup, face_to_face, walk, walk_end
from intermask.data.synthetic.primitives import bump, wave
from intermask.data.synthetic.scene import FPS, ArmPlan, Scene, Stage


def _offset(reach: float, x: float, y: float, z: float) -> torch.Tensor:
    """Palm offset from the shoulder in units of the arm reach."""
    return torch.tensor([x * reach, y * reach, z * reach], dtype=torch.float64)


def _raise_and_wave(
    arm: ArmPlan,
    t: torch.Tensor,
    *,
    side: int,
    reach: float,
    start: float,
    rise: float,
    hold: float,
    fall: float,
    frequency: float,
) -> None:
    """Hand up beside the head, waving side to side."""
    sign = SIDE_SIGN[side]
    raised = _offset(reach, sign * 0.42, 0.38, 0.18).expand(len(t), 3).clone()
    raised[:, 0] += sign * 0.14 * reach * wave(t, start + rise, frequency)
    arm.blend(bump(t, start, rise, hold, fall), raised, (sign, -1.0, 0.0))


def wave_back(setup: Setup) -> Scene:
    """The actor waves; once the raised hand is visible the reactor waves back."""
    side = setup.side
    distance = setup.uniform(2.0, 4.0) * setup.scale
    frequency = setup.uniform(1.6, 2.2) * setup.speed
    rise, fall = setup.seconds(0.5), setup.seconds(0.6)
    hold = setup.integer(2, 4) / frequency
    start_reactor = setup.onset + rise + setup.delay
    hold_reactor = setup.integer(2, 4) / frequency
    end = max(setup.onset + rise + hold, start_reactor + rise + hold_reactor) + fall
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    t = scene.t
    _raise_and_wave(
        scene.persons[0].arms[side],
        t,
        side=side,
        reach=setup.bodies[0].reach,
        start=setup.onset,
        rise=rise,
        hold=hold,
        fall=fall,
        frequency=frequency,
    )
    reactor_side = setup.integer(0, 1)
    _raise_and_wave(
        scene.persons[1].arms[reactor_side],
        t,
        side=reactor_side,
        reach=setup.bodies[1].reach,
        start=start_reactor,
        rise=rise,
        hold=hold_reactor,
        fall=fall,
        frequency=frequency,
    )
    return scene


def bow(setup: Setup) -> Scene:
    """The actor bows; the reactor bows in return."""
    distance = setup.uniform(1.8, 2.6) * setup.scale
    down, up = setup.seconds(0.8), setup.seconds(0.8)
    hold = setup.uniform(0.3, 0.8)
    start_reactor = setup.onset + 0.5 * down + setup.delay
    hold_reactor = setup.uniform(0.3, 0.8)
    end = max(setup.onset + down + hold, start_reactor + down + hold_reactor) + up
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    t = scene.t
    for person, (start, held) in enumerate(((setup.onset, hold), (start_reactor, hold_reactor))):
        weight = bump(t, start, down, held, up)
        scene.persons[person].spine[:, 0] += setup.uniform(0.45, 0.8) * weight
        scene.persons[person].head[:, 0] += 0.15 * weight
    return scene


def _guard(arm: ArmPlan, t: torch.Tensor, *, side: int, reach: float, weight: torch.Tensor) -> None:
    """Fists up in front of the chin."""
    sign = SIDE_SIGN[side]
    arm.blend(weight, _offset(reach, -sign * 0.2, 0.12, 0.45), (sign, -1.0, -0.2))


def punch_dodge(setup: Setup) -> Scene:
    """The actor raises a guard and throws a punch at the reactor's head; the reactor leans away
    and steps back, so the fist stops short of where the head was."""
    side = setup.side
    distance = setup.uniform(0.85, 1.05) * setup.scale
    guard_time = setup.seconds(0.4)
    punch = setup.onset + guard_time + setup.uniform(0.1, 0.3)
    strike, retract = setup.seconds(0.18), setup.seconds(0.35)
    start_reactor = punch + 0.5 * setup.delay
    dodge = walk(
        setup,
        start=start_reactor + setup.seconds(0.1),
        distance=-0.3 * setup.scale,
        step_length=0.3,
        step_time=0.3,
        lift=0.05,
    )
    end = max(punch + strike + 0.08 + retract, walk_end(dodge)) + setup.seconds(0.5)
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    t = scene.t
    actor, reactor = scene.persons
    guard = bump(
        t,
        setup.onset,
        guard_time,
        end - setup.onset - guard_time - setup.seconds(0.5),
        setup.seconds(0.5),
    )
    for arm_side in (0, 1):
        _guard(actor.arms[arm_side], t, side=arm_side, reach=setup.bodies[0].reach, weight=guard)
    punch_frame = int(round(punch * FPS))

    def short_of_head(stage: Stage) -> torch.Tensor:
        head = stage.positions[1, min(punch_frame, stage.positions.shape[1] - 1), 15]
        towards_actor = stage.positions[0, 0, 16 + side] - head
        return (head + 0.15 * towards_actor / towards_actor.norm()).expand(
            stage.positions.shape[1], 3
        )

    swing = bump(t, punch, strike, 0.08, retract)
    actor.arms[side].reach_to(swing, short_of_head, (SIDE_SIGN[side], -1.0, 0.0))
    actor.spine[:, 0] += 0.15 * swing
    actor.spine[:, 1] -= SIDE_SIGN[side] * 0.3 * swing  # the punching shoulder turns forward
    reactor.walk = dodge
    lean = bump(t, start_reactor, setup.seconds(0.25), setup.seconds(0.4), setup.seconds(0.7))
    reactor.spine[:, 0] -= 0.3 * lean
    reactor.spine[:, 2] += setup.rng.choice((-1.0, 1.0)) * 0.25 * lean
    for arm_side in (0, 1):
        _guard(reactor.arms[arm_side], t, side=arm_side, reach=setup.bodies[1].reach, weight=lean)
    return scene


def kick_block(setup: Setup) -> Scene:
    """The actor kicks with one leg; the reactor crosses the forearms and steps back."""
    side = setup.side
    distance = setup.uniform(1.0, 1.2) * setup.scale
    kick = setup.onset + setup.seconds(0.4)
    extend, hold, recoil = setup.seconds(0.3), setup.seconds(0.1), setup.seconds(0.4)
    start_reactor = kick + 0.5 * setup.delay
    retreat = walk(
        setup,
        start=start_reactor + setup.seconds(0.15),
        distance=-0.25 * setup.scale,
        step_length=0.25,
        step_time=0.3,
        lift=0.05,
    )
    end = max(kick + extend + hold + recoil, walk_end(retreat)) + setup.seconds(0.6)
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    t = scene.t
    actor, reactor = scene.persons
    guard = bump(
        t,
        setup.onset,
        setup.seconds(0.35),
        end - setup.onset - setup.seconds(0.95),
        setup.seconds(0.6),
    )
    for arm_side in (0, 1):
        _guard(actor.arms[arm_side], t, side=arm_side, reach=setup.bodies[0].reach, weight=guard)
    strike = bump(t, kick, extend, hold, recoil)
    actor.foot_forward[side] += setup.uniform(0.45, 0.6) * setup.scale * strike
    actor.foot_lift[side] += setup.uniform(0.35, 0.5) * setup.scale * strike
    actor.spine[:, 0] -= 0.2 * strike  # lean back to balance the raised leg
    reactor.walk = retreat
    block = bump(t, start_reactor, setup.seconds(0.25), setup.seconds(0.5), setup.seconds(0.6))
    reach = setup.bodies[1].reach
    for arm_side, arm in enumerate(reactor.arms):
        sign = SIDE_SIGN[arm_side]
        arm.blend(block, _offset(reach, -sign * 0.35, -0.45, 0.55), (sign, -0.5, -0.5))
    reactor.spine[:, 0] += 0.15 * block
    return scene


def dance(setup: Setup) -> Scene:
    """The actor starts dancing to a beat; the reactor joins on a later beat, in sync."""
    distance = setup.uniform(1.3, 2.0) * setup.scale
    beat = min(max(setup.uniform(1.6, 2.1) * setup.speed, 1.2), 2.8)  # beats per second
    fade = setup.seconds(0.6)
    length = setup.uniform(3.0, 6.0)
    join = setup.onset + math.ceil((setup.delay + 0.4) * beat) / beat  # on the actor's beat grid
    end = setup.onset + fade + length + fade
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    t = scene.t
    style = setup.integer(0, 1)
    for person, start in enumerate((setup.onset, join)):
        weight = bump(t, start, fade, end - fade - start - fade, fade)
        plan = scene.persons[person]
        # Both people share the actor's beat phase: that is what "in sync" means here.
        bounce = (1 - torch.cos(2 * math.pi * beat * (t - setup.onset))) / 2
        plan.dip += 0.05 * setup.scale * bounce * weight
        plan.spine[:, 1] += 0.25 * wave(t, setup.onset, beat / 2) * weight
        plan.spine[:, 2] += 0.08 * wave(t, setup.onset, beat / 2) * weight
        plan.head[:, 0] += 0.1 * wave(t, setup.onset, beat) * weight
        reach = setup.bodies[person].reach
        for side, arm in enumerate(plan.arms):
            sign = SIDE_SIGN[side]
            moving = _offset(reach, sign * 0.45, 0.0, 0.35).expand(len(t), 3).clone()
            if style == 0:  # arms pump up and down in turn
                moving[:, 1] += 0.35 * reach * wave(t, setup.onset, beat / 2, side * math.pi)
            else:  # both arms up, swaying together
                moving[:, 1] += 0.45 * reach
                moving[:, 0] += 0.25 * reach * wave(t, setup.onset, beat / 2)
            arm.blend(weight, moving, (sign, -1.0, 0.0))
    return scene
