"""Closed test meshes (outward, counter-clockwise faces) and a brute-force inside test."""

from __future__ import annotations

import math

import numpy as np
import torch


def uv_sphere(
    radius: float, centre=(0.0, 0.0, 0.0), *, rings: int = 48, segments: int = 96
) -> tuple[torch.Tensor, torch.Tensor]:
    """A closed UV sphere: vertices (V, 3) float64, faces (F, 3) int64, outward."""
    vertices = [(0.0, radius, 0.0)]
    for i in range(1, rings):
        polar = math.pi * i / rings
        for j in range(segments):
            azimuth = 2 * math.pi * j / segments
            vertices.append(
                (
                    radius * math.sin(polar) * math.cos(azimuth),
                    radius * math.cos(polar),
                    radius * math.sin(polar) * math.sin(azimuth),
                )
            )
    vertices.append((0.0, -radius, 0.0))
    faces = []
    bottom = len(vertices) - 1

    def ring(i: int, j: int) -> int:
        return 1 + (i - 1) * segments + j % segments

    for j in range(segments):
        faces.append((0, ring(1, j + 1), ring(1, j)))
        faces.append((bottom, ring(rings - 1, j), ring(rings - 1, j + 1)))
    for i in range(1, rings - 1):
        for j in range(segments):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1)
            faces += [(a, b, d), (a, d, c)]
    v = torch.tensor(vertices, dtype=torch.float64) + torch.tensor(centre, dtype=torch.float64)
    return v, torch.tensor(faces, dtype=torch.int64)


def box_mesh(low, high) -> tuple[torch.Tensor, torch.Tensor]:
    """An axis-aligned box: 8 vertices, 12 outward faces."""
    (x0, y0, z0), (x1, y1, z1) = low, high
    v = torch.tensor(
        [(x, y, z) for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)], dtype=torch.float64
    )
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = []
    for a, b, c, d in quads:
        faces += [(a, b, c), (a, c, d)]
    return v, torch.tensor(faces, dtype=torch.int64)


def winding_numbers(points: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Generalised winding number (solid angles, Jacobson et al.) of (N, 3) points: ~1 inside."""
    a, b, c = (vertices[faces[:, k]][None] - points[:, None] for k in range(3))
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    det = np.einsum("nfi,nfi->nf", a, np.cross(b, c))
    dot = (
        la * lb * lc
        + np.einsum("nfi,nfi->nf", a, b) * lc
        + np.einsum("nfi,nfi->nf", b, c) * la
        + np.einsum("nfi,nfi->nf", c, a) * lb
    )
    return (2 * np.arctan2(det, dot)).sum(-1) / (4 * math.pi)
