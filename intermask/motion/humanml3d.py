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

from intermask.motion.rotations import quaternion_apply
from intermask.motion.skeleton import NUM_JOINTS

FPS = 20
FEATURE_DIM = 263
ROOT_ROT_VELOCITY = slice(0, 1)
ROOT_LINEAR_VELOCITY = slice(1, 3)
ROOT_HEIGHT = slice(3, 4)
RIC = slice(4, 4 + (NUM_JOINTS - 1) * 3)  # 4:67
ROTATIONS = slice(RIC.stop, RIC.stop + (NUM_JOINTS - 1) * 6)  # 67:193
LOCAL_VELOCITY = slice(ROTATIONS.stop, ROTATIONS.stop + NUM_JOINTS * 3)  # 193:259
FOOT_CONTACTS = slice(LOCAL_VELOCITY.stop, LOCAL_VELOCITY.stop + 4)  # 259:263


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
