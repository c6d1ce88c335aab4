"""The InterHuman 262-d per-person feature, its two-person relation and its per-joint view.

Raw release (``motions_processed/person{1,2}/<id>.npy``): (T, 492) float32 in a Z-up world frame;
columns [0:186] are 62 SMPL-H joint positions, [186:492] 51 local 6D rotations of joints 1..51
("rows" layout). Only the 22 body positions and the 21 body rotations are used.

The feature (per person, per frame, 262 = 66 + 66 + 126 + 4), following InterGen's processing:
    positions 22x3 | velocities 22x3 | 6D rotations of joints 1..21 | foot contacts (7, 10, 8, 11)
after (1) Z-up -> Y-up, (2) flooring, (3) frame-0 root to the origin in x and z, (4) turning the
person to face +Z at frame 0, (5) dropping the last frame (velocity t = pos t+1 - pos t).
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from einops import rearrange

from intermask.motion.mirror import mirror_joint_positions, mirror_joint_rot6d
from intermask.motion.skeleton import FACE_JOINTS, FOOT_JOINTS, MIRROR_PERMUTATION, NUM_JOINTS

FPS = 30  # frames per second of the release (InterGen), and of the embedded dataset
RAW_DIM = 492
NUM_RAW_JOINTS = 62  # 22 body + 30 hand joints + 10 finger tips
NUM_RAW_ROTATIONS = 51  # joints 1..51
RAW_POSITIONS = slice(0, 66)  # 22 body joints x 3
RAW_ROTATIONS = slice(186, 312)  # joints 1..21 x 6D
FEATURE_DIM = 262
POSITIONS = slice(0, 66)
VELOCITIES = slice(66, 132)
ROTATIONS = slice(132, 258)
CONTACTS = slice(258, 262)
NUM_ROTATIONS = NUM_JOINTS - 1  # the root has no rotation in the feature
JOINT_VIEW_CHANNELS = 12  # [pos 3, vel 3, rot6d 6]
VELOCITY_THRESHOLD = 0.001  # squared metres per frame (InterGen's feet_thre)
HEIGHT_THRESHOLDS = (0.12, 0.05)  # metres: (ankle, foot)
# Contacts are ordered like FOOT_JOINTS (l_ankle, l_foot, r_ankle, r_foot); a mirror swaps sides.
CONTACT_MIRROR_PERMUTATION = (2, 3, 0, 1)

# SMPL-H order after the body: 15 left-hand joints, 15 right-hand joints, then the finger tips,
# 5 left and 5 right. The generators never read the hands; mirroring them keeps the raw row whole.
_HAND_JOINTS = 15
_TIPS = 5
_LEFT_HAND = NUM_JOINTS
_RIGHT_HAND = NUM_JOINTS + _HAND_JOINTS
_LEFT_TIPS = NUM_JOINTS + 2 * _HAND_JOINTS
_RIGHT_TIPS = _LEFT_TIPS + _TIPS


def _raw_mirror_permutation() -> tuple[int, ...]:
    permutation = list(MIRROR_PERMUTATION) + list(range(NUM_JOINTS, NUM_RAW_JOINTS))
    for left, right, count in (
        (_LEFT_HAND, _RIGHT_HAND, _HAND_JOINTS),
        (_LEFT_TIPS, _RIGHT_TIPS, _TIPS),
    ):
        for k in range(count):
            permutation[left + k], permutation[right + k] = right + k, left + k
    return tuple(permutation)


RAW_MIRROR_PERMUTATION: tuple[int, ...] = _raw_mirror_permutation()  # 62 raw joints
RAW_ROTATION_MIRROR_PERMUTATION: tuple[int, ...] = tuple(  # 51 rotations of joints 1..51
    RAW_MIRROR_PERMUTATION[joint] - 1 for joint in range(1, NUM_RAW_ROTATIONS + 1)
)


class BodyMotion(NamedTuple):
    positions: torch.Tensor  # (..., T, 22, 3) body joint positions, raw (Z-up) frame
    rot6d: torch.Tensor  # (..., T, 21, 6) local rotations of joints 1..21


class Canonical(NamedTuple):
    positions: torch.Tensor  # (..., T, 22, 3) canonical = facing @ (world - origin)
    facing: torch.Tensor  # (..., 3, 3) rotation about +Y taking the frame-0 forward to +Z
    origin: torch.Tensor  # (..., 3) (frame-0 root x, floor height, frame-0 root z), Y-up


class PersonFeatures(NamedTuple):
    features: torch.Tensor  # (..., T-1, 262)
    facing: torch.Tensor  # (..., 3, 3) see Canonical
    origin: torch.Tensor  # (..., 3) see Canonical


class FeatureParts(NamedTuple):
    positions: torch.Tensor  # (..., 22, 3)
    velocities: torch.Tensor  # (..., 22, 3)
    rot6d: torch.Tensor  # (..., 21, 6) joints 1..21
    contacts: torch.Tensor  # (..., 4) l_ankle, l_foot, r_ankle, r_foot


def _check_last_dims(
    x: torch.Tensor, expected: tuple[int, ...], name: str, min_frames: int = 0
) -> None:
    """Raise ValueError unless x is (..., *expected) with at least min_frames frames before them."""
    received = tuple(x.shape)
    dims = ", ".join(map(str, expected))
    if len(received) < len(expected) or received[len(received) - len(expected) :] != expected:
        raise ValueError(f"{name}: expected shape (..., {dims}), got {received}")
    if min_frames == 0:
        return
    frames = received[-len(expected) - 1] if len(received) > len(expected) else 0
    if frames < min_frames:
        raise ValueError(
            f"{name}: expected (..., T, {dims}) with T >= {min_frames} frames, got {received}"
        )


# ----------------------------------------------------------------------------- raw frame


def select_body(raw: torch.Tensor) -> BodyMotion:
    """(..., T, 492) raw rows -> the 22 body positions and the 21 body rotations."""
    _check_last_dims(raw, (RAW_DIM,), "select_body")
    positions = rearrange(raw[..., RAW_POSITIONS], "... (j c) -> ... j c", c=3)
    rot6d = rearrange(raw[..., RAW_ROTATIONS], "... (j c) -> ... j c", c=6)
    return BodyMotion(positions, rot6d)


def zup_to_yup(vectors: torch.Tensor) -> torch.Tensor:
    """(..., 3) Z-up (x, y, z) -> Y-up (x, z, -y): a rotation of -90 degrees about x."""
    _check_last_dims(vectors, (3,), "zup_to_yup")
    x, y, z = vectors.unbind(-1)
    return torch.stack((x, z, -y), dim=-1)


def yup_to_zup(vectors: torch.Tensor) -> torch.Tensor:
    """(..., 3) Y-up (x, y, z) -> Z-up (x, -z, y), the inverse of zup_to_yup."""
    _check_last_dims(vectors, (3,), "yup_to_zup")
    x, y, z = vectors.unbind(-1)
    return torch.stack((x, -z, y), dim=-1)


def mirror_body(body: BodyMotion) -> BodyMotion:
    """Mirror a body motion: negate x, swap left/right joints, M R M on the 6D rotations."""
    return BodyMotion(mirror_joint_positions(body.positions), mirror_joint_rot6d(body.rot6d))


def mirror_raw(raw: torch.Tensor) -> torch.Tensor:
    """(..., T, 492) -> (..., T, 492) mirrored, hands and finger tips included; an involution."""
    _check_last_dims(raw, (RAW_DIM,), "mirror_raw")
    positions_end = NUM_RAW_JOINTS * 3
    positions = rearrange(raw[..., :positions_end], "... (j c) -> ... j c", c=3)
    rot6d = rearrange(raw[..., positions_end:], "... (j c) -> ... j c", c=6)
    positions = mirror_joint_positions(positions, RAW_MIRROR_PERMUTATION)
    rot6d = mirror_joint_rot6d(rot6d, RAW_ROTATION_MIRROR_PERMUTATION)
    return torch.cat(
        (rearrange(positions, "... j c -> ... (j c)"), rearrange(rot6d, "... j c -> ... (j c)")),
        dim=-1,
    )


# ----------------------------------------------------------------------------- canonical frame


def foot_contacts(
    positions: torch.Tensor,
    velocity_threshold: float = VELOCITY_THRESHOLD,
    height_thresholds: tuple[float, float] = HEIGHT_THRESHOLDS,
) -> torch.Tensor:
    """(..., T, 22, 3) floored Y-up positions -> (..., T-1, 4) contacts in {0, 1}.

    A foot joint touches the ground at frame t when its squared displacement to frame t+1 is below
    velocity_threshold and its height at frame t is below the (ankle, foot) height threshold.
    Order: l_ankle, l_foot, r_ankle, r_foot (skeleton.FOOT_JOINTS).
    """
    _check_last_dims(positions, (NUM_JOINTS, 3), "foot_contacts", min_frames=2)
    feet = positions[..., list(FOOT_JOINTS), :]  # (..., T, 4, 3)
    squared_speed = (feet[..., 1:, :, :] - feet[..., :-1, :, :]).square().sum(-1)  # (..., T-1, 4)
    ankle, foot = height_thresholds
    heights = positions.new_tensor([ankle, foot, ankle, foot])
    contact = (squared_speed < velocity_threshold) & (feet[..., :-1, :, 1] < heights)
    return contact.to(positions.dtype)


def facing_rotation(joints: torch.Tensor, eps: float = 1e-8) -> torch.Tensor:
    """(..., 22, 3) Y-up joints of one frame -> (..., 3, 3) rotation about +Y turning them to +Z.

    forward = normalize(cross(up, r_hip - l_hip)) = normalize((across_z, 0, -across_x)); the
    rotation by angle a about +Y maps (fx, 0, fz) to +Z when cos a = fz and sin a = -fx. Written in
    closed form instead of InterGen's quaternion-between-vectors, which is undefined when the person
    already faces -Z.
    """
    _check_last_dims(joints, (NUM_JOINTS, 3), "facing_rotation")
    r_hip, l_hip = FACE_JOINTS[0], FACE_JOINTS[1]
    across = joints[..., r_hip, :] - joints[..., l_hip, :]
    forward_x, forward_z = across[..., 2], -across[..., 0]
    length = torch.hypot(forward_x, forward_z)
    if bool((length < eps).any()):
        raise ValueError(
            f"facing_rotation: the hip vector r_hip - l_hip needs a horizontal component of at least "
            f"{eps}; got {length.min().item():.3g} (vertical hips, or all-zero joints)"
        )
    cos, sin = forward_z / length, -forward_x / length
    zero, one = torch.zeros_like(cos), torch.ones_like(cos)
    rows = (cos, zero, sin, zero, one, zero, -sin, zero, cos)
    return torch.stack(rows, dim=-1).reshape(*cos.shape, 3, 3)


def canonicalize_person(positions: torch.Tensor) -> Canonical:
    """(..., T, 22, 3) Y-up world positions -> floored, frame-0 root at the origin, facing +Z."""
    _check_last_dims(positions, (NUM_JOINTS, 3), "canonicalize_person", min_frames=1)
    floor = positions[..., 1].amin(dim=(-2, -1))  # (...) over frames and joints
    root = positions[..., 0, 0, :]  # (..., 3) frame 0, joint 0
    origin = torch.stack((root[..., 0], floor, root[..., 2]), dim=-1)
    facing = facing_rotation(positions[..., 0, :, :])
    canonical = torch.einsum("...ij,...tkj->...tki", facing, positions - origin[..., None, None, :])
    return Canonical(canonical, facing, origin)


def assemble_features(positions: torch.Tensor, rot6d: torch.Tensor) -> torch.Tensor:
    """Canonical (..., T, 22, 3) positions and (..., T, 21, 6) rotations -> (..., T-1, 262)."""
    _check_last_dims(positions, (NUM_JOINTS, 3), "assemble_features", min_frames=2)
    _check_last_dims(rot6d, (NUM_ROTATIONS, 6), "assemble_features")
    velocities = positions[..., 1:, :, :] - positions[..., :-1, :, :]
    parts = FeatureParts(
        positions[..., :-1, :, :], velocities, rot6d[..., :-1, :, :], foot_contacts(positions)
    )
    return join_features(parts)


def person_features(raw: torch.Tensor, mirror: bool = False) -> PersonFeatures:
    """(..., T, 492) raw rows of one person -> PersonFeatures with features (..., T-1, 262).

    mirror=True mirrors the raw motion first (before canonicalization, as the reference does).
    """
    _check_last_dims(raw, (RAW_DIM,), "person_features", min_frames=2)
    body = select_body(raw)
    if mirror:
        body = mirror_body(body)
    canonical = canonicalize_person(zup_to_yup(body.positions))
    features = assemble_features(canonical.positions, body.rot6d)
    return PersonFeatures(features, canonical.facing, canonical.origin)


# ----------------------------------------------------------------------------- two persons


def to_reference_frame(
    features: torch.Tensor,
    *,
    facing: torch.Tensor,
    origin: torch.Tensor,
    reference_facing: torch.Tensor,
    reference_origin: torch.Tensor,
) -> torch.Tensor:
    """Re-express canonical (..., T, 262) features in another person's canonical frame.

    facing/origin: (..., 3, 3)/(..., 3) of the person the features belong to (see Canonical);
    reference_facing/reference_origin: the same for the reference person.

    The world positions are facing^T c + origin; in the reference frame they become
    reference_facing (world - reference_origin), except that each person keeps their own floor
    (InterGen zeroes the y of the offset), so the offset is taken in x and z only. Velocities are
    rotated; rotations (local) and contacts are unchanged.
    """
    _check_last_dims(features, (FEATURE_DIM,), "to_reference_frame")
    rotation = reference_facing @ facing.transpose(-1, -2)  # (..., 3, 3)
    offset = (origin - reference_origin) * origin.new_tensor([1.0, 0.0, 1.0])
    offset = torch.einsum("...ij,...j->...i", reference_facing, offset)  # (..., 3)
    parts = split_features(features)
    positions = torch.einsum("...ij,...tkj->...tki", rotation, parts.positions)
    positions = positions + offset[..., None, None, :]
    velocities = torch.einsum("...ij,...tkj->...tki", rotation, parts.velocities)
    return join_features(parts._replace(positions=positions, velocities=velocities))


def interaction_features(
    raw1: torch.Tensor, raw2: torch.Tensor, mirror: bool = False
) -> torch.Tensor:
    """Two persons' (..., T, 492) raw rows -> (..., T-1, 2, 262).

    Person 1 is canonical (frame-0 root at the origin, facing +Z); person 2 is canonicalized on
    their own and then moved into person 1's frame (relative yaw and xz offset).
    """
    if raw1.shape != raw2.shape:
        raise ValueError(
            f"interaction_features: both persons need the same shape; got {tuple(raw1.shape)} "
            f"and {tuple(raw2.shape)}"
        )
    one = person_features(raw1, mirror=mirror)
    two = person_features(raw2, mirror=mirror)
    two_in_one = to_reference_frame(
        two.features,
        facing=two.facing,
        origin=two.origin,
        reference_facing=one.facing,
        reference_origin=one.origin,
    )
    return torch.stack((one.features, two_in_one), dim=-2)


# ----------------------------------------------------------------------------- feature views


def split_features(features: torch.Tensor) -> FeatureParts:
    """(..., 262) -> FeatureParts (views into the input)."""
    _check_last_dims(features, (FEATURE_DIM,), "split_features")
    return FeatureParts(
        rearrange(features[..., POSITIONS], "... (j c) -> ... j c", c=3),
        rearrange(features[..., VELOCITIES], "... (j c) -> ... j c", c=3),
        rearrange(features[..., ROTATIONS], "... (j c) -> ... j c", c=6),
        features[..., CONTACTS],
    )


def join_features(parts: FeatureParts) -> torch.Tensor:
    """FeatureParts -> (..., 262), the inverse of split_features."""
    return torch.cat(
        (
            rearrange(parts.positions, "... j c -> ... (j c)"),
            rearrange(parts.velocities, "... j c -> ... (j c)"),
            rearrange(parts.rot6d, "... j c -> ... (j c)"),
            parts.contacts,
        ),
        dim=-1,
    )


def mirror_features(features: torch.Tensor) -> torch.Tensor:
    """(..., 262) canonical features -> the features of the mirrored motion.

    Equal to the features of the mirrored raw motion: reflecting x maps the floor, the frame-0
    root and the frame-0 facing to their mirror images, so canonicalization commutes with the
    mirror (and so does the two-person relation, whose rotation F1 F2^T becomes M F1 F2^T M).
    """
    parts = split_features(features)
    return join_features(
        FeatureParts(
            mirror_joint_positions(parts.positions),
            mirror_joint_positions(parts.velocities),
            mirror_joint_rot6d(parts.rot6d),
            parts.contacts[..., list(CONTACT_MIRROR_PERMUTATION)],
        )
    )


def features_to_positions(features: torch.Tensor) -> torch.Tensor:
    """(..., 262) -> (..., 22, 3) joint positions (Y-up, canonical frame)."""
    return split_features(features).positions


def features_to_joint_view(features: torch.Tensor) -> torch.Tensor:
    """(..., 262) -> (..., 22, 12) per-joint [pos 3, vel 3, rot6d 6]; the root's rotation is zeros.

    Foot contacts are not part of the view (InterMask's VQ input).
    """
    parts = split_features(features)
    root_rotation = parts.rot6d.new_zeros(*parts.rot6d.shape[:-2], 1, 6)
    rot6d = torch.cat((root_rotation, parts.rot6d), dim=-2)  # (..., 22, 6)
    return torch.cat((parts.positions, parts.velocities, rot6d), dim=-1)


def joint_view_to_features(view: torch.Tensor) -> torch.Tensor:
    """(..., 22, 12) per-joint view -> (..., 262); the root rotation is dropped, contacts are zeros.

    Meant for normalized space, where zero is the mean contact value.
    """
    _check_last_dims(view, (NUM_JOINTS, JOINT_VIEW_CHANNELS), "joint_view_to_features")
    contacts = view.new_zeros(*view.shape[:-2], len(FOOT_JOINTS))
    parts = FeatureParts(view[..., 0:3], view[..., 3:6], view[..., 1:, 6:12], contacts)
    return join_features(parts)
