"""Interactions built on walking: walk toward and meet, chase, beckon and approach.

Walks are straight lines along the walker's facing with planted feet (primitives.gait); a turn
(the fleeing reactor of a chase) happens on the spot before the walk starts.
Scene frame: actor at the origin facing +Z, reactor ahead facing -Z (see choreography.py).
"""

from __future__ import annotations

import math

import torch

from intermask.data.synthetic.body import SIDE_SIGN
from intermask.data.synthetic.choreography import Setup, face_to_face, walk, walk_end
from intermask.data.synthetic.primitives import bump, ramp, wave
from intermask.data.synthetic.scene import PersonPlan, Scene

_MAX_SECONDS = 9.6  # leave room under the 10 s cap


def _bent_arms(plan: PersonPlan, weight: torch.Tensor) -> None:
    """Elbows bent at about 90 degrees, as when running."""
    reach = plan.body.reach
    for side, arm in enumerate(plan.arms):
        sign = SIDE_SIGN[side]
        bent = torch.tensor([sign * 0.12 * reach, -0.55 * reach, 0.3 * reach], dtype=torch.float64)
        arm.blend(weight, bent, (sign * 0.3, -0.3, -1.0))


def _rotate_xz(yaw: torch.Tensor, xz: torch.Tensor) -> torch.Tensor:
    """(T,) yaw, (2,) body-frame (x, z) -> (T, 2) world (x, z) after turning by yaw about +Y."""
    cos, sin = torch.cos(yaw), torch.sin(yaw)
    return torch.stack((cos * xz[0] + sin * xz[1], -sin * xz[0] + cos * xz[1]), -1)


def turn_in_place(
    plan: PersonPlan,
    t: torch.Tensor,
    *,
    start: float,
    duration: float,
    angle: float,
    first: int,
    lift: float,
) -> None:
    """Turn on the spot by `angle` in two pivots and a closing step, feet never sliding.

    Pivot 1 turns half-way about the `first` foot's hip while that leg counter-twists (hip yaw)
    and the other foot steps round with the body; pivot 2 does the same on the other foot; a last
    step untwists the leg that pivoted last. The pelvis moves so the pivot hip stays put.
    """
    yaw0 = plan.yaw[0].item()
    phase = duration / 2.5  # pivot, pivot, half-length closing step
    ends = (start + phase, start + 2 * phase, start + 2.5 * phase)
    half = (ramp(t, start, phase), ramp(t, ends[0], phase))
    turned = angle / 2 * (half[0] + half[1])
    plan.yaw = plan.yaw + turned
    hips = [plan.body.offsets[1 + side, [0, 2]] for side in (0, 1)]
    second = 1 - first
    yaw_mid = yaw0 + angle / 2
    pivot1 = _rotate_xz(torch.full_like(t, yaw0), hips[first]) - _rotate_xz(
        yaw0 + angle / 2 * half[0], hips[first]
    )
    pivot2 = _rotate_xz(torch.full_like(t, yaw_mid), hips[second]) - _rotate_xz(
        yaw_mid + angle / 2 * half[1], hips[second]
    )
    plan.root_shift = plan.root_shift + pivot1 + pivot2
    # Pivot legs counter-twist while weighted; each untwists in the air during its next step.
    plan.hip_yaw[first] = -(angle / 2 * half[0]) * (1 - half[1])
    plan.hip_yaw[second] = -(angle / 2 * half[1]) * (1 - ramp(t, ends[1], ends[2] - ends[1]))
    steps = (
        bump(t, start, phase / 2, 0.0, phase / 2),
        bump(t, ends[0], phase / 2, 0.0, phase / 2),
        bump(t, ends[1], (ends[2] - ends[1]) / 2, 0.0, (ends[2] - ends[1]) / 2),
    )
    plan.foot_lift[second] += lift * steps[0]
    plan.foot_lift[first] += lift * steps[1]
    plan.foot_lift[second] += lift * steps[2]


def walk_meet(setup: Setup) -> Scene:
    """The actor walks toward the reactor, who sets off a moment later; they stop face to face."""
    gap = setup.uniform(0.9, 1.3) * setup.scale
    distance = setup.uniform(3.0, 6.0) * setup.scale
    share = setup.uniform(0.45, 0.7)
    step_time = setup.uniform(0.48, 0.56)
    actor_walk = walk(
        setup,
        start=setup.onset,
        distance=(distance - gap) * share,
        step_length=0.62,
        step_time=step_time,
    )
    start_reactor = setup.onset + setup.delay + setup.seconds(0.3)
    reactor_walk = walk(
        setup,
        start=start_reactor,
        distance=(distance - gap) * (1 - share),
        step_length=0.62,
        step_time=step_time,
    )
    meet = max(walk_end(actor_walk), walk_end(reactor_walk))
    end = meet + setup.seconds(0.9)
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    actor, reactor = scene.persons
    actor.walk, reactor.walk = actor_walk, reactor_walk
    for plan in scene.persons:  # a nod of greeting once they stand
        plan.head[:, 0] += 0.3 * bump(scene.t, meet, setup.seconds(0.3), 0.1, setup.seconds(0.4))
    return scene


def chase(setup: Setup) -> Scene:
    """The actor runs at the reactor, who turns around on the spot and runs away."""
    distance = setup.uniform(2.8, 3.8) * setup.scale
    step_time = setup.uniform(0.3, 0.36)
    run = setup.uniform(4.0, 6.0) * setup.scale
    start_reactor = setup.onset + setup.delay
    turn = setup.seconds(0.6)
    # The chaser leans forward before sprinting (the cue to flee) and sets off at most 0.3 s before
    # the reactor has turned round, so a slow reaction never lets it catch up.
    get_set = max(setup.seconds(0.5), setup.delay + turn - 0.3)
    actor_run = walk(
        setup,
        start=setup.onset + get_set,
        distance=run,
        step_length=0.7,
        step_time=step_time,
        lift=0.14,
    )
    final_gap = setup.uniform(1.3, 2.0) * setup.scale
    # The fleeing reactor takes longer strides than the chaser, so the gap only shrinks while it
    # turns round; it ends final_gap ahead of the chaser.
    reactor_run = walk(
        setup,
        start=start_reactor + turn,
        distance=max(run - distance + final_gap, 1.0),
        step_length=0.85,
        step_time=step_time,
        lift=0.14,
    )
    end = max(walk_end(actor_run), walk_end(reactor_run)) + setup.seconds(0.4)
    scene = face_to_face(setup, distance=distance, seconds=min(end + setup.tail, _MAX_SECONDS))
    t = scene.t
    actor, reactor = scene.persons
    actor.walk, reactor.walk = actor_run, reactor_run
    direction = float(setup.rng.choice((-1.0, 1.0)))
    turn_in_place(
        reactor,
        t,
        start=start_reactor,
        duration=turn,
        angle=direction * math.pi,
        first=setup.integer(0, 1),
        lift=0.06 * setup.scale,
    )
    actor.spine[:, 0] += 0.15 * bump(t, setup.onset, get_set, 0.0, 0.4)
    for plan, running, start in (
        (actor, actor_run, setup.onset),
        (reactor, reactor_run, start_reactor),
    ):
        weight = bump(t, start, running.start - start + 0.2, running.duration - 0.6, 0.4)
        _bent_arms(plan, weight)
        plan.spine[:, 0] += 0.15 * weight
    return scene


def beckon(setup: Setup) -> Scene:
    """The actor beckons with one hand; the reactor walks over."""
    side = setup.side
    gap = setup.uniform(1.0, 1.3) * setup.scale
    distance = setup.uniform(2.5, 4.5) * setup.scale
    frequency = setup.uniform(1.2, 1.7) * setup.speed
    rise = setup.seconds(0.5)
    cycles = setup.integer(2, 4)
    start_reactor = setup.onset + rise + 1 / frequency + setup.delay
    approach = walk(
        setup, start=start_reactor, distance=distance - gap, step_length=0.62, step_time=0.52
    )
    end = max(setup.onset + rise + cycles / frequency, walk_end(approach)) + setup.seconds(0.5)
    scene = face_to_face(setup, distance=distance, seconds=end + setup.tail)
    t = scene.t
    actor, reactor = scene.persons
    reach = setup.bodies[0].reach
    sign = SIDE_SIGN[side]
    hand = torch.tensor([sign * 0.1 * reach, -0.25 * reach, 0.55 * reach], dtype=torch.float64)
    hand = hand.expand(len(t), 3).clone()
    # Curling the forearm in and out: the palm travels towards the chest and back.
    curl = (wave(t, setup.onset + rise, frequency, -math.pi / 2) + 1) / 2
    hand[:, 2] -= 0.3 * reach * curl
    hand[:, 1] += 0.12 * reach * curl
    actor.arms[side].blend(
        bump(t, setup.onset, rise, cycles / frequency, setup.seconds(0.6)), hand, (sign, -1.0, 0.0)
    )
    reactor.walk = approach
    return scene
