"""Interactions in which the two bodies touch: handshake, hug, push, high five, pass, shoulder pat.

Spacing is derived from the two bodies' arm reach (``contact_distance``) so the palms really meet:
the contact targets are world points computed from both bodies, and the arm IK reaches them.
Scene frame: actor at the origin facing +Z, reactor ahead facing -Z (see choreography.py).
"""

from __future__ import annotations

import math

import torch

from intermask.data.synthetic.body import SIDE_SIGN, forward_reach
from intermask.data.synthetic.choreography import (
    Setup,
    contact_distance,
    face_to_face,
    meeting_point,
    walk,
    walk_end,
)
from intermask.data.synthetic.primitives import bump, ramp, wave
from intermask.data.synthetic.scene import Scene, Stage, Target, partner_point

_PALM_GAP = 0.025  # metres between two touching palm centres
_REACH_POLE = (0.0, -1.0, -0.2)  # elbow down and a little back for a forward reach


def _reach_pole(side: int) -> tuple[float, float, float]:
    return (SIDE_SIGN[side] * 0.6, _REACH_POLE[1], _REACH_POLE[2])


def _lean(scene: Scene, person: int, weight: torch.Tensor, amount: float) -> None:
    """Bend the spine forward (positive) or back (negative) by `amount` radians times weight."""
    scene.persons[person].spine[:, 0] += amount * weight


def handshake(setup: Setup) -> Scene:
    """The actor offers a hand; after a delay the reactor takes it; a few pumps; release."""
    side = setup.side
    height = setup.shoulder_height - setup.uniform(0.25, 0.33) * setup.scale
    lateral = float(setup.bodies[0].shoulder[0])
    distance = contact_distance(setup, height=height, lateral=lateral, fraction=(0.86, 0.92))
    reach_actor = setup.seconds(0.7)
    start_reactor = setup.onset + reach_actor * 0.5 + setup.delay
    contact = start_reactor + setup.seconds(0.6)
    frequency = 2.2 * setup.speed
    hold = setup.integer(2, 4) / frequency
    release = contact + hold + 0.1
    scene = face_to_face(
        setup, distance=distance, seconds=release + setup.seconds(0.7) + setup.tail
    )
    t = scene.t
    pump = (
        0.035 * setup.scale * wave(t, contact, frequency) * bump(t, contact, 0.05, hold - 0.1, 0.05)
    )
    joints = (16 + side, 16 + side)  # same hand on both sides: the shoulders are diagonal
    for person, (start, rise) in enumerate(
        ((setup.onset, reach_actor), (start_reactor, contact - start_reactor))
    ):
        weight = bump(t, start, rise, release - start - rise, setup.seconds(0.7))
        target = meeting_point(
            joints=joints, time=contact, height=height, lift=pump, across=(0.5 - person) * _PALM_GAP
        )
        scene.persons[person].arms[side].reach_to(weight, target, _reach_pole(side))
        _lean(scene, person, weight, 0.08)
    return scene


def high_five(setup: Setup) -> Scene:
    """The actor raises a hand, the reactor answers with the opposite hand; a short slap."""
    side, other = setup.side, 1 - setup.side
    height = setup.shoulder_height + setup.uniform(0.18, 0.28) * setup.scale
    distance = contact_distance(
        setup, height=height, lateral=0.04 * setup.scale, fraction=(0.72, 0.85)
    )
    raise_time = setup.seconds(0.5)
    start_reactor = setup.onset + raise_time * 0.5 + setup.delay
    contact = start_reactor + setup.seconds(0.6)
    swing = setup.seconds(0.15)
    scene = face_to_face(
        setup, distance=distance, seconds=contact + setup.seconds(0.7) + setup.tail + 0.1
    )
    t = scene.t
    joints = (16 + side, 16 + other)  # actor's right meets reactor's left: same side of the pair
    slap = meeting_point(joints=joints, time=contact, height=height, along=-_PALM_GAP / 2)
    ready = meeting_point(
        joints=joints, time=contact, height=height - 0.05, along=-0.18 * setup.scale
    )
    actor = scene.persons[0].arms[side]
    actor.reach_to(
        bump(t, setup.onset, raise_time, contact - swing - setup.onset - raise_time, swing),
        ready,
        _reach_pole(side),
    )
    actor.reach_to(
        bump(t, contact - swing, swing, 0.05, setup.seconds(0.6)), slap, _reach_pole(side)
    )
    reactor_slap = meeting_point(joints=joints, time=contact, height=height, along=_PALM_GAP / 2)
    scene.persons[1].arms[other].reach_to(
        bump(t, start_reactor, contact - start_reactor, 0.05, setup.seconds(0.6)),
        reactor_slap,
        _reach_pole(other),
    )
    return scene


def pass_object(setup: Setup) -> Scene:
    """The actor holds out an object; the reactor takes it and brings it to their chest."""
    side = setup.side
    height = setup.shoulder_height - setup.uniform(0.28, 0.36) * setup.scale
    lateral = float(setup.bodies[0].shoulder[0])
    distance = contact_distance(setup, height=height, lateral=lateral, fraction=(0.86, 0.92))
    offer = setup.seconds(0.8)
    start_reactor = setup.onset + offer * 0.6 + setup.delay
    contact = start_reactor + setup.seconds(0.7)
    handover = contact + setup.seconds(0.35)
    scene = face_to_face(
        setup, distance=distance, seconds=handover + setup.seconds(1.4) + setup.tail
    )
    t = scene.t
    joints = (16 + side, 16 + side)
    give = meeting_point(joints=joints, time=contact, height=height - _PALM_GAP / 2, across=0.0)
    take = meeting_point(joints=joints, time=contact, height=height + _PALM_GAP / 2, across=0.0)
    scene.persons[0].arms[side].reach_to(
        bump(t, setup.onset, offer, handover - setup.onset - offer, setup.seconds(0.7)),
        give,
        _reach_pole(side),
    )
    reactor = scene.persons[1].arms[side]
    reactor.reach_to(
        bump(t, start_reactor, contact - start_reactor, handover - contact, setup.seconds(0.7)),
        take,
        _reach_pole(side),
    )
    reach = setup.bodies[1].reach
    hold = torch.tensor(
        [-SIDE_SIGN[side] * 0.15 * reach, -0.55 * reach, 0.45 * reach], dtype=torch.float64
    )
    reactor.blend(ramp(t, handover, setup.seconds(0.7)), hold, (SIDE_SIGN[side], -1.0, 0.0))
    return scene


def pat_shoulder(setup: Setup) -> Scene:
    """The actor pats the reactor's shoulder; the reactor pats back on the actor's shoulder."""
    side, other = setup.side, 1 - setup.side
    # Hand on top of the partner's shoulder on the same side of the pair (actor's right hand on
    # the reactor's left shoulder): reach straight ahead, a little above shoulder height.
    forward = [
        setup.uniform(0.86, 0.92) * body.reach + 2 * float(body.shoulder[2]) + 0.03
        for body in setup.bodies
    ]
    distance = min(forward)
    frequency = 2.5 * setup.speed
    reach_time = setup.seconds(0.6)
    contact = setup.onset + reach_time
    hold = setup.integer(2, 3) / frequency
    start_reactor = contact + setup.delay
    hold_reactor = setup.integer(2, 3) / frequency
    end = max(contact + hold, start_reactor + reach_time + hold_reactor) + setup.seconds(0.6)
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    t = scene.t
    pats = 0.03 * setup.scale * (wave(t, contact, frequency, -math.pi / 2) + 1) / 2
    on_reactor = partner_point(1, 16 + other, (0.0, 0.06, 0.03))
    scene.persons[0].arms[side].reach_to(
        bump(t, setup.onset, reach_time, hold, setup.seconds(0.6)),
        _lifted(on_reactor, pats),
        _reach_pole(side),
    )
    on_actor = partner_point(0, 16 + other, (0.0, 0.06, 0.03))
    reactor_pats = (
        0.03 * setup.scale * (wave(t, start_reactor + reach_time, frequency, -math.pi / 2) + 1) / 2
    )
    scene.persons[1].arms[side].reach_to(
        bump(t, start_reactor, reach_time, hold_reactor, setup.seconds(0.6)),
        _lifted(on_actor, reactor_pats),
        _reach_pole(side),
    )
    nod = bump(t, start_reactor, setup.seconds(0.3), 0.1, setup.seconds(0.4))
    scene.persons[1].head[:, 0] += 0.25 * nod
    return scene


def _lifted(target: Target, lift: torch.Tensor) -> Target:
    """A target moved up by lift (T,)."""

    def moved(stage: Stage) -> torch.Tensor:
        points = target(stage).clone()
        points[:, 1] += lift
        return points

    return moved


def hug(setup: Setup) -> Scene:
    """The actor steps in and hugs; the reactor hugs back; both let go."""
    start_distance = setup.uniform(0.95, 1.25) * setup.scale
    hug_distance = setup.uniform(0.34, 0.38) * setup.scale
    approach = walk(
        setup,
        start=setup.onset,
        distance=start_distance - hug_distance,
        step_length=0.5,
        step_time=0.6,
    )
    arrive = approach.start + approach.duration
    start_reactor = setup.onset + 0.5 * approach.duration + setup.delay
    embrace = max(arrive, start_reactor) + setup.seconds(0.3)
    hold = setup.uniform(1.0, 2.2)
    release = embrace + hold
    scene = face_to_face(
        setup, distance=start_distance, seconds=release + setup.seconds(0.9) + setup.tail
    )
    t = scene.t
    scene.persons[0].walk = approach
    starts = (setup.onset + 0.4 * approach.duration, start_reactor)
    high = setup.integer(0, 1)  # one arm over the partner's shoulder blade, the other lower
    for person, start in enumerate(starts):
        weight = bump(t, start, embrace - start, hold, setup.seconds(0.9))
        partner = 1 - person
        for side in (0, 1):
            # My left hand goes round the partner's right side (their -x) to their back.
            offset = (
                -SIDE_SIGN[side] * 0.10 * setup.scale,
                (0.05 if side == high else -0.09) * setup.scale,
                -0.10 * setup.scale,
            )
            pole = (SIDE_SIGN[side] * 1.0, -0.4, -0.3)
            scene.persons[person].arms[side].reach_to(
                weight, partner_point(partner, 9, offset), pole
            )
        _lean(scene, person, weight, 0.1)
        scene.persons[person].head[:, 1] += 0.45 * weight  # turn the head aside, cheek by cheek
    return scene


def push(setup: Setup) -> Scene:
    """The actor shoves the reactor's chest with both hands; the reactor stumbles backwards."""
    actor_body, reactor_body = setup.bodies
    chest_height = reactor_body.standing_root_height + float(
        reactor_body.offsets[[3, 6, 9], 1].sum()
    )
    lateral = float(actor_body.shoulder[0]) - 0.11 * setup.scale
    forward = forward_reach(
        actor_body, height=chest_height, lateral=lateral, fraction=setup.uniform(0.8, 0.9)
    )
    distance = forward + float(actor_body.shoulder[2]) + 0.12 * setup.scale
    strike = setup.seconds(0.45)
    contact = setup.onset + strike
    start_reactor = contact + setup.uniform(0.05, 0.15)
    stumble = walk(
        setup,
        start=start_reactor,
        distance=-setup.uniform(0.5, 1.0) * setup.scale,
        step_length=0.35,
        step_time=0.28,
        lift=0.06,
    )
    scene = face_to_face(
        setup, distance=distance, seconds=walk_end(stumble) + setup.seconds(0.4) + setup.tail
    )
    t = scene.t
    weight = bump(t, setup.onset, strike, 0.12, setup.seconds(0.6))
    for side in (0, 1):
        offset = (-SIDE_SIGN[side] * 0.11 * setup.scale, 0.0, 0.12 * setup.scale)
        scene.persons[0].arms[side].reach_to(
            weight, partner_point(1, 9, offset), (SIDE_SIGN[side], -1.0, -0.3)
        )
    _lean(scene, 0, bump(t, setup.onset, strike, 0.2, setup.seconds(0.8)), 0.2)
    reactor = scene.persons[1]
    reactor.walk = stumble
    jolt = bump(t, start_reactor, setup.seconds(0.15), setup.seconds(0.3), setup.seconds(0.9))
    _lean(scene, 1, jolt, -0.25)
    reactor.head[:, 0] += 0.3 * jolt  # the head lags behind the pushed chest
    reach = reactor_body.reach
    for side, arm in enumerate(reactor.arms):
        flail = torch.tensor(
            [SIDE_SIGN[side] * 0.45 * reach, -0.35 * reach, 0.35 * reach], dtype=torch.float64
        )
        arm.blend(jolt, flail, (SIDE_SIGN[side], -1.0, 0.0))
    return scene
