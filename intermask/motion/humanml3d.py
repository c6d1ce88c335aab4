"""The HumanML3D 263-d per-frame feature (Guo et al. 2022) and joint positions from it.

One person, SMPL 22-joint skeleton (``intermask.motion.skeleton``), Y up, metres, 20 fps.
Frame t of a release clip holds, in this order:

| slice | dims | content |
|---|---|---|
| ``ROOT_ROT_VELOCITY`` | 1 | root rotation about +Y from frame t to t+1, as *half* its angle |
| ``ROOT_LINEAR_VELOCITY`` | 2 | root XZ displacement t -> t+1, in the heading frame of t+1 |
| ``ROOT_HEIGHT`` | 1 | root Y |
| ``RIC`` | 63 | joints 1..21 relative to the root's XZ (Y kept), in the heading frame of t |
| ``ROTATIONS`` | 126 | 6D local rotations of joints 1..21, "columns" layout |
| ``LOCAL_VELOCITY`` | 66 | displacement t -> t+1 of all 22 joints, in the heading frame of t |
| ``FOOT_CONTACTS`` | 4 | left ankle, left toe, right ankle, right toe (0 or 1) |

The "heading frame" is the world turned about +Y so that the person faces +Z; frame 0 of every
clip faces +Z with the root at the XZ origin, so the heading at frame 0 is the identity.
The reference processing stores ``arcsin`` of the Y component of the relative heading quaternion,
i.e. half the yaw change, and rebuilds the heading as the quaternion (cos a, 0, sin a, 0) of the
accumulated half angles a; :func:`recover_root` does the same so that positions match the
released ``new_joints`` files.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F

from intermask.motion.rotations import matrix_to_rot6d, quaternion_apply, rotation_about_axis
from intermask.motion.skeleton import NUM_JOINTS, PARENTS

FPS = 20
FEATURE_DIM = 263
ROOT_ROT_VELOCITY = slice(0, 1)
ROOT_LINEAR_VELOCITY = slice(1, 3)
ROOT_HEIGHT = slice(3, 4)
RIC = slice(4, 4 + (NUM_JOINTS - 1) * 3)  # 4:67
ROTATIONS = slice(RIC.stop, RIC.stop + (NUM_JOINTS - 1) * 6)  # 67:193
LOCAL_VELOCITY = slice(ROTATIONS.stop, ROTATIONS.stop + NUM_JOINTS * 3)  # 193:259
FOOT_CONTACTS = slice(LOCAL_VELOCITY.stop, LOCAL_VELOCITY.stop + 4)  # 259:263
PARTS = (  # the seven parts in order; they tile the 263 dims
    ROOT_ROT_VELOCITY,
    ROOT_LINEAR_VELOCITY,
    ROOT_HEIGHT,
    RIC,
    ROTATIONS,
    LOCAL_VELOCITY,
    FOOT_CONTACTS,
)

# The reference processing (HumanML3D motion_process.py) fixes these:
FACE_JOINTS = (2, 1, 17, 16)  # right hip, left hip, right shoulder, left shoulder
FOOT_JOINTS = (7, 10, 8, 11)  # left ankle, left foot, right ankle, right foot: contact order
# A foot joint touches the ground when its squared displacement to the next frame is below this
# (m^2 at 20 fps): process_file(positions, 0.002). The height test next to it in foot_detect
# (factors 3.0 / 2.0) is commented out in the released code, so height plays no part.
CONTACT_THRESHOLD = 0.002
# The per-frame facing is smoothed over time: gaussian_filter1d(forward, 20, mode="nearest").
HEADING_SIGMA = 20.0  # frames


class HumanML3DParts(NamedTuple):
    """The 263-d frame cut into its parts, joints unflattened."""

    root_rot_velocity: torch.Tensor  # (..., T, 1)
    root_linear_velocity: torch.Tensor  # (..., T, 2) x, z
    root_height: torch.Tensor  # (..., T, 1)
    ric: torch.Tensor  # (..., T, 21, 3)
    rotations: torch.Tensor  # (..., T, 21, 6)
    local_velocity: torch.Tensor  # (..., T, 22, 3)
    foot_contacts: torch.Tensor  # (..., T, 4)


class RootTrajectory(NamedTuple):
    """The root recovered from the velocities (:func:`recover_root`)."""

    heading: torch.Tensor  # (..., T, 4) (w, x, y, z): world -> heading frame
    position: torch.Tensor  # (..., T, 3) world root position


def _check_features(features: torch.Tensor, name: str) -> None:
    if features.ndim < 2 or features.shape[-1] != FEATURE_DIM:
        raise ValueError(
            f"{name}: expected shape (..., T, {FEATURE_DIM}), got {tuple(features.shape)}"
        )
    if not features.is_floating_point():
        raise ValueError(f"{name}: expected a float tensor, got dtype {features.dtype}")


def split_parts(features: torch.Tensor) -> HumanML3DParts:
    """(..., T, 263) -> the named parts (views, no copy)."""
    _check_features(features, "split_parts")
    lead = features.shape[:-1]
    return HumanML3DParts(
        root_rot_velocity=features[..., ROOT_ROT_VELOCITY],
        root_linear_velocity=features[..., ROOT_LINEAR_VELOCITY],
        root_height=features[..., ROOT_HEIGHT],
        ric=features[..., RIC].reshape(*lead, NUM_JOINTS - 1, 3),
        rotations=features[..., ROTATIONS].reshape(*lead, NUM_JOINTS - 1, 6),
        local_velocity=features[..., LOCAL_VELOCITY].reshape(*lead, NUM_JOINTS, 3),
        foot_contacts=features[..., FOOT_CONTACTS],
    )


def _shift_cumsum(x: torch.Tensor, dim: int) -> torch.Tensor:
    """out[t] = sum of x[s] for s < t along ``dim`` (out[0] = 0): the value of frame t is built
    from the velocities of the frames before it."""
    zero = torch.zeros_like(x.narrow(dim, 0, 1))
    return torch.cumsum(torch.cat((zero, x.narrow(dim, 0, x.shape[dim] - 1)), dim=dim), dim=dim)


def recover_root(features: torch.Tensor) -> RootTrajectory:
    """(..., T, 263) -> heading (..., T, 4) and root position (..., T, 3).

    Half angle a_t = sum of the angular channel over frames s < t (a_0 = 0); heading quaternion
    q_t = (cos a_t, 0, sin a_t, 0) (a turn by 2 a_t about +Y, world -> heading frame). The root
    XZ at frame t is the sum over s = 1..t of q_s^-1 applied to the XZ velocity stored at frame
    s - 1: the velocity of s - 1 -> s was written in the heading frame of s, so it is turned back
    with that frame's heading. The root Y is the height channel.
    """
    _check_features(features, "recover_root")
    parts = split_parts(features)
    half_angle = _shift_cumsum(parts.root_rot_velocity[..., 0], dim=-1)  # (..., T)
    zero = torch.zeros_like(half_angle)
    heading = torch.stack((torch.cos(half_angle), zero, torch.sin(half_angle), zero), dim=-1)
    inverse = heading * heading.new_tensor([1.0, -1.0, -1.0, -1.0])
    vx, vz = parts.root_linear_velocity.unbind(-1)
    step = torch.stack((vx, torch.zeros_like(vx), vz), dim=-1)  # (..., T, 3), frame s-1 -> s at s-1
    # Move each step to the frame it ends in (s), turn it with q_s^-1, then integrate.
    shifted = torch.cat((torch.zeros_like(step[..., :1, :]), step[..., :-1, :]), dim=-2)
    world_step = quaternion_apply(inverse, shifted)
    xz = torch.cumsum(world_step, dim=-2)
    position = torch.stack((xz[..., 0], parts.root_height[..., 0], xz[..., 2]), dim=-1)
    return RootTrajectory(heading=heading, position=position)


def recover_from_ric(features: torch.Tensor) -> torch.Tensor:
    """(..., T, 263) de-normalized features -> (..., T, 22, 3) world joint positions, Y up.

    Root from :func:`recover_root`; joints 1..21 are the RIC positions turned back with the
    inverse heading of their own frame, plus the root's XZ (their Y is absolute already). Same
    numbers as the reference ``recover_from_ric`` (float32 or float64, any leading dims).
    """
    _check_features(features, "recover_from_ric")
    root = recover_root(features)
    inverse = root.heading * root.heading.new_tensor([1.0, -1.0, -1.0, -1.0])
    ric = split_parts(features).ric  # (..., T, 21, 3)
    joints = quaternion_apply(inverse[..., None, :], ric)
    ground = root.position * root.position.new_tensor([1.0, 0.0, 1.0])
    joints = joints + ground[..., None, :]
    return torch.cat((root.position[..., None, :], joints), dim=-2)


class HumanML3DMotion(NamedTuple):
    """What :func:`features_from_positions` returns; both have T - 1 frames."""

    features: torch.Tensor  # (T - 1, 263) the ``new_joint_vecs`` array
    joints: torch.Tensor  # (T - 1, 22, 3) the ``new_joints`` array: recover_from_ric(features)


def _smooth(x: torch.Tensor, sigma: float) -> torch.Tensor:
    """(T, C) -> (T, C) Gaussian filter along T, edges repeated (scipy's ``mode="nearest"``,
    kernel cut at 4 sigma as scipy's default ``truncate``)."""
    if sigma <= 0:
        return x
    radius = int(4.0 * sigma + 0.5)
    taps = torch.arange(-radius, radius + 1, dtype=x.dtype)
    kernel = torch.exp(-0.5 * (taps / sigma) ** 2)
    kernel = (kernel / kernel.sum()).expand(x.shape[1], 1, -1)
    padded = F.pad(x.T[None], (radius, radius), mode="replicate")  # (1, C, T + 2 radius)
    return F.conv1d(padded, kernel, groups=x.shape[1])[0].T


def facing_yaw(positions: torch.Tensor, sigma: float = HEADING_SIGMA) -> torch.Tensor:
    """(T, 22, 3) Y-up positions -> (T,) yaw of the facing direction (0 faces +Z, atan2(x, z)).

    Facing = +Y x across, with across the sum of the hips' and the shoulders' right-minus-left
    vectors (``FACE_JOINTS``), normalized, then smoothed over time with ``sigma`` frames.
    """
    r_hip, l_hip, r_shoulder, l_shoulder = FACE_JOINTS
    across = positions[:, r_hip] - positions[:, l_hip]
    across = across + positions[:, r_shoulder] - positions[:, l_shoulder]
    across = F.normalize(across, dim=-1)
    up = torch.zeros_like(across)
    up[:, 1] = 1.0
    forward = _smooth(torch.linalg.cross(up, across, dim=-1), sigma)
    return torch.atan2(forward[:, 0], forward[:, 2])


def features_from_positions(
    positions: torch.Tensor,
    local_rotations: torch.Tensor | None = None,
    *,
    sigma: float = HEADING_SIGMA,
    contact_threshold: float = CONTACT_THRESHOLD,
) -> HumanML3DMotion:
    """(T, 22, 3) Y-up positions at 20 fps (and optionally their (T, 22, 3, 3) local rotations,
    row 0 the root's world orientation) -> the 263-d features and joints of T - 1 frames.

    The motion is first put in the release's canonical place: lowest joint of the clip at Y = 0,
    frame-0 root above the origin, frame-0 heading facing +Z. Heading H_t turns the world about +Y
    by -yaw_t (:func:`facing_yaw`), so that frame t faces +Z. Then, for t < T - 1: the angular
    channel is -wrap(yaw_t+1 - yaw_t) / 2, which equals ``arcsin`` of the Y component of the
    relative quaternion H_t+1 H_t^-1 taken with w >= 0 (the reference takes it without fixing the
    sign, which flips the channel's sign when the smoothed yaw crosses 180 degrees: not copied);
    the root step t -> t+1 turned by H_t+1; the root height; RIC = H_t (p_j - root XZ); the local
    rotations of joints 1..21 in the ``"columns"`` 6D layout, the root's children taken relative
    to the heading (H_t G_root L_j, a yaw-free rotation; the reference derives swing-only
    rotations from bone directions instead, so our values differ there); H_t (p_t+1 - p_t) for
    every joint; foot contacts from ``contact_threshold``. Without ``local_rotations`` the 6D
    part is the identity. ``recover_from_ric(features)`` gives ``joints`` (the canonical
    positions of frames 0..T-2) up to rounding.
    """
    frames = positions.shape[0]
    if positions.ndim != 3 or positions.shape[1:] != (NUM_JOINTS, 3) or frames < 2:
        raise ValueError(
            f"positions: expected shape (T >= 2, {NUM_JOINTS}, 3), got {tuple(positions.shape)}"
        )
    if local_rotations is not None and local_rotations.shape != (frames, NUM_JOINTS, 3, 3):
        raise ValueError(
            f"local_rotations: expected shape ({frames}, {NUM_JOINTS}, 3, 3), "
            f"got {tuple(local_rotations.shape)}"
        )
    dtype = positions.dtype
    positions = positions.clone()
    positions[..., 1] -= positions[..., 1].min()
    yaw = facing_yaw(positions, sigma)
    start = rotation_about_axis(-yaw[0], "y")
    origin = positions[0, 0] * positions.new_tensor([1.0, 0.0, 1.0])
    positions = (positions - origin) @ start.T
    yaw = yaw - yaw[0]
    heading = rotation_about_axis(-yaw, "y")  # (T, 3, 3) world -> heading frame
    step = torch.remainder(yaw[1:] - yaw[:-1] + torch.pi, 2 * torch.pi) - torch.pi
    rot_velocity = -0.5 * step[:, None]  # (T-1, 1)
    root = positions[:, 0]
    root_step = torch.einsum("tij,tj->ti", heading[1:], root[1:] - root[:-1])[:, [0, 2]]
    ground = root * root.new_tensor([1.0, 0.0, 1.0])
    ric = torch.einsum("tij,tkj->tki", heading, positions[:, 1:] - ground[:, None])
    velocity = torch.einsum("tij,tkj->tki", heading[:-1], positions[1:] - positions[:-1])
    if local_rotations is None:
        local = torch.eye(3, dtype=dtype).expand(frames, NUM_JOINTS - 1, 3, 3)
    else:
        local = local_rotations[:, 1:].to(dtype).clone()
        root_frame = heading @ start @ local_rotations[:, 0].to(dtype)  # yaw-free root
        for joint in range(1, NUM_JOINTS):
            if PARENTS[joint] == 0:
                local[:, joint - 1] = root_frame @ local[:, joint - 1]
    rotations = matrix_to_rot6d(local, "columns")  # (T, 21, 6)
    feet = positions[1:, list(FOOT_JOINTS)] - positions[:-1, list(FOOT_JOINTS)]
    contacts = ((feet**2).sum(-1) < contact_threshold).to(dtype)  # (T-1, 4)
    last = frames - 1
    features = torch.cat(
        (
            rot_velocity,
            root_step,
            root[:last, 1:2],
            ric[:last].reshape(last, -1),
            rotations[:last].reshape(last, -1),
            velocity.reshape(last, -1),
            contacts,
        ),
        dim=-1,
    )
    return HumanML3DMotion(features=features, joints=positions[:last])
