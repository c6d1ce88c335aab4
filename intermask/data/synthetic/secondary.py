"""Secondary motion: the small, smooth, per-clip-random movement every real body has.

Choreographies only script the gesture of an interaction, and the IK solves it with as few
degrees of freedom as possible, so without this module most joints would turn about a single
axis and feet, wrists and collars would never turn at all: a learned model would see whole
rotation channels that are constant over the dataset. :func:`sample_secondary` draws, per
person, a posture (constant offsets: real people stand with toes out, a slight lean, bent wrists)
and slow sway curves (sums of a few sinusoids below 0.5 Hz); the rig adds them before it solves
the limbs, so feet stay planted and palms still reach their targets.

Sway amplitudes are kept small enough that an idle body moves far below the 0.1 m/s at which the
motion tests call a joint "moving": onsets stay where the choreography puts them.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F

from intermask.data.synthetic.primitives import smoothstep, wave
from intermask.data.synthetic.scene import FPS

_BAND = (0.05, 0.35)  # Hz: postural drift and sway, well below any gesture frequency
_TERMS = 3  # sinusoids per curve: enough to look irregular, cheap to evaluate
# (posture std, sway RMS) in radians per joint axis. Postures carry most of the variation: they
# cost no speed. Sways of joints high in the chain (pelvis, spine) are the smallest because every
# joint above them moves with them.
_PELVIS = (0.02, 0.006)
_SPINE = (0.06, 0.008)
_NECK_HEAD = (0.07, 0.03)
_COLLAR = (0.05, 0.01)
_WRIST = (0.18, 0.05)
_PRONATION = (0.2, 0.05)
_HIP_TWIST = (0.06, 0.01)
_KNEE_TWIST = (0.08, 0.01)
_TOES = (0.08, 0.01)
_PELVIS_SHIFT = 0.006  # m RMS of the idle weight shift
_POLE = 0.1  # RMS of the elbow pole direction jitter (unit vector): upper-arm twist
_TEMPLATE_STATURE = 1.652  # distances below are for the SMPL template's size
_BREATH = ((0.2, 0.33), 0.008)  # Hz range, chest pitch amplitude (rad)


class Secondary(NamedTuple):
    """One person's secondary motion; angles in radians, (x, y, z) Euler bends like PersonPlan.

    pelvis: (T, 3) pelvis bends; pelvis_shift: (T, 2) idle (lateral, forward) pelvis shift (m);
    spine: (3, T, 3) extra bends of spine1..3; neck_head: (2, T, 3) of neck and head;
    collar, wrist, toes: (2, T, 3) left/right; pronation, hip_twist, knee_twist: (2, T);
    pole: (2, T, 3) elbow pole jitter; the floats are per-person gait and reflex gains.
    """

    pelvis: torch.Tensor
    pelvis_shift: torch.Tensor
    spine: torch.Tensor
    neck_head: torch.Tensor
    collar: torch.Tensor
    wrist: torch.Tensor
    toes: torch.Tensor
    pronation: torch.Tensor
    hip_twist: torch.Tensor
    knee_twist: torch.Tensor
    pole: torch.Tensor
    toe_out: float  # rad, both feet turned outwards (positive) by this much
    foot_tilt: tuple[float, float]  # rad, left/right sole roll about the foot's long axis
    soft_knees: float  # m the pelvis sits below the straight-legged height
    heel_off: float  # rad of foot pitch when the trailing heel leaves the ground
    heel_strike: float  # rad of toe-up pitch just before the swinging foot lands
    gait_sway: float  # m the pelvis shifts over the stance foot
    gait_roll: float  # rad the pelvis drops on the swing side
    gait_yaw: float  # rad per metre of foot lead: the pelvis turns with the forward leg
    counter_rotation: float  # share of the pelvis turn the chest undoes while walking
    screw_home: float  # rad of tibial rotation per rad of knee flexion
    shrug: float  # rad of collar elevation with the arm raised overhead
    protraction: float  # rad of collar protraction with the arm reaching forward
    look_gain: float  # share of the direction to the partner's head the head turns through
    look_lag: float  # s, time constant of the gaze following the partner


def smooth_noise(rng: np.random.Generator, t: torch.Tensor, count: int) -> torch.Tensor:
    """(count, T) smooth random curves of unit RMS: sums of _TERMS sinusoids in _BAND."""
    frequency = torch.from_numpy(rng.uniform(*_BAND, size=(count, _TERMS, 1)))
    phase = torch.from_numpy(rng.uniform(0.0, 2 * math.pi, size=(count, _TERMS, 1)))
    curves = torch.sin(2 * math.pi * frequency * t + phase)  # (count, terms, T)
    return curves.sum(1) * math.sqrt(2.0 / _TERMS)


def _curves(
    rng: np.random.Generator, t: torch.Tensor, shape: tuple[int, ...], amount: tuple[float, float]
) -> torch.Tensor:
    """(*shape, T): a random posture plus a smooth sway, both per curve."""
    count = math.prod(shape)
    posture = torch.from_numpy(rng.normal(0.0, amount[0], size=(count, 1)))
    sway = amount[1] * smooth_noise(rng, t, count)
    return (posture + sway).reshape(*shape, len(t))


def sample_secondary(rng: np.random.Generator, t: torch.Tensor, stature: float) -> Secondary:
    """Draw the secondary motion of a person `stature` metres tall on the time axis t (T,)."""
    scale = stature / _TEMPLATE_STATURE
    spine = _curves(rng, t, (3, 3), _SPINE).transpose(-1, -2).clone()  # (3, T, 3)
    frequency = rng.uniform(*_BREATH[0])
    breath = _BREATH[1] * wave(t, 0.0, frequency, rng.uniform(0, 2 * math.pi))
    spine[2, :, 0] += breath  # the chest lifts and sinks
    collar = _curves(rng, t, (2, 3), _COLLAR).transpose(-1, -2).clone()
    collar[..., 2] += torch.tensor([0.5, -0.5], dtype=torch.float64)[:, None] * breath
    return Secondary(
        pelvis=_curves(rng, t, (3,), _PELVIS).T,
        pelvis_shift=_PELVIS_SHIFT * scale * smooth_noise(rng, t, 2).T,
        spine=spine,
        neck_head=_curves(rng, t, (2, 3), _NECK_HEAD).transpose(-1, -2),
        collar=collar,
        wrist=_curves(rng, t, (2, 3), _WRIST).transpose(-1, -2),
        toes=_curves(rng, t, (2, 3), _TOES).transpose(-1, -2),
        pronation=_curves(rng, t, (2,), _PRONATION),
        hip_twist=_curves(rng, t, (2,), _HIP_TWIST),
        knee_twist=_curves(rng, t, (2,), _KNEE_TWIST),
        pole=_POLE * smooth_noise(rng, t, 6).reshape(2, 3, len(t)).transpose(-1, -2),
        toe_out=float(rng.normal(0.12, 0.06)),
        foot_tilt=(float(rng.normal(0.0, 0.04)), float(rng.normal(0.0, 0.04))),
        soft_knees=float(rng.uniform(0.005, 0.02)) * scale,
        heel_off=float(rng.uniform(0.25, 0.45)),
        heel_strike=float(rng.uniform(0.1, 0.2)),
        gait_sway=float(rng.uniform(0.015, 0.03)) * scale,
        gait_roll=float(rng.uniform(0.03, 0.06)),
        gait_yaw=float(rng.uniform(0.08, 0.15)),
        counter_rotation=float(rng.uniform(0.6, 1.0)),
        screw_home=float(rng.uniform(0.08, 0.15)),
        shrug=float(rng.uniform(0.15, 0.3)),
        protraction=float(rng.uniform(0.08, 0.18)),
        look_gain=float(rng.uniform(0.5, 0.9)),
        look_lag=float(rng.uniform(0.12, 0.3)),
    )


def euler_matrices(angles: torch.Tensor) -> torch.Tensor:
    """(..., 3) bends (x, y, z) -> (..., 3, 3) = Rx Ry Rz, written out: the generic quaternion
    path costs several times more and this runs for every joint of every frame."""
    ca, cb, cc = torch.cos(angles).unbind(-1)
    sa, sb, sc = torch.sin(angles).unbind(-1)
    rows = (
        cb * cc,
        -cb * sc,
        sb,
        ca * sc + sa * sb * cc,
        ca * cc - sa * sb * sc,
        -sa * cb,
        sa * sc - ca * sb * cc,
        sa * cc + ca * sb * sc,
        ca * cb,
    )
    return torch.stack(rows, -1).reshape(*angles.shape[:-1], 3, 3)


def about(angle: torch.Tensor, axis: int) -> torch.Tensor:
    """(...) angles -> (..., 3, 3) rotations about coordinate axis 0 (x), 1 (y) or 2 (z)."""
    angles = torch.zeros(*angle.shape, 3, dtype=angle.dtype)
    angles[..., axis] = angle
    return euler_matrices(angles)


def twist(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """(..., 3) axes (any length), (...) angles -> (..., 3, 3) rotations about those axes."""
    unit = F.normalize(axis, dim=-1)
    x, y, z = unit.unbind(-1)
    zero = torch.zeros_like(x)
    cross = torch.stack((zero, -z, y, z, zero, -x, -y, x, zero), -1).reshape(*x.shape, 3, 3)
    sin, cos = torch.sin(angle)[..., None, None], torch.cos(angle)[..., None, None]
    return torch.eye(3, dtype=axis.dtype) + sin * cross + (1 - cos) * (cross @ cross)


def lag(curves: torch.Tensor, seconds: float) -> torch.Tensor:
    """Causal exponential smoothing of (C, T) curves with time constant `seconds`: a reflex that
    follows its stimulus with a delay (conv1d, the first value held before the clip starts)."""
    taps = max(1, int(4 * seconds * FPS))
    kernel = torch.exp(-torch.arange(taps, dtype=curves.dtype) / (seconds * FPS))
    kernel = (kernel / kernel.sum()).flip(0)[None, None]
    padded = torch.cat((curves[:, :1].expand(-1, taps - 1), curves), dim=1)
    return F.conv1d(padded[:, None], kernel)[:, 0]


def look_at(
    own_head: torch.Tensor,
    partner_head: torch.Tensor,
    chest: torch.Tensor,
    sec: Secondary,
) -> torch.Tensor:
    """(T, 3) neck+head bends turning the gaze towards the partner's head.

    own_head, partner_head: (T, 3) world positions; chest: (T, 3, 3) world frame of spine3, the
    neck's parent. The turn is a share (look_gain) of the full direction, softly limited (people
    turn the eyes the rest of the way), fades out when the partner is behind or very close, and
    lags the partner by look_lag.
    """
    direction = (chest.transpose(-1, -2) @ (partner_head - own_head)[..., None])[..., 0]
    horizontal = torch.hypot(direction[:, 0], direction[:, 2])
    distance = direction.norm(dim=-1).clamp_min(1e-6)
    yaw = torch.atan2(direction[:, 0], direction[:, 2])
    pitch = torch.atan2(-direction[:, 1], horizontal)  # +x bends look down
    # Behind (cos < -0.1) the yaw would flip sign through +-pi: fade out well before.
    ahead = smoothstep((direction[:, 2] / distance + 0.1) / 0.6)
    near = smoothstep((distance - 0.4) / 0.5)  # cheek to cheek, nobody stares at the ear
    weight = sec.look_gain * ahead * near
    angles = torch.stack((0.4 * torch.tanh(pitch / 0.4), 0.8 * torch.tanh(yaw / 0.8))) * weight
    smoothed = lag(angles, sec.look_lag)
    return torch.stack((smoothed[0], smoothed[1], torch.zeros_like(smoothed[0])), -1)


def collar_bends(
    reach: torch.Tensor, heading: torch.Tensor, side: int, sec: Secondary
) -> torch.Tensor:
    """(T, 3) collar bends: the shoulder girdle elevates as the palm rises above the shoulder and
    protracts as it reaches forward (scapulohumeral rhythm), plus the idle collar sway.

    reach: (T, 3) palm target minus shoulder in units of the arm length; heading: (T, 3, 3).
    """
    local = (heading.transpose(-1, -2) @ reach[..., None])[..., 0]
    sign = 1.0 if side == 0 else -1.0  # the left collar points to +x
    elevation = sec.shrug * smoothstep((local[:, 1] + 0.3) / 1.0)
    forward = sec.protraction * smoothstep((local[:, 2] - 0.1) / 0.6)
    bends = sec.collar[side].clone()
    bends[:, 2] += sign * elevation  # +z lifts the +x end
    bends[:, 1] -= sign * forward  # -y swings the +x end forward
    return bends
