"""What a choreography writes down: per-person motion plans over a shared time axis.

A choreography never touches joint positions. It fills, for the actor and the reactor, a
:class:`PersonPlan`: where the person stands, the facing curve, an optional straight walk, pelvis
dip, foot offsets (kicks), spine/head bends, and for each arm a palm target. Palm targets are
either *local* (an offset from the shoulder in the person's heading frame, i.e. rotated by the
facing only: gestures) or *world cues*
evaluated after a first kinematic pass of both bodies (contacts: the partner's hand, chest, back).
:mod:`intermask.data.synthetic.rig` turns plans into joint rotations and positions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import torch

from intermask.data.synthetic.body import SIDE_SIGN, BodyShape
from intermask.data.synthetic.primitives import Walk, wave
from intermask.motion import interhuman

FPS = interhuman.FPS  # the embedded dataset is written at the official rate
MIN_SECONDS, MAX_SECONDS = 2.0, 10.0
_IDLE_SWAY = 0.012  # rad: breathing-like spine sway, far below any speed threshold


class Stage(NamedTuple):
    """Both bodies after the first kinematic pass (arms not yet solved), scene order."""

    positions: torch.Tensor  # (2, T, 22, 3) Y-up world joints
    chest: torch.Tensor  # (2, T, 3, 3) world frame of spine3 (joint 9)


Target = Callable[[Stage], torch.Tensor]  # Stage -> (T, 3) world palm target


@dataclass
class WorldCue:
    """Blend the palm towards a world target with weight (T,) in [0, 1]; pole in the heading frame."""

    weight: torch.Tensor
    target: Target
    pole: tuple[float, float, float]


def relaxed_offset(body: BodyShape, side: int) -> torch.Tensor:
    """(3,) palm offset from the shoulder of an arm hanging at the side, elbow slightly bent."""
    reach = body.reach
    return torch.tensor(
        [SIDE_SIGN[side] * 0.08 * reach, -0.93 * reach, 0.06 * reach], dtype=torch.float64
    )


@dataclass
class ArmPlan:
    """One arm: local palm offset (T, 3) and elbow pole (T, 3), both in the heading frame."""

    local: torch.Tensor
    pole: torch.Tensor
    cues: list[WorldCue] = field(default_factory=list)

    def blend(
        self, weight: torch.Tensor, offset: torch.Tensor, pole: tuple[float, float, float]
    ) -> None:
        """Cross-fade the local palm target towards `offset` ((3,) or (T, 3)) with weight (T,)."""
        w = weight[:, None]
        self.local = (1 - w) * self.local + w * torch.as_tensor(offset, dtype=torch.float64)
        self.pole = (1 - w) * self.pole + w * torch.tensor(pole, dtype=torch.float64)

    def reach_to(
        self, weight: torch.Tensor, target: Target, pole: tuple[float, float, float]
    ) -> None:
        """Add a world-space palm target, active with weight (T,)."""
        self.cues.append(WorldCue(weight=weight, target=target, pole=pole))


@dataclass
class PersonPlan:
    """Everything the rig needs for one person; all curves are sampled on the scene's time axis.

    yaw: (T,) facing angle about +Y (0 faces +Z); it may change only while standing, before `walk`
    (see locomotion.turn_in_place, which also fills hip_yaw and root_shift so planted feet stay).
    dip: (T,) pelvis lowering in metres (knee bends). foot_forward / foot_lift: (2, T) extra
    left/right ankle offsets (kicks). hip_yaw: (2, T) leg twist about the vertical. root_shift:
    (T, 2) extra world (x, z) pelvis displacement. spine / head: (T, 3) bends (x forward, y twist,
    z side).
    """

    body: BodyShape
    position: tuple[float, float]
    yaw: torch.Tensor
    arms: tuple[ArmPlan, ArmPlan]
    walk: Walk | None = None
    dip: torch.Tensor | None = None
    foot_forward: torch.Tensor | None = None
    foot_lift: torch.Tensor | None = None
    hip_yaw: torch.Tensor | None = None
    root_shift: torch.Tensor | None = None
    spine: torch.Tensor | None = None
    head: torch.Tensor | None = None

    @classmethod
    def standing(
        cls,
        *,
        body: BodyShape,
        t: torch.Tensor,
        position: tuple[float, float],
        yaw: float,
        sway_phase: float,
    ) -> PersonPlan:
        """A person standing still, arms relaxed, with a faint idle sway."""
        zeros = torch.zeros_like(t)
        arms = tuple(
            ArmPlan(
                local=relaxed_offset(body, side).expand(len(t), 3).clone(),
                pole=torch.tensor([SIDE_SIGN[side] * 0.3, 0.0, -1.0], dtype=torch.float64)
                .expand(len(t), 3)
                .clone(),
            )
            for side in (0, 1)
        )
        spine = torch.zeros(len(t), 3, dtype=torch.float64)
        spine[:, 0] = _IDLE_SWAY * wave(t, 0.0, 0.22, sway_phase)
        return cls(
            body=body,
            position=position,
            yaw=torch.full_like(t, yaw),
            arms=arms,  # type: ignore[arg-type]
            dip=zeros.clone(),
            foot_forward=torch.zeros(2, len(t), dtype=torch.float64),
            foot_lift=torch.zeros(2, len(t), dtype=torch.float64),
            hip_yaw=torch.zeros(2, len(t), dtype=torch.float64),
            root_shift=torch.zeros(len(t), 2, dtype=torch.float64),
            spine=spine,
            head=torch.zeros(len(t), 3, dtype=torch.float64),
        )


@dataclass
class Scene:
    """A clip under construction: time axis and the [actor, reactor] plans."""

    t: torch.Tensor
    persons: tuple[PersonPlan, PersonPlan]

    @property
    def frames(self) -> int:
        return len(self.t)


def time_axis(seconds: float) -> torch.Tensor:
    """(T,) frame times at 30 fps for a clip of `seconds`, clipped to the 2-10 s range."""
    seconds = min(max(seconds, MIN_SECONDS), MAX_SECONDS)
    frames = int(round(seconds * FPS))
    return torch.arange(frames, dtype=torch.float64) / FPS


# ----------------------------------------------------------------------------- world targets


def partner_point(partner: int, joint: int, offset: tuple[float, float, float]) -> Target:
    """Target a point fixed to a person's chest frame: joint position + chest @ offset."""
    local = torch.tensor(offset, dtype=torch.float64)

    def target(stage: Stage) -> torch.Tensor:
        return stage.positions[partner, :, joint] + stage.chest[partner] @ local

    return target
