"""Shared vocabulary of the interaction choreographies: the sampled setup and placement helpers.

Every interaction is a function ``Setup -> Scene`` written in a *scene frame*: the actor stands at
the origin facing +Z, the reactor at (0, distance) facing the actor. The clip generator then turns
the whole pair to a random world heading and position. Durations are authored at speed 1 and
divided by the sampled speed (``setup.seconds``), so "quickly" / "slowly" in the captions match.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from intermask.data.synthetic.body import BodyShape, forward_reach
from intermask.data.synthetic.primitives import Walk, steps_for
from intermask.data.synthetic.scene import FPS, PersonPlan, Scene, Stage, Target, time_axis

_TEMPLATE_STATURE = 1.652  # stature of the unscaled SMPL template (body.template_body)
SPEED_RANGE = (0.7, 1.4)
ONSET_RANGE = (0.3, 1.0)  # seconds of stillness before the actor moves
DELAY_RANGE = (0.2, 0.6)  # reaction delay of the reactor (the plausible range)
_FACING_JITTER = 0.08  # radians (~5 degrees): people rarely face each other exactly


@dataclass(frozen=True)
class Setup:
    """Sampled parameters shared by all interactions; bodies are [actor, reactor]."""

    rng: np.random.Generator
    bodies: tuple[BodyShape, BodyShape]
    side: int  # the actor's acting hand / leg: 0 left, 1 right
    speed: float
    onset: float
    delay: float
    tail: float

    def seconds(self, at_unit_speed: float) -> float:
        """A duration authored at speed 1, played at the sampled speed."""
        return at_unit_speed / self.speed

    def uniform(self, low: float, high: float) -> float:
        return float(self.rng.uniform(low, high))

    def integer(self, low: int, high: int) -> int:
        """Uniform integer in [low, high]."""
        return int(self.rng.integers(low, high + 1))

    @property
    def scale(self) -> float:
        """Mean stature of the pair relative to the template: scales distances."""
        return (self.bodies[0].stature + self.bodies[1].stature) / (2 * _TEMPLATE_STATURE)

    @property
    def shoulder_height(self) -> float:
        return float(self.bodies[0].shoulder[1] + self.bodies[1].shoulder[1]) / 2


def sample_setup(rng: np.random.Generator, bodies: tuple[BodyShape, BodyShape]) -> Setup:
    """Speed log-uniform in SPEED_RANGE; right hand twice as likely as left."""
    speed = math.exp(rng.uniform(math.log(SPEED_RANGE[0]), math.log(SPEED_RANGE[1])))
    return Setup(
        rng=rng,
        bodies=bodies,
        side=int(rng.random() < 0.67),
        speed=speed,
        onset=float(rng.uniform(*ONSET_RANGE)),
        delay=float(rng.uniform(*DELAY_RANGE)),
        tail=float(rng.uniform(0.3, 0.8)),
    )


def face_to_face(setup: Setup, *, distance: float, seconds: float) -> Scene:
    """Actor at the origin facing +Z, reactor `distance` metres ahead facing back, both still."""
    t = time_axis(seconds)
    jitter = setup.rng.uniform(-_FACING_JITTER, _FACING_JITTER, size=2)
    phases = setup.rng.uniform(0, 2 * math.pi, size=2)
    actor = PersonPlan.standing(
        body=setup.bodies[0],
        t=t,
        position=(0.0, 0.0),
        yaw=float(jitter[0]),
        sway_phase=float(phases[0]),
    )
    reactor = PersonPlan.standing(
        body=setup.bodies[1],
        t=t,
        position=(0.0, distance),
        yaw=math.pi + float(jitter[1]),
        sway_phase=float(phases[1]),
    )
    return Scene(t=t, persons=(actor, reactor))


def contact_distance(
    setup: Setup, *, height: float, lateral: float, fraction: tuple[float, float]
) -> float:
    """Pelvis distance at which both palms meet half-way at `height` with `fraction` of their reach.

    Shoulders sit slightly behind the pelvis (negative z in the rest pose), hence the z terms.
    """
    forward = [
        forward_reach(body, height=height, lateral=lateral, fraction=setup.uniform(*fraction))
        + float(body.shoulder[2])
        for body in setup.bodies
    ]
    return forward[0] + forward[1]


def walk(
    setup: Setup,
    *,
    start: float,
    distance: float,
    step_length: float,
    step_time: float,
    lift: float = 0.08,
) -> Walk:
    """A walk with a step count fitting the distance; step_time is at unit speed."""
    steps = steps_for(distance, step_length * setup.scale)
    return Walk(
        start=start,
        duration=steps * setup.seconds(step_time),
        distance=distance,
        steps=steps,
        lead=setup.integer(0, 1),
        lift=lift * setup.scale,
    )


def walk_end(plan_walk: Walk | None) -> float:
    return 0.0 if plan_walk is None else plan_walk.start + plan_walk.duration


def meeting_point(
    *,
    joints: tuple[int, int],
    time: float,
    height: float,
    along: float = 0.0,
    across: float = 0.0,
    lift: torch.Tensor | None = None,
) -> Target:
    """Half-way between an actor joint and a reactor joint (e.g. shoulders) at `time`, at `height`.

    along / across: metres along the actor->reactor axis and to the actor's left of it (palm gaps);
    lift: (T,) vertical motion of the meeting point (handshake pumps, pats).
    """

    def target(stage: Stage) -> torch.Tensor:
        frame = min(int(round(time * FPS)), stage.positions.shape[1] - 1)
        middle = (stage.positions[0, frame, joints[0]] + stage.positions[1, frame, joints[1]]) / 2
        axis = stage.positions[1, frame, 0] - stage.positions[0, frame, 0]
        axis = torch.stack((axis[0], torch.zeros_like(axis[1]), axis[2]))
        axis = axis / axis.norm().clamp_min(1e-9)
        left = torch.stack((axis[2], torch.zeros_like(axis[1]), -axis[0]))  # up x axis
        point = (
            torch.stack((middle[0], middle.new_tensor(height), middle[2]))
            + along * axis
            + across * left
        )
        points = point.expand(stage.positions.shape[1], 3).clone()
        if lift is not None:
            points[:, 1] += lift
        return points

    return target
