"""Per-person body proportions and the rigid hand template of the synthetic dataset.

A body is the SMPL 22-joint skeleton (``REST_OFFSETS``, Y-up, facing +Z, left at +X) scaled to a
sampled stature, with a few percent of independent jitter per segment group (legs, spine, arms).
Left and right stay symmetric. The 40 hand joints of the InterHuman raw frame (15 finger joints
per hand, then 5 finger tips per hand) hang rigidly off each wrist: the raw data carries identity
hand rotations, so a fixed template in the wrist frame is exactly what those rotations say.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from intermask.motion.skeleton import REST_OFFSETS, rest_pose_positions

# Top of the skull above the head joint, as a share of the template size (SMPL head joint sits
# at the skull base, ~12 cm below the crown for a 1.65 m template).
_HEAD_TOP = 0.12
HEIGHT_RANGE = (1.5, 1.95)  # metres, the realistic range
_HEIGHT_MEAN, _HEIGHT_STD = 1.72, 0.09
_SEGMENT_JITTER = 0.04  # +-4 % per segment group
_SEGMENTS = {
    "legs": (1, 2, 4, 5, 7, 8, 10, 11),
    "spine": (3, 6, 9, 12, 15),
    "arms": (13, 14, 16, 17, 18, 19, 20, 21),
}

# Left hand in the left wrist frame (metres, template size): the hand continues the forearm along
# +X, palm down (-Y), thumb forward (+Z). Rows: SMPL-H order index, middle, pinky, ring, thumb
# (3 joints each), then the tips thumb, index, middle, ring, pinky.
_FINGER_BASES = {  # finger -> (base joint, direction of the next phalanges)
    "index": ((0.088, -0.006, 0.025), (0.032, -0.006, 0.002)),
    "middle": ((0.095, -0.004, 0.003), (0.035, -0.006, 0.0)),
    "pinky": ((0.076, -0.009, -0.037), (0.024, -0.005, -0.004)),
    "ring": ((0.088, -0.006, -0.019), (0.031, -0.006, -0.002)),
    "thumb": ((0.025, -0.016, 0.030), (0.026, -0.006, 0.018)),
}
_TIP_ORDER = ("thumb", "index", "middle", "ring", "pinky")
HAND_JOINTS_PER_SIDE = 15
LEFT = 0
SIDE_SIGN = (1.0, -1.0)  # body-frame x sign of the left / right side


def _left_hand_template() -> torch.Tensor:
    """(20, 3): 15 finger joints then 5 tips of the left hand, left-wrist frame, template size."""
    joints, tips = [], {}
    for finger, (base, step) in _FINGER_BASES.items():
        base_t, step_t = (
            torch.tensor(base, dtype=torch.float64),
            torch.tensor(step, dtype=torch.float64),
        )
        joints += [base_t + k * step_t for k in range(3)]
        tips[finger] = base_t + 3.2 * step_t
    return torch.stack(joints + [tips[name] for name in _TIP_ORDER])


_LEFT_HAND = _left_hand_template()


@dataclass(frozen=True)
class BodyShape:
    """One person's proportions.

    offsets: (22, 3) rest offsets (Y-up metres); stature: standing height in metres;
    hand: (2, 20, 3) left/right hand template in the wrist frames (15 joints, then 5 tips).
    """

    offsets: torch.Tensor
    stature: float
    hand: torch.Tensor

    @property
    def standing_root_height(self) -> float:
        """Pelvis height when standing with flat feet (the foot joints touch the ground)."""
        return float(-rest_pose_positions(self.offsets)[:, 1].min())

    @property
    def arm_lengths(self) -> tuple[float, float]:
        """(shoulder->elbow, elbow->palm centre) of the left arm; the right one is its mirror."""
        upper = float(self.offsets[18].norm())
        lower = float((self.offsets[20] + self.hand[LEFT, :HAND_JOINTS_PER_SIDE].mean(0)).norm())
        return upper, lower

    @property
    def reach(self) -> float:
        """Shoulder to palm centre with the arm straight."""
        upper, lower = self.arm_lengths
        return upper + lower

    @property
    def shoulder(self) -> torch.Tensor:
        """(3,) left shoulder position relative to the ground point below the pelvis, standing."""
        position = rest_pose_positions(self.offsets)[16].clone()
        position[1] += self.standing_root_height
        return position


def _stature(offsets: torch.Tensor, scale: float) -> float:
    rest = rest_pose_positions(offsets)
    return float(rest[15, 1] - rest[:, 1].min()) + _HEAD_TOP * scale


def template_body() -> BodyShape:
    """The unscaled SMPL template (used where the layout cannot store proportions: Inter-X)."""
    offsets = REST_OFFSETS.to(torch.float64)
    return BodyShape(offsets=offsets, stature=_stature(offsets, 1.0), hand=_hands(1.0))


def _hands(scale: float) -> torch.Tensor:
    right = _LEFT_HAND * torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64)
    return torch.stack((_LEFT_HAND, right)) * scale


def sample_body(rng: np.random.Generator) -> BodyShape:
    """A body with stature ~ N(1.72, 0.09) clipped to HEIGHT_RANGE and +-4 % segment jitter."""
    height = float(np.clip(rng.normal(_HEIGHT_MEAN, _HEIGHT_STD), *HEIGHT_RANGE))
    factors = torch.ones(REST_OFFSETS.shape[0], 1, dtype=torch.float64)
    for joints in _SEGMENTS.values():
        factors[list(joints)] = 1.0 + rng.uniform(-_SEGMENT_JITTER, _SEGMENT_JITTER)
    arm_factor = float(factors[18, 0])  # the hands follow the arms
    jittered = REST_OFFSETS.to(torch.float64) * factors
    # Stature is linear in a global scale once the proportions are fixed: solve for it.
    scale = height / _stature(jittered, 1.0)
    return BodyShape(offsets=jittered * scale, stature=height, hand=_hands(scale * arm_factor))


def hand_positions(
    wrist_positions: torch.Tensor, wrist_rotations: torch.Tensor, body: BodyShape
) -> torch.Tensor:
    """Place the 40 hand joints.

    wrist_positions: (T, 2, 3) left/right wrist; wrist_rotations: (T, 2, 3, 3) their world frames.
    Returns (T, 40, 3): 15 left, 15 right finger joints, then 5 left and 5 right tips (SMPL-H order).
    """
    placed = wrist_positions[:, :, None] + torch.einsum(
        "tsij,skj->tski", wrist_rotations, body.hand
    )
    joints = placed[:, :, :HAND_JOINTS_PER_SIDE].flatten(1, 2)
    tips = placed[:, :, HAND_JOINTS_PER_SIDE:].flatten(1, 2)
    return torch.cat((joints, tips), dim=1)


def forward_reach(body: BodyShape, *, height: float, lateral: float, fraction: float) -> float:
    """How far in front of the shoulder a palm target at `height` (m above ground) and `lateral`
    (m sideways from the shoulder) lies when it uses `fraction` of the straight-arm reach.
    Used to space two people so that a contact target is comfortably reachable for both."""
    drop = float(body.shoulder[1]) - height
    squared = (fraction * body.reach) ** 2 - drop**2 - lateral**2
    return float(np.sqrt(max(squared, 0.01)))
