"""Joint validation, camera presets and the perspective projection shared by every renderer.

Everything here is numpy (float64) on Y-up metres. A camera orbits the scene centre: its azimuth
is measured from the direction perpendicular to the line joining the two persons, so the preset
``"side"`` always shows both people side by side, person 1 on the left, whatever the heading of
the pair in the world.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from intermask.motion.skeleton import FACE_JOINTS, NUM_JOINTS

UpAxis = Literal["y", "z"]
NEAR_PLANE = 0.05  # metres in front of the camera; nearer geometry is clipped away


@dataclass(frozen=True)
class Camera:
    """An orbit camera around the scene centre.

    azimuth_deg: rotation about +Y from the pair's side view; elevation_deg: above the floor
    plane (< 90); fov_deg: vertical field of view; zoom: > 1 moves closer than the framing that
    fits every joint of every frame.
    """

    azimuth_deg: float = 0.0
    elevation_deg: float = 15.0
    fov_deg: float = 40.0
    zoom: float = 1.0

    def __post_init__(self) -> None:
        if not -89.9 <= self.elevation_deg <= 89.9:
            raise ValueError(
                f"Camera: elevation_deg must be in [-89.9, 89.9], got {self.elevation_deg}"
            )
        if not 5.0 <= self.fov_deg <= 150.0:
            raise ValueError(f"Camera: fov_deg must be in [5, 150], got {self.fov_deg}")
        if self.zoom <= 0:
            raise ValueError(f"Camera: zoom must be > 0, got {self.zoom}")


VIEWS: dict[str, Camera] = {
    "side": Camera(azimuth_deg=0.0, elevation_deg=15.0),
    "oblique": Camera(azimuth_deg=40.0, elevation_deg=28.0),
    "along": Camera(azimuth_deg=-90.0, elevation_deg=15.0),  # behind person 1, facing person 2
    "top": Camera(azimuth_deg=0.0, elevation_deg=80.0),
}


def resolve_views(view: str | Camera | Sequence[str | Camera]) -> list[tuple[str, Camera]]:
    """A view name, a Camera or a sequence of them -> [(label, Camera)], at least one."""
    items = [view] if isinstance(view, str | Camera) else list(view)
    if not items:
        raise ValueError("view: expected at least one view name or Camera, got an empty sequence")
    resolved = []
    for item in items:
        if isinstance(item, Camera):
            resolved.append((f"az {item.azimuth_deg:g} el {item.elevation_deg:g}", item))
        elif item in VIEWS:
            resolved.append((item, VIEWS[item]))
        else:
            raise ValueError(
                f"unknown view {item!r}; expected a Camera or one of {', '.join(VIEWS)}"
            )
    return resolved


def prepare_joints(joints: object, *, up_axis: UpAxis = "y", name: str = "joints") -> np.ndarray:
    """(T, P, 22, 3) or (T, 22, 3) positions (numpy or torch) -> float64 (T, P, 22, 3), Y-up.

    up_axis="z" converts from a Z-up frame (x, y, z) -> (x, z, -y), as motion.zup_to_yup does.
    """
    if hasattr(joints, "detach"):  # a torch tensor; avoid importing torch for numpy callers
        joints = joints.detach().cpu().numpy()
    array = np.asarray(joints, dtype=np.float64)
    if array.ndim == 3:
        array = array[:, None]
    if array.ndim != 4 or array.shape[-2:] != (NUM_JOINTS, 3):
        raise ValueError(
            f"{name}: expected shape (T, P, {NUM_JOINTS}, 3) or (T, {NUM_JOINTS}, 3), "
            f"got {tuple(np.shape(joints))}"
        )
    if array.shape[0] < 1 or array.shape[1] < 1:
        raise ValueError(f"{name}: needs at least one frame and one person, got {array.shape}")
    if not np.isfinite(array).all():
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(array))[0])
        raise ValueError(f"{name}: non-finite value at (frame, person, joint, axis) {bad}")
    if up_axis == "z":
        array = np.stack((array[..., 0], array[..., 2], -array[..., 1]), axis=-1)
    elif up_axis != "y":
        raise ValueError(f"{name}: up_axis must be 'y' or 'z', got {up_axis!r}")
    return array


@dataclass(frozen=True)
class Scene:
    """Where a clip lives: the floor height, the horizontal extent and the pair axis."""

    floor: float
    centre: np.ndarray  # (3,) middle of the bounding box of all joints over all frames
    radius: float  # half the bounding box diagonal (at least 0.5 m)
    pair_axis: np.ndarray  # (3,) horizontal unit vector from person 1 towards person 2
    extent: tuple[float, float, float, float]  # (x_min, x_max, z_min, z_max) of all joints


def scene_of(joints: np.ndarray) -> Scene:
    """Frame a (T, P, 22, 3) clip: floor = lowest joint, pair axis from the mean pelvis positions.

    With one person (or two on the same spot) the axis is the first frame's hip line, so the
    "side" view looks at that person from the front.
    """
    low, high = joints.reshape(-1, 3).min(0), joints.reshape(-1, 3).max(0)
    centre = (low + high) / 2
    radius = max(float(np.linalg.norm(high - low)) / 2, 0.5)
    axis = np.zeros(3)
    if joints.shape[1] >= 2:
        axis = joints[:, 1, 0].mean(0) - joints[:, 0, 0].mean(0)
        axis[1] = 0.0
    if np.linalg.norm(axis) < 1e-3:
        r_hip, l_hip = FACE_JOINTS[0], FACE_JOINTS[1]
        axis = joints[0, 0, r_hip] - joints[0, 0, l_hip]
        axis[1] = 0.0
    if np.linalg.norm(axis) < 1e-6:
        axis = np.array([1.0, 0.0, 0.0])
    return Scene(
        floor=float(low[1]),
        centre=centre,
        radius=radius,
        pair_axis=axis / np.linalg.norm(axis),
        extent=(float(low[0]), float(high[0]), float(low[2]), float(high[2])),
    )


@dataclass(frozen=True)
class CameraPose:
    """A placed camera: eye position and the orthonormal (right, up, forward) basis."""

    eye: np.ndarray  # (3,)
    basis: np.ndarray  # (3, 3) rows: right, up, forward
    focal: float  # pixels per unit of x/z for the image height
    width: int
    height: int


def place_camera(camera: Camera, scene: Scene, size: tuple[int, int]) -> CameraPose:
    """Put a Camera in a Scene for an image of size (width, height) in pixels."""
    width, height = size
    # n points from the scene to a camera whose screen-right is the pair axis (person 2 on the right)
    n = np.array([-scene.pair_axis[2], 0.0, scene.pair_axis[0]])
    azimuth, elevation = math.radians(camera.azimuth_deg), math.radians(camera.elevation_deg)
    cos_a, sin_a = math.cos(azimuth), math.sin(azimuth)
    n = np.array([cos_a * n[0] + sin_a * n[2], 0.0, -sin_a * n[0] + cos_a * n[2]])
    direction = math.cos(elevation) * n + np.array([0.0, math.sin(elevation), 0.0])
    half_fov = math.radians(camera.fov_deg) / 2
    # Fit the bounding sphere in the narrower of the two fields of view.
    aspect = min(1.0, width / height)
    distance = 1.1 * scene.radius / math.sin(math.atan(math.tan(half_fov) * aspect)) / camera.zoom
    eye = scene.centre + distance * direction
    forward = -direction
    right = np.cross(forward, np.array([0.0, 1.0, 0.0]))
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    focal = (height / 2) / math.tan(half_fov)
    return CameraPose(
        eye=eye, basis=np.stack((right, up, forward)), focal=focal, width=width, height=height
    )


def to_camera(pose: CameraPose, points: np.ndarray) -> np.ndarray:
    """(..., 3) world points -> (..., 3) camera coordinates (right, up, depth)."""
    return (points - pose.eye) @ pose.basis.T


def camera_to_pixels(pose: CameraPose, camera_points: np.ndarray) -> np.ndarray:
    """(..., 3) camera coordinates with depth > 0 -> (..., 2) pixel coordinates (u right, v down)."""
    depth = np.maximum(camera_points[..., 2], NEAR_PLANE)
    u = pose.width / 2 + pose.focal * camera_points[..., 0] / depth
    v = pose.height / 2 - pose.focal * camera_points[..., 1] / depth
    return np.stack((u, v), axis=-1)


def project(pose: CameraPose, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(..., 3) world points -> ((..., 2) pixels, (...) depth). Depth <= NEAR_PLANE is behind."""
    camera_points = to_camera(pose, points)
    return camera_to_pixels(pose, camera_points), camera_points[..., 2]


def clip_segment(pose: CameraPose, start: np.ndarray, end: np.ndarray) -> np.ndarray | None:
    """A world segment (3,), (3,) -> its (2, 2) pixel end points after near-plane clipping, or None."""
    a, b = to_camera(pose, start), to_camera(pose, end)
    if a[2] < NEAR_PLANE and b[2] < NEAR_PLANE:
        return None
    if a[2] < NEAR_PLANE or b[2] < NEAR_PLANE:
        t = (NEAR_PLANE - a[2]) / (b[2] - a[2])
        crossing = a + t * (b - a)
        a, b = (crossing, b) if a[2] < NEAR_PLANE else (a, crossing)
    return camera_to_pixels(pose, np.stack((a, b)))


def floor_grid(
    scene: Scene, spacing: float = 0.5, margin: float = 1.0
) -> list[tuple[np.ndarray, np.ndarray]]:
    """World segments of a square grid on the floor covering the joints' extent plus a margin."""
    x_min, x_max, z_min, z_max = scene.extent
    xs = np.arange(
        math.floor((x_min - margin) / spacing), math.ceil((x_max + margin) / spacing) + 1
    )
    zs = np.arange(
        math.floor((z_min - margin) / spacing), math.ceil((z_max + margin) / spacing) + 1
    )
    xs, zs = xs * spacing, zs * spacing
    y = scene.floor
    lines = [(np.array([x, y, zs[0]]), np.array([x, y, zs[-1]])) for x in xs]
    lines += [(np.array([xs[0], y, z]), np.array([xs[-1], y, z])) for z in zs]
    return lines
