"""The SMPL 22-joint body skeleton used by InterHuman (and by the body rows of Inter-X).

Frame convention: Y up, metres; in the rest pose the person faces +Z and their LEFT is +X
(SMPL's convention, so ``across = r_hip - l_hip`` points to -X and ``cross(up, across)`` is +Z).
"""

from __future__ import annotations

import torch

NUM_JOINTS = 22
JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "l_hip",
    "r_hip",
    "spine1",
    "l_knee",
    "r_knee",
    "spine2",
    "l_ankle",
    "r_ankle",
    "spine3",
    "l_foot",
    "r_foot",
    "neck",
    "l_collar",
    "r_collar",
    "head",
    "l_shoulder",
    "r_shoulder",
    "l_elbow",
    "r_elbow",
    "l_wrist",
    "r_wrist",
)
PARENTS: tuple[int, ...] = (
    -1,
    0,
    0,
    0,
    1,
    2,
    3,
    4,
    5,
    6,
    7,
    8,
    9,
    9,
    9,
    12,
    13,
    14,
    16,
    17,
    18,
    19,
)
KINEMATIC_CHAINS: tuple[tuple[int, ...], ...] = (
    (0, 2, 5, 8, 11),
    (0, 1, 4, 7, 10),
    (0, 3, 6, 9, 12, 15),
    (9, 14, 17, 19, 21),
    (9, 13, 16, 18, 20),
)
LEFT_JOINTS: tuple[int, ...] = (1, 4, 7, 10, 13, 16, 18, 20)
RIGHT_JOINTS: tuple[int, ...] = (2, 5, 8, 11, 14, 17, 19, 21)


def _mirror_permutation() -> tuple[int, ...]:
    permutation = list(range(NUM_JOINTS))
    for left, right in zip(LEFT_JOINTS, RIGHT_JOINTS, strict=True):
        permutation[left], permutation[right] = right, left
    return tuple(permutation)


# positions_mirrored = positions[..., MIRROR_PERMUTATION, :] (then negate the lateral axis)
MIRROR_PERMUTATION: tuple[int, ...] = _mirror_permutation()
FACE_JOINTS: tuple[int, int, int, int] = (2, 1, 17, 16)  # r_hip, l_hip, r_shoulder, l_shoulder
FOOT_JOINTS_LEFT: tuple[int, int] = (7, 10)  # ankle, foot
FOOT_JOINTS_RIGHT: tuple[int, int] = (8, 11)
FOOT_JOINTS: tuple[int, int, int, int] = (*FOOT_JOINTS_LEFT, *FOOT_JOINTS_RIGHT)
BONES: tuple[tuple[int, int], ...] = tuple((PARENTS[j], j) for j in range(1, NUM_JOINTS))

# Offsets of each joint from its parent in the rest pose, rounded from the SMPL neutral template
# and made left/right symmetric. Rows are joints; the right side is the left side with x negated.
_LEFT_AND_CENTRE_OFFSETS = {
    0: (0.0, 0.0, 0.0),
    1: (0.058, -0.088, -0.005),  # l_hip from pelvis
    3: (0.0, 0.110, -0.025),  # spine1
    4: (0.045, -0.377, -0.008),  # l_knee
    6: (0.0, 0.134, 0.006),  # spine2
    7: (-0.013, -0.407, -0.035),  # l_ankle
    9: (0.0, 0.053, 0.023),  # spine3
    10: (0.032, -0.053, 0.122),  # l_foot
    12: (0.0, 0.220, -0.045),  # neck
    13: (0.078, 0.127, -0.012),  # l_collar
    15: (0.0, 0.090, 0.050),  # head
    16: (0.112, 0.037, -0.031),  # l_shoulder
    18: (0.256, -0.013, -0.022),  # l_elbow
    20: (0.266, 0.013, -0.006),  # l_wrist
}


def _rest_offsets() -> torch.Tensor:
    offsets = torch.zeros(NUM_JOINTS, 3)
    for joint, offset in _LEFT_AND_CENTRE_OFFSETS.items():
        offsets[joint] = torch.tensor(offset)
    for left, right in zip(LEFT_JOINTS, RIGHT_JOINTS, strict=True):
        offsets[right] = offsets[left] * torch.tensor([-1.0, 1.0, 1.0])
    return offsets


REST_OFFSETS: torch.Tensor = _rest_offsets()


def rest_pose_positions(offsets: torch.Tensor = REST_OFFSETS) -> torch.Tensor:
    """Joint positions (22, 3) of the rest pose with the pelvis at the origin."""
    positions = torch.zeros_like(offsets)
    for joint in range(1, NUM_JOINTS):
        positions[joint] = positions[PARENTS[joint]] + offsets[joint]
    return positions
