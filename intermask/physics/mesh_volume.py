"""Intersection Volume of two body meshes (ARFlow section 4.1: voxelised intersection of the two
bodies' meshes), beside the capsule proxy of :mod:`intermask.physics.volume`.

Voxel centres sit on the same global lattice as the capsule measure, (k + 1/2) pitch on every
axis. A centre is inside a mesh when the mesh's winding number around it is non-zero, counted
along the vertical line through it: every triangle the line crosses below the centre adds +1 if
the line enters through it (its normal points down) and -1 if it leaves. The non-zero rule makes
a body that passes through itself (a hand in the torso, SMPL-X's eyeballs in the head) count once,
as a union, where a parity count would cancel it.

Per frame, only the overlap of the two meshes' bounding boxes can hold shared voxels; for every
lattice column (x, z) in it, the crossings of both meshes are found by testing each triangle
against the columns its footprint covers (all triangles below the top of the box count: crossings
below a centre decide its winding), sorted along y, and the stretches where both winding numbers
are non-zero are counted in lattice centres: no per-voxel test at all.

A line through a shared edge or vertex must be counted by exactly one of the triangles there, or
a whole column flips. Edge functions are computed once per edge in a canonical direction (lower
vertex index first), so the two triangles of an edge read the same number, and a line exactly on
an edge goes to the triangle on a fixed side of it (a top-left rule), as rasterisers do.
"""

from __future__ import annotations

import torch

from intermask.physics.capsules import check_finite
from intermask.physics.volume import DEFAULT_PITCH, _check_mask

DEFAULT_MESH_CHUNK = 1 << 21  # (triangle, column) candidates per chunk: ~0.3 GB of temporaries


def _check_meshes(vertices: torch.Tensor, faces: torch.Tensor, name: str) -> None:
    if vertices.ndim < 3 or vertices.shape[-1] != 3:
        raise ValueError(f"{name}: vertices must be (..., V, 3), got {tuple(vertices.shape)}")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.numel() == 0:
        raise ValueError(f"{name}: faces must be (F, 3) vertex indices, got {tuple(faces.shape)}")
    if int(faces.min()) < 0 or int(faces.max()) >= vertices.shape[-2]:
        raise ValueError(f"{name}: faces index vertices outside [0, {vertices.shape[-2]})")
    check_finite(vertices, f"{name}: vertices")


def _edge_tables(faces: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Per face and corner k the edge from corner k+1 to k+2 (opposite corner k) in canonical
    order: start (F, 3), end (F, 3) vertex indices and the sign (+1 / -1) of its direction in the
    face."""
    u, v = faces[:, [1, 2, 0]], faces[:, [2, 0, 1]]
    forward = u < v
    return torch.where(forward, u, v), torch.where(forward, v, u), torch.where(forward, 1.0, -1.0)


def _lattice(
    low: torch.Tensor, high: torch.Tensor, pitch: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """First and last integer k with centre (k + 1/2) pitch inside [low, high]."""
    return torch.ceil(low / pitch - 0.5).long(), torch.floor(high / pitch - 0.5).long()


def _crossings(
    vertices: torch.Tensor,
    faces: torch.Tensor,
    edges: tuple[torch.Tensor, torch.Tensor, torch.Tensor],
    box: tuple[torch.Tensor, torch.Tensor],
    pitch: float,
    chunk: int,
) -> tuple[torch.Tensor, ...]:
    """Where the lattice columns of each frame's box cross one mesh.

    vertices (f, V, 3) float64; box low, high (f, 3). Returns frame, column x index, column z
    index, height y and winding step (+1 entering, -1 leaving), each (C,)."""
    low, high = box
    corners = vertices[:, faces]  # (f, F, 3 corners, 3)
    x, y, z = corners.unbind(-1)
    first_x, last_x = _lattice(x.amin(-1), x.amax(-1), pitch)
    first_z, last_z = _lattice(z.amin(-1), z.amax(-1), pitch)
    box_first, box_last = _lattice(low, high, pitch)
    first_x = torch.maximum(first_x, box_first[:, None, 0])
    last_x = torch.minimum(last_x, box_last[:, None, 0])
    first_z = torch.maximum(first_z, box_first[:, None, 2])
    last_z = torch.minimum(last_z, box_last[:, None, 2])
    count_x, count_z = (last_x - first_x + 1).clamp_min(0), (last_z - first_z + 1).clamp_min(0)
    # the line runs upwards from below: a triangle wholly above the box changes nothing inside it
    below_top = y.amin(-1) < high[:, None, 1]
    sizes = torch.where(below_top, count_x * count_z, 0)
    frame, face = torch.nonzero(sizes, as_tuple=True)
    # signed area of the face's (x, z) footprint: the side its normal points to along y
    area = (x[frame, face, 1] - x[frame, face, 0]) * (z[frame, face, 2] - z[frame, face, 0]) - (
        z[frame, face, 1] - z[frame, face, 0]
    ) * (x[frame, face, 2] - x[frame, face, 0])
    keep = area != 0  # a vertical face: the line only grazes it, its neighbours count
    frame, face, area = frame[keep], face[keep], area[keep]
    found: list[tuple[torch.Tensor, ...]] = []
    sizes = sizes[frame, face]
    ends = sizes.cumsum(0)
    pieces = torch.div(ends - 1, chunk, rounding_mode="floor")
    start, end, sign = edges
    for piece in torch.unique(pieces).tolist():
        rows = torch.nonzero(pieces == piece).squeeze(-1)
        pair = torch.repeat_interleave(rows, sizes[rows])
        offset = torch.repeat_interleave(sizes[rows].cumsum(0) - sizes[rows], sizes[rows])
        local = torch.arange(pair.shape[0], device=pair.device) - offset
        f, t = frame[pair], face[pair]
        nz = count_z[f, t]
        column_x = first_x[f, t] + torch.div(local, nz, rounding_mode="floor")
        column_z = first_z[f, t] + local % nz
        px, pz = (column_x + 0.5) * pitch, (column_z + 0.5) * pitch
        orient = torch.sign(area[pair])
        weights, inside = [], torch.ones_like(px, dtype=torch.bool)
        for corner in range(3):
            u = vertices[f, start[t, corner]]  # (n, 3)
            v = vertices[f, end[t, corner]]
            dx, dz = v[:, 0] - u[:, 0], v[:, 2] - u[:, 2]
            value = dx * (pz - u[:, 2]) - dz * (px - u[:, 0])  # canonical edge function
            facing = orient * sign[t, corner]
            oriented = facing * value
            top_left = (facing * dx > 0) | ((dx == 0) & (facing * dz > 0))
            inside &= (oriented > 0) | ((oriented == 0) & top_left)
            weights.append(oriented)
        hit = torch.nonzero(inside).squeeze(-1)
        w = torch.stack([k[hit] for k in weights], -1)  # (h, 3) barycentric weights, unnormalised
        heights = (w * y[f[hit], t[hit]]).sum(-1) / w.sum(-1)
        found.append((f[hit], column_x[hit], column_z[hit], heights, orient[hit]))
    if not found:
        empty = vertices.new_zeros(0)
        index = empty.long()
        return index, index, index, empty, empty
    return tuple(torch.cat(parts) for parts in zip(*found, strict=True))


def _segment_cumsum(values: torch.Tensor, group: torch.Tensor) -> torch.Tensor:
    """Running sums of values (n,) restarted where the sorted group ids (n,) change."""
    total = values.cumsum(0)
    starts = torch.ones_like(group, dtype=torch.bool)
    starts[1:] = group[1:] != group[:-1]
    before = torch.where(starts, total - values, torch.zeros_like(total))
    index = starts.long().cumsum(0) - 1
    return total - before[starts][index]


def mesh_shared_voxel_counts(
    vertices_a: torch.Tensor,
    faces_a: torch.Tensor,
    vertices_b: torch.Tensor,
    faces_b: torch.Tensor,
    *,
    pitch: float = DEFAULT_PITCH,
    chunk: int = DEFAULT_MESH_CHUNK,
) -> torch.Tensor:
    """Lattice voxel centres inside both meshes, per frame: vertices (F, V, 3) in metres, faces
    (F', 3) each -> (F,) int64. Computed in float64."""
    if not pitch > 0:
        raise ValueError(f"mesh intersection volume: pitch must be > 0 metres, got {pitch}")
    a, b = vertices_a.double(), vertices_b.double()
    frames = a.shape[0]
    low = torch.maximum(a.amin(1), b.amin(1))
    high = torch.minimum(a.amax(1), b.amax(1))
    counts = torch.zeros(frames, dtype=torch.long, device=a.device)
    near = torch.nonzero((low < high).all(-1)).squeeze(-1)
    if near.numel() == 0:
        return counts
    box = (low[near], high[near])
    events = [
        _crossings(v[near], f, _edge_tables(f), box, pitch, chunk)
        for v, f in ((a, faces_a), (b, faces_b))
    ]
    frame = torch.cat([e[0] for e in events])
    if frame.numel() == 0:
        return counts
    column_x, column_z = torch.cat([e[1] for e in events]), torch.cat([e[2] for e in events])
    height, step = torch.cat([e[3] for e in events]), torch.cat([e[4] for e in events])
    body = torch.cat([torch.zeros_like(events[0][0]), torch.ones_like(events[1][0])])
    span_x = column_x - column_x.min()
    span_z = column_z - column_z.min()
    group = (frame * (int(span_x.max()) + 1) + span_x) * (int(span_z.max()) + 1) + span_z
    order = torch.sort(height, stable=True).indices
    order = order[torch.sort(group[order], stable=True).indices]
    group, height, step, body, frame = (
        group[order],
        height[order],
        step[order],
        body[order],
        frame[order],
    )
    winding_a = _segment_cumsum(torch.where(body == 0, step, 0.0), group)
    winding_b = _segment_cumsum(torch.where(body == 1, step, 0.0), group)
    inside = (winding_a.round() != 0) & (winding_b.round() != 0)
    rows = torch.nonzero(inside).squeeze(-1)
    # a stretch ends at the next crossing of its column, or at the top of the box (crossings
    # above it were not collected)
    top = box[1][frame[rows], 1]
    following = (rows + 1).clamp_max(len(group) - 1)
    same = (rows + 1 < len(group)) & (group[following] == group[rows])
    end = torch.where(same, torch.minimum(height[following], top), top)
    first, last = _lattice(height[rows], end, pitch)
    counts[near] += torch.zeros_like(near).index_add_(
        0, frame[rows], (last - first + 1).clamp_min(0)
    )
    return counts


def mesh_intersection_volume(
    vertices_a: torch.Tensor,
    vertices_b: torch.Tensor,
    faces_a: torch.Tensor,
    faces_b: torch.Tensor | None = None,
    *,
    pitch: float = DEFAULT_PITCH,
    frame_mask: torch.Tensor | None = None,
    chunk: int = DEFAULT_MESH_CHUNK,
) -> torch.Tensor:
    """Per-frame intersection volume in cm^3 of two closed meshes.

    vertices_a (..., Va, 3), vertices_b (..., Vb, 3) in metres, any up axis would do but the
    lattice columns run along the second axis (Y up here); faces_a (Fa, 3), faces_b (Fb, 3)
    (faces_a when None), counter-clockwise seen from outside. frame_mask (...) bool: False
    frames are skipped and get 0. Returns (...) float32."""
    faces_b = faces_a if faces_b is None else faces_b
    _check_meshes(vertices_a, faces_a, "mesh_intersection_volume: body a")
    _check_meshes(vertices_b, faces_b, "mesh_intersection_volume: body b")
    if vertices_a.shape[:-2] != vertices_b.shape[:-2]:
        raise ValueError(
            f"mesh_intersection_volume: the two bodies need the same leading shape, got "
            f"{tuple(vertices_a.shape)} and {tuple(vertices_b.shape)}"
        )
    leading = vertices_a.shape[:-2]
    _check_mask(frame_mask, leading, "mesh_intersection_volume")
    flat_a = vertices_a.detach().reshape(-1, *vertices_a.shape[-2:])
    flat_b = vertices_b.detach().reshape(-1, *vertices_b.shape[-2:])
    rows = torch.arange(flat_a.shape[0], device=flat_a.device)
    if frame_mask is not None:
        rows = torch.nonzero(frame_mask.reshape(-1).to(flat_a.device)).squeeze(-1)
    voxels = torch.zeros(flat_a.shape[0], dtype=torch.long, device=flat_a.device)
    with torch.no_grad():
        voxels[rows] = mesh_shared_voxel_counts(
            flat_a[rows],
            faces_a.to(flat_a.device),
            flat_b[rows],
            faces_b.to(flat_a.device),
            pitch=pitch,
            chunk=chunk,
        )
    return (voxels.to(torch.float32) * (pitch * 100.0) ** 3).reshape(leading)
