"""Time curves and the walking gait, vectorised over a clip's time axis.

Every curve takes ``t`` (T,) in seconds (float64) and returns (T,) values; choreographies build
motion as sums of these envelopes, never with a per-frame loop.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import torch


def smoothstep(x: torch.Tensor) -> torch.Tensor:
    """Cubic 0 -> 1 ease with zero slope at both ends; clamps outside [0, 1]."""
    x = x.clamp(0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def ramp(t: torch.Tensor, start: float, duration: float) -> torch.Tensor:
    """0 before `start`, 1 after `start + duration`, smooth in between."""
    return smoothstep((t - start) / max(duration, 1e-6))


def bump(t: torch.Tensor, start: float, rise: float, hold: float, fall: float) -> torch.Tensor:
    """0 -> 1 over `rise`, stays 1 for `hold`, back to 0 over `fall` (seconds)."""
    return ramp(t, start, rise) - ramp(t, start + rise + hold, fall)


def wave(t: torch.Tensor, start: float, frequency: float, phase: float = 0.0) -> torch.Tensor:
    """sin(2 pi f (t - start) + phase): an oscillation whose phase is anchored at `start`."""
    return torch.sin(2.0 * math.pi * frequency * (t - start) + phase)


@dataclass(frozen=True)
class Walk:
    """A straight walk along the person's facing (negative distance: backwards).

    start, duration: seconds; distance: metres, signed; steps: foot placements (>= 2, the last
    one brings the trailing foot beside the leading one); lead: 0 left / 1 right foot first;
    lift: swing-foot clearance (m).
    """

    start: float
    duration: float
    distance: float
    steps: int
    lead: int
    lift: float


class Gait(NamedTuple):
    feet: torch.Tensor  # (2, T) left/right foot displacement along the walking axis (m)
    lift: torch.Tensor  # (2, T) left/right foot height above its resting height (m)
    pelvis: torch.Tensor  # (T,) pelvis displacement along the walking axis (m)
    phase: torch.Tensor  # (T,) step phase in [0, steps]; integer values are double support


def _phase(t: torch.Tensor, walk: Walk) -> torch.Tensor:
    """Step phase with a smooth speed-up over about the first step and slow-down over the last."""
    u = ((t - walk.start) / walk.duration).clamp(0.0, 1.0)
    edge = min(0.5, 1.2 / walk.steps)
    speed = smoothstep(u / edge) * smoothstep((1.0 - u) / edge) + 1e-9
    speed = torch.where((u > 0) & (u < 1), speed, torch.zeros_like(speed))
    cumulative = torch.cumsum(speed, 0)
    return walk.steps * cumulative / cumulative[-1].clamp_min(1e-12)


def _pelvis_progress(phase: torch.Tensor, steps: int) -> torch.Tensor:
    """Pelvis position in step lengths: midway between the feet at every double support, with
    C1 quadratic blends on the first and last step (it starts and stops with zero speed)."""
    last = float(steps - 1)
    middle = phase - 0.5
    start = phase.square() / 2
    end = last - (steps - phase).square() / 2
    return torch.where(phase < 1, start, torch.where(phase > steps - 1, end, middle))


def gait(t: torch.Tensor, walk: Walk) -> Gait:
    """Foot and pelvis trajectories of a walk; planted feet are exactly still.

    Step i moves one foot from max(i-1, 0) to min(i+1, steps-1) step lengths while the other
    stands at i step lengths; the moving foot follows a cycloid (zero speed at lift-off and
    touch-down) so a landed foot never slides.
    """
    if walk.steps < 2:
        raise ValueError(f"a walk needs at least 2 steps, got {walk.steps}")
    step_length = walk.distance / (walk.steps - 1)
    phase = _phase(t, walk)
    index = phase.floor().clamp(0, walk.steps - 1)
    u = phase - index
    swing_from = (index - 1).clamp_min(0)
    swing_to = (index + 1).clamp_max(walk.steps - 1)
    progress = u - torch.sin(2 * math.pi * u) / (2 * math.pi)
    swing = (swing_from + (swing_to - swing_from) * progress) * step_length
    stand = index * step_length
    swing_lift = walk.lift * torch.sin(math.pi * u).square()
    lead_swings = (index.long() % 2) == 0  # steps 0, 2, 4, ... move the lead foot
    lead = torch.where(lead_swings, swing, stand)
    trail = torch.where(lead_swings, stand, swing)
    lead_lift = torch.where(lead_swings, swing_lift, torch.zeros_like(swing_lift))
    trail_lift = torch.where(lead_swings, torch.zeros_like(swing_lift), swing_lift)
    feet = torch.stack((lead, trail) if walk.lead == 0 else (trail, lead))
    lift = torch.stack((lead_lift, trail_lift) if walk.lead == 0 else (trail_lift, lead_lift))
    pelvis = _pelvis_progress(phase, walk.steps) * step_length
    return Gait(feet=feet, lift=lift, pelvis=pelvis, phase=phase)


def still_gait(t: torch.Tensor) -> Gait:
    """No walking: feet and pelvis at their resting places."""
    zeros = torch.zeros_like(t)
    return Gait(
        feet=torch.stack((zeros, zeros)),
        lift=torch.stack((zeros, zeros)),
        pelvis=zeros,
        phase=zeros,
    )


def steps_for(distance: float, step_length: float) -> int:
    """Number of foot placements for a walk of `distance` with a nominal step length."""
    return max(2, round(abs(distance) / step_length) + 1)
