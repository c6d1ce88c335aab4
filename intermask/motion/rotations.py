"""Rotation conversions between 3x3 matrices, 6D, axis-angle and quaternions.

Pure torch, differentiable, any leading batch shape ``(...)``. Quaternions are ``(w, x, y, z)``.

The 6D representation (Zhou et al. 2019) keeps the first two columns of a rotation matrix.
InterHuman writes them *row by row*: ``[R00, R01, R10, R11, R20, R21]`` (layout ``"rows"``, the
default here and everywhere in the project). The InterMask geodesic loss reads the same numbers
as ``[R00, R10, R20, R01, R11, R21]`` (layout ``"columns"``); that layout exists so the difference
can be tested and named, never silently assumed.
"""

from __future__ import annotations

from typing import Literal

import torch
import torch.nn.functional as F

Rot6dLayout = Literal["rows", "columns"]
ROT6D_LAYOUT: Rot6dLayout = "rows"
_AXES = {"x": 0, "y": 1, "z": 2}


def _check_last_dims(x: torch.Tensor, expected: tuple[int, ...], name: str) -> None:
    if tuple(x.shape[len(x.shape) - len(expected) :]) != expected:
        raise ValueError(
            f"{name}: expected shape (..., {', '.join(map(str, expected))}), got {tuple(x.shape)}"
        )


def _check_layout(layout: str) -> None:
    if layout not in ("rows", "columns"):
        raise ValueError(f"unknown 6D layout {layout!r}; expected 'rows' or 'columns'")


def matrix_to_rot6d(matrix: torch.Tensor, layout: Rot6dLayout = ROT6D_LAYOUT) -> torch.Tensor:
    """(..., 3, 3) rotation matrices -> (..., 6) first two columns in the given layout."""
    _check_last_dims(matrix, (3, 3), "matrix_to_rot6d")
    _check_layout(layout)
    two_columns = matrix[..., :, :2]  # (..., 3, 2)
    if layout == "columns":
        two_columns = two_columns.transpose(-1, -2)  # (..., 2, 3)
    return two_columns.reshape(*matrix.shape[:-2], 6)


def rot6d_to_matrix(rot6d: torch.Tensor, layout: Rot6dLayout = ROT6D_LAYOUT) -> torch.Tensor:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt; any input gives a proper rotation."""
    _check_last_dims(rot6d, (6,), "rot6d_to_matrix")
    _check_layout(layout)
    if layout == "rows":
        first, second = rot6d[..., 0::2], rot6d[..., 1::2]
    else:
        first, second = rot6d[..., :3], rot6d[..., 3:]
    b1 = F.normalize(first, dim=-1)
    b2 = F.normalize(second - (b1 * second).sum(-1, keepdim=True) * b1, dim=-1)
    b3 = torch.linalg.cross(b1, b2, dim=-1)
    return torch.stack((b1, b2, b3), dim=-1)


def quaternion_to_matrix(quaternion: torch.Tensor) -> torch.Tensor:
    """(..., 4) (w, x, y, z), not necessarily unit -> (..., 3, 3)."""
    _check_last_dims(quaternion, (4,), "quaternion_to_matrix")
    w, x, y, z = F.normalize(quaternion, dim=-1).unbind(-1)
    matrix = torch.stack(
        (
            1 - 2 * (y * y + z * z),
            2 * (x * y - z * w),
            2 * (x * z + y * w),
            2 * (x * y + z * w),
            1 - 2 * (x * x + z * z),
            2 * (y * z - x * w),
            2 * (x * z - y * w),
            2 * (y * z + x * w),
            1 - 2 * (x * x + y * y),
        ),
        dim=-1,
    )
    return matrix.reshape(*quaternion.shape[:-1], 3, 3)


def matrix_to_quaternion(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) -> (..., 4) unit quaternion with w >= 0.

    Each of the four classic formulas divides by a different diagonal combination; we evaluate all
    four and keep, per rotation, the one with the largest (best conditioned) denominator.
    """
    _check_last_dims(matrix, (3, 3), "matrix_to_quaternion")
    m = matrix.reshape(*matrix.shape[:-2], 9)
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m.unbind(-1)
    four_squares = torch.stack(
        (1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22), dim=-1
    )
    root = torch.sqrt(four_squares.clamp_min(1e-12))  # 2 |q_k| for k = w, x, y, z
    candidates = torch.stack(
        (
            torch.stack((root[..., 0] ** 2, m21 - m12, m02 - m20, m10 - m01), dim=-1),
            torch.stack((m21 - m12, root[..., 1] ** 2, m10 + m01, m02 + m20), dim=-1),
            torch.stack((m02 - m20, m10 + m01, root[..., 2] ** 2, m12 + m21), dim=-1),
            torch.stack((m10 - m01, m20 + m02, m21 + m12, root[..., 3] ** 2), dim=-1),
        ),
        dim=-2,
    ) / (2 * root[..., None])  # (..., 4 candidates, 4)
    best = four_squares.argmax(dim=-1)
    quaternion = torch.gather(
        candidates, -2, best[..., None, None].expand(*best.shape, 1, 4)
    ).squeeze(-2)
    quaternion = F.normalize(quaternion, dim=-1)
    return torch.where(quaternion[..., :1] < 0, -quaternion, quaternion)


def _sin_half_over_angle(angle: torch.Tensor) -> torch.Tensor:
    """sin(angle / 2) / angle, with its Taylor series near zero (no 0/0)."""
    small = angle.abs() < 1e-6
    safe = torch.where(small, torch.ones_like(angle), angle)
    return torch.where(small, 0.5 - angle * angle / 48, torch.sin(safe / 2) / safe)


def axis_angle_to_quaternion(axis_angle: torch.Tensor) -> torch.Tensor:
    """(..., 3) rotation vector (axis * angle in radians) -> (..., 4)."""
    _check_last_dims(axis_angle, (3,), "axis_angle_to_quaternion")
    angle = torch.linalg.vector_norm(axis_angle, dim=-1, keepdim=True)
    return torch.cat((torch.cos(angle / 2), axis_angle * _sin_half_over_angle(angle)), dim=-1)


def quaternion_to_axis_angle(quaternion: torch.Tensor) -> torch.Tensor:
    """(..., 4) -> (..., 3) rotation vector with angle in [0, pi]."""
    _check_last_dims(quaternion, (4,), "quaternion_to_axis_angle")
    quaternion = F.normalize(quaternion, dim=-1)
    quaternion = torch.where(quaternion[..., :1] < 0, -quaternion, quaternion)
    vector_norm = torch.linalg.vector_norm(quaternion[..., 1:], dim=-1, keepdim=True)
    angle = 2 * torch.atan2(vector_norm, quaternion[..., :1])
    return quaternion[..., 1:] / _sin_half_over_angle(angle)


def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """(..., 3) -> (..., 3, 3)."""
    return quaternion_to_matrix(axis_angle_to_quaternion(axis_angle))


def matrix_to_axis_angle(matrix: torch.Tensor) -> torch.Tensor:
    """(..., 3, 3) -> (..., 3)."""
    return quaternion_to_axis_angle(matrix_to_quaternion(matrix))


def axis_angle_to_rot6d(
    axis_angle: torch.Tensor, layout: Rot6dLayout = ROT6D_LAYOUT
) -> torch.Tensor:
    """(..., 3) -> (..., 6)."""
    return matrix_to_rot6d(axis_angle_to_matrix(axis_angle), layout)


def rot6d_to_axis_angle(rot6d: torch.Tensor, layout: Rot6dLayout = ROT6D_LAYOUT) -> torch.Tensor:
    """(..., 6) -> (..., 3)."""
    return matrix_to_axis_angle(rot6d_to_matrix(rot6d, layout))


def quaternion_multiply(q1: torch.Tensor, q2: torch.Tensor) -> torch.Tensor:
    """Hamilton product q1 * q2 of (..., 4) quaternions (apply q2 first, then q1)."""
    w1, x1, y1, z1 = q1.unbind(-1)
    w2, x2, y2, z2 = q2.unbind(-1)
    return torch.stack(
        (
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ),
        dim=-1,
    )


def quaternion_inverse(quaternion: torch.Tensor) -> torch.Tensor:
    """Inverse of (..., 4) unit quaternions (the conjugate)."""
    return quaternion * quaternion.new_tensor([1.0, -1.0, -1.0, -1.0])


def quaternion_apply(quaternion: torch.Tensor, vector: torch.Tensor) -> torch.Tensor:
    """Rotate (..., 3) vectors by (..., 4) unit quaternions (broadcasting)."""
    _check_last_dims(vector, (3,), "quaternion_apply")
    q_vec = quaternion[..., 1:]
    t = 2 * torch.linalg.cross(q_vec.expand_as(vector), vector, dim=-1)
    return vector + quaternion[..., :1] * t + torch.linalg.cross(q_vec.expand_as(t), t, dim=-1)


def rotation_about_axis(angle: torch.Tensor, axis: Literal["x", "y", "z"]) -> torch.Tensor:
    """(...) angles in radians -> (..., 3, 3) right-handed rotations about a coordinate axis."""
    if axis not in _AXES:
        raise ValueError(f"unknown axis {axis!r}; expected one of 'x', 'y', 'z'")
    angle = torch.as_tensor(angle)
    axis_angle = torch.zeros(
        *angle.shape,
        3,
        dtype=angle.dtype if angle.is_floating_point() else torch.float32,
        device=angle.device,
    )
    axis_angle[..., _AXES[axis]] = angle
    return axis_angle_to_matrix(axis_angle)


def geodesic_angle(matrix1: torch.Tensor, matrix2: torch.Tensor) -> torch.Tensor:
    """Angle in radians of the relative rotation matrix1^T matrix2: (..., 3, 3) x2 -> (...).

    atan2(sin, cos) instead of acos keeps the gradient finite at 0 and pi.
    """
    relative = matrix1.transpose(-1, -2) @ matrix2
    cos = (relative.diagonal(dim1=-2, dim2=-1).sum(-1) - 1) / 2
    skew = torch.stack(
        (
            relative[..., 2, 1] - relative[..., 1, 2],
            relative[..., 0, 2] - relative[..., 2, 0],
            relative[..., 1, 0] - relative[..., 0, 1],
        ),
        dim=-1,
    )
    sin = torch.linalg.vector_norm(skew, dim=-1) / 2
    return torch.atan2(sin, cos)
