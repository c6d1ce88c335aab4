"""Test helpers: posed bodies built from the rest skeleton and numpy reference geometry."""

from __future__ import annotations

import math

import numpy as np
import torch

from intermask.motion.rotations import rotation_about_axis
from intermask.motion.skeleton import rest_pose_positions


def facing_pair(gap: float, *, frames: int = 1, dtype=torch.float64) -> tuple[torch.Tensor, ...]:
    """Two rest-pose bodies (frames, 22, 3), Y-up, facing each other with pelvises `gap` apart.

    Person A faces +Z at the origin; person B is turned 180 degrees about Y at z = gap.
    """
    rest = rest_pose_positions().to(dtype) + torch.tensor([0.0, 0.95, 0.0], dtype=dtype)
    turn = rotation_about_axis(torch.tensor(math.pi, dtype=dtype), "y")
    other = rest @ turn.T + torch.tensor([0.0, 0.0, gap], dtype=dtype)
    return rest.expand(frames, 22, 3).clone(), other.expand(frames, 22, 3).clone()


def point_segment_distance(
    points: np.ndarray, a: np.ndarray, b: np.ndarray, *, samples: int = 4001
) -> np.ndarray:
    """(N, 3) points, (K, 3) segment ends -> (N, K) distances by dense sampling of each segment."""
    s = np.linspace(0.0, 1.0, samples)
    samples = a[:, None, :] + s[None, :, None] * (b - a)[:, None, :]  # (K, S, 3)
    diff = points[:, None, None, :] - samples[None]  # (N, K, S, 3)
    return np.sqrt((diff**2).sum(-1)).min(-1)


def dense_shared_voxels(
    a_ends: tuple[np.ndarray, np.ndarray, np.ndarray],
    b_ends: tuple[np.ndarray, np.ndarray, np.ndarray],
    pitch: float,
) -> int:
    """Voxel centres (k + 1/2) pitch inside both capsule bodies, found by testing every centre
    in the overlap of the two bodies' boxes. *_ends: a (K, 3), b (K, 3), radius (K,)."""

    def box(ends):
        a, b, r = ends
        return (np.minimum(a, b) - r[:, None]).min(0), (np.maximum(a, b) + r[:, None]).max(0)

    (low_a, high_a), (low_b, high_b) = box(a_ends), box(b_ends)
    low, high = np.maximum(low_a, low_b), np.minimum(high_a, high_b)
    if np.any(low >= high):
        return 0
    axes = [
        (np.arange(np.ceil(lo / pitch - 0.5), np.floor(hi / pitch - 0.5) + 1) + 0.5) * pitch
        for lo, hi in zip(low, high, strict=True)
    ]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)

    def inside(ends):
        a, b, r = ends
        ba = b - a
        pa = centres[:, None, :] - a[None]
        t = np.clip((pa * ba).sum(-1) / np.maximum((ba * ba).sum(-1), 1e-12), 0.0, 1.0)
        distance = np.linalg.norm(pa - t[..., None] * ba, axis=-1)
        return (distance < r).any(-1)

    return int((inside(a_ends) & inside(b_ends)).sum())


def lens_volume(r1: float, r2: float, d: float) -> float:
    """Closed-form volume of the intersection of two balls (docs/penetration.md), metres^3."""
    return (
        math.pi * (r1 + r2 - d) ** 2 * (d * d + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d)
    )
