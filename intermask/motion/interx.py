"""The Inter-X 56x6 representation, and joint positions from either dataset's representation.

Processed release (``motions/{train,val,test}.h5``): (T, 56, 6) per clip, Z-up, 30 fps. Rows
0..54 are axis-angle rotations (global orient, 21 body joints, jaw, left eye, right eye, 15 left
hand, 15 right hand), row 55 the root translation; channels 0:3 are person 1, 3:6 person 2.

Generator representation per person (T, 56, 6): rows 0..54 -> 6D rotation ("rows" layout),
row 55 -> [translation 3, translation velocity 3], the last frame's velocity being 0.
"""

from __future__ import annotations

from typing import Literal

import torch
from einops import rearrange

from intermask.motion.interhuman import FEATURE_DIM, features_to_positions, zup_to_yup
from intermask.motion.kinds import DatasetKind, check_dataset_kind
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.rotations import axis_angle_to_rot6d, rot6d_to_axis_angle, rot6d_to_matrix
from intermask.motion.skeleton import NUM_JOINTS, REST_OFFSETS

FPS = 30  # frames per second of the processed release
NUM_ROWS = 56
NUM_ROTATION_ROWS = 55
TRANSLATION_ROW = 55
NUM_PERSONS = 2
RAW_CHANNELS = (
    6  # 3 per person in the release; [6D] or [translation, velocity] in the representation
)
BODY_ROWS = slice(0, NUM_JOINTS)  # global orient + 21 body joints = the SMPL 22-joint skeleton

UpAxis = Literal["y", "z"]


def _check_last_dims(x: torch.Tensor, expected: tuple[int, ...], name: str) -> None:
    received = tuple(x.shape)
    if len(received) < len(expected) or received[len(received) - len(expected) :] != expected:
        dims = ", ".join(map(str, expected))
        raise ValueError(f"{name}: expected shape (..., {dims}), got {received}")


def split_persons(raw: torch.Tensor) -> torch.Tensor:
    """(..., T, 56, 6) processed release -> (..., T, 2, 56, 3) axis-angle/translation per person."""
    _check_last_dims(raw, (NUM_ROWS, RAW_CHANNELS), "split_persons")
    return rearrange(raw, "... t r (p c) -> ... t p r c", p=NUM_PERSONS)


def person_representation(axis_angle: torch.Tensor) -> torch.Tensor:
    """(..., T, 56, 3) one person's rows -> (..., T, 56, 6) generator representation."""
    _check_last_dims(axis_angle, (NUM_ROWS, 3), "person_representation")
    if axis_angle.ndim < 3:
        raise ValueError(
            f"person_representation: expected (..., T, 56, 3), got {tuple(axis_angle.shape)}"
        )
    rot6d = axis_angle_to_rot6d(axis_angle[..., :NUM_ROTATION_ROWS, :])  # (..., T, 55, 6)
    translation = axis_angle[..., TRANSLATION_ROW, :]  # (..., T, 3)
    velocity = torch.cat(
        (
            translation[..., 1:, :] - translation[..., :-1, :],
            torch.zeros_like(translation[..., :1, :]),
        ),
        dim=-2,
    )
    root_row = torch.cat((translation, velocity), dim=-1)[..., None, :]  # (..., T, 1, 6)
    return torch.cat((rot6d, root_row), dim=-2)


def representation_to_axis_angle(representation: torch.Tensor) -> torch.Tensor:
    """(..., T, 56, 6) generator representation -> (..., T, 56, 3) release rows (inverse)."""
    _check_last_dims(representation, (NUM_ROWS, RAW_CHANNELS), "representation_to_axis_angle")
    axis_angle = rot6d_to_axis_angle(representation[..., :NUM_ROTATION_ROWS, :])
    translation = representation[..., TRANSLATION_ROW:, :3]
    return torch.cat((axis_angle, translation), dim=-2)


def interx_positions(
    representation: torch.Tensor, offsets: torch.Tensor = REST_OFFSETS, up_axis: UpAxis = "z"
) -> torch.Tensor:
    """(..., T, 56, 6) representation -> (..., T, 22, 3) Y-up joint positions.

    Forward kinematics of rows 0..21 (global orient + 21 body joints) with the pelvis at the
    translation (our body-model convention; SMPL-X would add a shape-dependent pelvis offset).
    offsets: (22, 3) or broadcastable to (..., T, 22, 3), in the body's Y-up rest frame.
    up_axis names the raw frame's up axis ("z" for the release); the output is always Y-up.
    """
    _check_last_dims(representation, (NUM_ROWS, RAW_CHANNELS), "interx_positions")
    if up_axis not in ("y", "z"):
        raise ValueError(f"interx_positions: up_axis must be 'y' or 'z', got {up_axis!r}")
    local_rotations = rot6d_to_matrix(representation[..., BODY_ROWS, :])  # (..., T, 22, 3, 3)
    translation = representation[..., TRANSLATION_ROW, :3]  # (..., T, 3)
    positions = forward_kinematics(local_rotations, translation, offsets).positions
    return zup_to_yup(positions) if up_axis == "z" else positions


def interhuman_joint_positions(features: torch.Tensor) -> torch.Tensor:
    """(..., P, T, 262) de-normalized features -> (..., T, P, 22, 3) joint positions."""
    _check_last_dims(features, (FEATURE_DIM,), "interhuman_joint_positions")
    if features.ndim < 3:
        raise ValueError(
            f"interhuman_joint_positions: expected (..., P, T, 262), got {tuple(features.shape)}"
        )
    positions = person_joint_positions(features, "interhuman")
    return rearrange(positions, "... p t j c -> ... t p j c")


def interx_joint_positions(
    representation: torch.Tensor, offsets: torch.Tensor = REST_OFFSETS, up_axis: UpAxis = "z"
) -> torch.Tensor:
    """(..., P, T, 56, 6) per-person representations -> (..., T, P, 22, 3) Y-up joint positions."""
    _check_last_dims(representation, (NUM_ROWS, RAW_CHANNELS), "interx_joint_positions")
    if representation.ndim < 4:
        raise ValueError(
            f"interx_joint_positions: expected (..., P, T, 56, 6), got {tuple(representation.shape)}"
        )
    positions = person_joint_positions(representation, "interx", offsets=offsets, up_axis=up_axis)
    return rearrange(positions, "... p t j c -> ... t p j c")


def representation_of(features: torch.Tensor) -> DatasetKind:
    """The kind of de-normalized features by their trailing shape: (..., 262) InterHuman or
    (..., 56, 6) Inter-X."""
    if features.shape[-1] == FEATURE_DIM:
        return "interhuman"
    if tuple(features.shape[-2:]) == (NUM_ROWS, RAW_CHANNELS):
        return "interx"
    raise ValueError(
        f"no joint positions for features of shape {tuple(features.shape)}: expected (..., T, "
        f"{FEATURE_DIM}) InterHuman or (..., T, {NUM_ROWS}, {RAW_CHANNELS}) Inter-X"
    )


def person_joint_positions(
    features: torch.Tensor,
    representation: DatasetKind | None = None,
    *,
    offsets: torch.Tensor = REST_OFFSETS,
    up_axis: UpAxis = "z",
) -> torch.Tensor:
    """(..., T, *F) de-normalized features -> (..., T, 22, 3) joint positions in metres, Y-up:
    the one place features become joints. ``representation`` None reads it from the shape;
    Inter-X goes through the skeleton ``offsets`` (template by default) from its raw
    ``up_axis`` frame."""
    if representation is None:
        representation = representation_of(features)
    if check_dataset_kind(representation, name="representation") == "interhuman":
        return features_to_positions(features)
    return interx_positions(features, offsets=offsets, up_axis=up_axis)


def to_joint_positions(
    motion: torch.Tensor,
    representation: DatasetKind,
    offsets: torch.Tensor = REST_OFFSETS,
    up_axis: UpAxis = "z",
) -> torch.Tensor:
    """Joint positions (..., T, P, 22, 3), Y-up, for metrics and rendering.

    motion: de-normalized, (..., P, T, 262) for "interhuman" or (..., P, T, 56, 6) for "interx"
    (offsets and up_axis apply to "interx" only).
    """
    if check_dataset_kind(representation, name="representation") == "interhuman":
        return interhuman_joint_positions(motion)
    return interx_joint_positions(motion, offsets=offsets, up_axis=up_axis)
