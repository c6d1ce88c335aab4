"""Left/right mirroring of joint positions and 6D joint rotations.

Mirroring reflects the world through the plane x = 0 and swaps every left joint with its right
partner. Which axis is reflected:

* World: x. The InterHuman axis change (x, y, z) -> (x, z, -y) leaves x alone, so negating x in the
  raw Z-up frame and negating x in the Y-up frame are the same operation (tested).
* Body: x as well. Local joint rotations live in the SMPL body frame, whose left/right axis is x
  (the person's left is +X in the rest pose). A reflection M_w of the world and the symmetric rest
  offsets (offset[swap(j)] = M offset[j], M = diag(-1, 1, 1)) give mirrored local rotations
  L'[j] = M L[swap(j)] M, whatever the world reflection is; only the root's global orientation
  would see M_w, and InterHuman does not store it.

M R M flips the sign of the entries R01, R02, R10, R20. In InterHuman's "rows" 6D layout
[R00, R01, R10, R11, R20, R21] these are components 1, 2, 4: exactly the reference code's
sign pattern, which is how the layout was inferred.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from intermask.motion.rotations import ROT6D_LAYOUT, Rot6dLayout
from intermask.motion.skeleton import MIRROR_PERMUTATION, NUM_JOINTS

LATERAL_AXIS = 0  # x, in both the raw Z-up and the Y-up frame and in the SMPL body frame
# Components of a 6D rotation whose sign M R M flips, M = diag(-1, 1, 1).
ROT6D_NEGATED: dict[str, tuple[int, ...]] = {
    "rows": (1, 2, 4),  # [R00, R01, R10, R11, R20, R21]
    "columns": (1, 2, 3),  # [R00, R10, R20, R01, R11, R21]
}
# Joints 1..21 carry a rotation: index k is joint k + 1 and becomes MIRROR_PERMUTATION[k + 1] - 1.
ROTATION_MIRROR_PERMUTATION: tuple[int, ...] = tuple(
    MIRROR_PERMUTATION[joint] - 1 for joint in range(1, NUM_JOINTS)
)


def _check_permutation(
    x: torch.Tensor, permutation: Sequence[int], channels: int, name: str
) -> None:
    expected = (len(permutation), channels)
    if x.ndim < 2 or tuple(x.shape[-2:]) != expected:
        raise ValueError(
            f"{name}: expected shape (..., {expected[0]}, {expected[1]}), got {tuple(x.shape)}"
        )


def reflect_lateral(vectors: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 3) with the lateral (x) component negated."""
    if vectors.shape[-1:] != (3,):
        raise ValueError(f"reflect_lateral: expected shape (..., 3), got {tuple(vectors.shape)}")
    signs = vectors.new_tensor([-1.0, 1.0, 1.0])
    return vectors * signs


def mirror_matrix(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) rotations R -> M R M with M = diag(-1, 1, 1) (the definition mirroring follows)."""
    if matrix.shape[-2:] != (3, 3):
        raise ValueError(f"mirror_matrix: expected shape (..., 3, 3), got {tuple(matrix.shape)}")
    signs = matrix.new_tensor([-1.0, 1.0, 1.0])
    return signs[:, None] * matrix * signs[None, :]


def mirror_rot6d(rot6d: torch.Tensor, layout: Rot6dLayout = ROT6D_LAYOUT) -> torch.Tensor:
    """(..., 6) 6D rotations of R -> the 6D rotations of M R M (no joint swap)."""
    if rot6d.shape[-1:] != (6,):
        raise ValueError(f"mirror_rot6d: expected shape (..., 6), got {tuple(rot6d.shape)}")
    if layout not in ROT6D_NEGATED:
        raise ValueError(f"unknown 6D layout {layout!r}; expected one of {sorted(ROT6D_NEGATED)}")
    signs = rot6d.new_ones(6)
    signs[list(ROT6D_NEGATED[layout])] = -1.0
    return rot6d * signs


def mirror_joint_positions(
    positions: torch.Tensor, permutation: Sequence[int] = MIRROR_PERMUTATION
) -> torch.Tensor:
    """(..., J, 3) positions (or velocities) -> mirrored: left/right joints swapped, x negated."""
    _check_permutation(positions, permutation, 3, "mirror_joint_positions")
    return reflect_lateral(positions[..., list(permutation), :])


def mirror_joint_rot6d(
    rot6d: torch.Tensor,
    permutation: Sequence[int] = ROTATION_MIRROR_PERMUTATION,
    layout: Rot6dLayout = ROT6D_LAYOUT,
) -> torch.Tensor:
    """(..., J, 6) local 6D rotations (default: joints 1..21) -> left/right swapped, M R M each."""
    _check_permutation(rot6d, permutation, 6, "mirror_joint_rot6d")
    return mirror_rot6d(rot6d[..., list(permutation), :], layout)
