"""One synthetic two-person clip: sample, choreograph, pose, place in the world, caption.

:func:`generate_clip` is what the dataset writers call and what the tests inspect: it returns the
world joint positions and local rotations from which both official layouts are written.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import torch

from intermask.data.synthetic import contact, gestures, locomotion
from intermask.data.synthetic.body import BodyShape, sample_body, template_body
from intermask.data.synthetic.captions import make_captions
from intermask.data.synthetic.choreography import Setup, sample_setup
from intermask.data.synthetic.rig import PersonMotion, realize
from intermask.data.synthetic.scene import FPS, Scene
from intermask.motion.actions import ACTIONS
from intermask.motion.rotations import rotation_about_axis

# The choreography of each action of the vocabulary (intermask.motion.actions), in its order.
INTERACTIONS: dict[str, Callable[[Setup], Scene]] = {
    "handshake": contact.handshake,
    "hug": contact.hug,
    "push": contact.push,
    "punch_dodge": gestures.punch_dodge,
    "wave": gestures.wave_back,
    "bow": gestures.bow,
    "walk_meet": locomotion.walk_meet,
    "dance": gestures.dance,
    "pass_object": contact.pass_object,
    "high_five": contact.high_five,
    "kick_block": gestures.kick_block,
    "chase": locomotion.chase,
    "pat_shoulder": contact.pat_shoulder,
    "beckon": locomotion.beckon,
}
if tuple(INTERACTIONS) != ACTIONS:
    raise ImportError("the synthetic choreographies must follow intermask.motion.actions.ACTIONS")
SIDES = ("left", "right")
_WORLD_OFFSET = 1.0  # metres: the pair's centre lands within +-1 m of the origin


class SynthClip(NamedTuple):
    """A generated clip; persons are in file order (person 1, person 2).

    positions: (2, T, 22, 3) Y-up world joints (metres); hands: (2, T, 40, 3) finger joints and
    tips; local_rotations: (2, T, 22, 3, 3), row 0 the root's world orientation; offsets:
    (2, 22, 3) each body's rest offsets. actor is 1 or 2; side is the actor's acting hand/leg.
    """

    action: str
    action_id: int
    actor: int
    captions: tuple[str, ...]
    side: str
    speed: float
    positions: torch.Tensor
    hands: torch.Tensor
    local_rotations: torch.Tensor
    offsets: torch.Tensor

    @property
    def frames(self) -> int:
        return self.positions.shape[1]

    @property
    def fps(self) -> int:
        return FPS


def clip_rng(seed: int, index: int) -> np.random.Generator:
    """Independent random stream of clip `index` of a dataset with `seed`."""
    return np.random.default_rng(np.random.SeedSequence([seed, index]))


def _place(motion: PersonMotion, rotation: torch.Tensor, shift: torch.Tensor) -> PersonMotion:
    """Turn a posed person about +Y by `rotation` (3, 3) and move by `shift` (3,)."""
    local = motion.local_rotations.clone()
    local[:, 0] = rotation @ local[:, 0]
    return PersonMotion(
        positions=motion.positions @ rotation.T + shift,
        local_rotations=local,
        hands=motion.hands @ rotation.T + shift,
    )


def generate_clip(*, seed: int, index: int, action: str, vary_bodies: bool = True) -> SynthClip:
    """Generate clip `index` of the dataset `seed` showing `action`.

    vary_bodies=False uses the template skeleton for both people (the Inter-X layout stores no
    body shape, so a reader can only rebuild joints with the template offsets).
    """
    if action not in INTERACTIONS:
        raise ValueError(f"unknown interaction {action!r}; expected one of {', '.join(ACTIONS)}")
    rng = clip_rng(seed, index)
    bodies: tuple[BodyShape, BodyShape]
    bodies = (
        (sample_body(rng), sample_body(rng)) if vary_bodies else (template_body(), template_body())
    )
    setup = sample_setup(rng, bodies)
    scene = INTERACTIONS[action](setup)
    # A child stream for the secondary motion leaves the choreography's draws (and so every
    # scripted timing) exactly as they were without it.
    actor_motion, reactor_motion = realize(scene, rng.spawn(1)[0])
    actor = 1 + int(rng.integers(2))
    heading = float(rng.uniform(-math.pi, math.pi))
    rotation = rotation_about_axis(torch.tensor(heading, dtype=torch.float64), "y")
    centre = torch.tensor([0.0, 0.0, scene.persons[1].position[1] / 2], dtype=torch.float64)
    offset = rng.uniform(-_WORLD_OFFSET, _WORLD_OFFSET, size=2)
    shift = torch.tensor([offset[0], 0.0, offset[1]], dtype=torch.float64) - rotation @ centre
    placed = [_place(m, rotation, shift) for m in (actor_motion, reactor_motion)]
    order = (0, 1) if actor == 1 else (1, 0)
    persons = [placed[k] for k in order]
    captions = make_captions(
        rng, action=action, actor=actor, side=SIDES[setup.side], speed=setup.speed
    )
    return SynthClip(
        action=action,
        action_id=ACTIONS.index(action),
        actor=actor,
        captions=captions,
        side=SIDES[setup.side],
        speed=setup.speed,
        positions=torch.stack([p.positions for p in persons]),
        hands=torch.stack([p.hands for p in persons]),
        local_rotations=torch.stack([p.local_rotations for p in persons]),
        offsets=torch.stack([bodies[k].offsets for k in order]),
    )
