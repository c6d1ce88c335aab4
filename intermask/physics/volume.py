"""Intersection Volume and Intersection Frequency of two capsule bodies (ARFlow section 4.1).

IV of a frame = pitch^3 x the number of voxel centres inside both bodies (signed distance < 0 to
each), in cm^3. Voxel centres sit on one global lattice, (k + 1/2) pitch for integer k, so the
count does not depend on where a bounding box starts, and swapping or negating axes (Z-up <-> Y-up)
maps the lattice onto itself: the same motion gives the same IV in either frame.

Only the overlap of the two bodies' bounding boxes can hold shared voxels; the search is narrowed
further without changing the count. A voxel inside both bodies lies inside some capsule i of body A
and some capsule j of body B, so it lies in the box overlap of a pair (i, j) whose segments are
closer than r_i + r_j. Each such pair's box overlap is voxelized and tested against its two
capsules only; a voxel found by several pairs counts once (distinct lattice keys per frame). All
pairs of all frames form one ragged voxel list, processed in chunks of whole frames and about
`chunk_voxels` voxels: memory stays bounded and there is no loop over frames.
"""

from __future__ import annotations

import torch
from einops import rearrange

from intermask.physics.capsules import (
    BodyProxy,
    Capsules,
    body_capsules,
    check_finite,
    segment_distances,
)

# docs/penetration.md: 1-2 cm (ARFlow voxelizes meshes, pitch unstated)
DEFAULT_PITCH = 0.01  # metres
DEFAULT_TOLERANCE = 0.0  # cm^3; docs/penetration.md: a frame penetrates when any voxel is shared
DEFAULT_CHUNK_VOXELS = 1 << 20  # box voxels per chunk: ~0.1 GB of temporaries
_PAIR_FRAMES = 512  # frames per chunk of the (F, K, K) pair test
_BOX_SLACK = 1e-6  # metres: keeps voxels on a box face in despite rounding (never double-counts)


def _check_pair(joints_a: torch.Tensor, joints_b: torch.Tensor, name: str) -> None:
    if joints_a.shape != joints_b.shape or joints_a.ndim < 2 or joints_a.shape[-2:] != (22, 3):
        raise ValueError(
            f"{name}: joints_a and joints_b must both be (..., 22, 3) of one shape, got "
            f"{tuple(joints_a.shape)} and {tuple(joints_b.shape)}"
        )
    check_finite(joints_a, f"{name}: joints_a")
    check_finite(joints_b, f"{name}: joints_b")


def _check_mask(frame_mask: torch.Tensor | None, shape: torch.Size, name: str) -> None:
    if frame_mask is None:
        return
    if frame_mask.dtype != torch.bool or frame_mask.shape != shape:
        raise ValueError(
            f"{name}: frame_mask must be a bool tensor of shape {tuple(shape)}, got "
            f"{frame_mask.dtype} {tuple(frame_mask.shape)}"
        )


def _boxes(capsules: Capsules) -> tuple[torch.Tensor, torch.Tensor]:
    """Axis-aligned boxes (F, K, 3) low and high of each capsule."""
    radius = capsules.radius.expand(capsules.a.shape[:-1])[..., None]
    low = torch.minimum(capsules.a, capsules.b) - radius
    high = torch.maximum(capsules.a, capsules.b) + radius
    return low, high


def _clip_to_box(
    a: torch.Tensor, b: torch.Tensor, radius: torch.Tensor, low: torch.Tensor, high: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Box (P, 3) low, high of the part of capsule a-b (P, 3), radius (P,) inside box [low, high].

    The segment is clipped to the box grown by the radius (slab method) and the clipped capsule's
    box is intersected with [low, high]: a tighter box around a capsule's share of another box.
    """
    d = b - a
    grow_low, grow_high = low - radius[:, None], high + radius[:, None]
    flat = d.abs() < 1e-12  # parallel to a slab: all of it or none of it is inside
    safe = torch.where(flat, torch.ones_like(d), d)
    t_low, t_high = (grow_low - a) / safe, (grow_high - a) / safe
    inside = (a >= grow_low) & (a <= grow_high)
    enter = torch.where(
        flat, torch.where(inside, -torch.inf, torch.inf), torch.minimum(t_low, t_high)
    )
    leave = torch.where(
        flat, torch.where(inside, torch.inf, -torch.inf), torch.maximum(t_low, t_high)
    )
    enter = enter.amax(-1).clamp(0.0, 1.0)[:, None]
    leave = leave.amin(-1).clamp(0.0, 1.0)[:, None]
    start, end = a + enter * d, a + leave * d
    tight_low = torch.maximum(torch.minimum(start, end) - radius[:, None], low)
    tight_high = torch.minimum(torch.maximum(start, end) + radius[:, None], high)
    empty = (enter > leave).expand_as(tight_low)  # the capsule misses the box
    return tight_low, torch.where(empty, tight_low - 1.0, tight_high)


def _touching_pairs(caps_a: Capsules, caps_b: Capsules) -> tuple[torch.Tensor, ...]:
    """Pairs (frame, i, j) whose capsules intersect, with the overlap box of each pair.

    caps_*: a, b (F, K, 3), radius (F, K). Returns frame, i, j (P,) and low, high (P, 3).
    """
    low_a, high_a = _boxes(caps_a)
    low_b, high_b = _boxes(caps_b)
    # Whole-body boxes first: frames whose bodies are apart skip the (K, K) pair test.
    near = (
        (
            torch.maximum(low_a.amin(1), low_b.amin(1))
            < torch.minimum(high_a.amax(1), high_b.amax(1))
        )
        .all(-1)
        .nonzero()
        .squeeze(-1)
    )
    found: list[tuple[torch.Tensor, ...]] = []
    for rows in near.split(_PAIR_FRAMES):  # bounds the (f, K, K, 3) boxes; not a per-frame loop
        low = torch.maximum(low_a[rows, :, None], low_b[rows, None, :])  # (f, K, K, 3)
        high = torch.minimum(high_a[rows, :, None], high_b[rows, None, :])
        row, i, j = torch.nonzero((low < high).all(-1), as_tuple=True)  # the boxes overlap
        frame = rows[row]
        gap = segment_distances(
            caps_a.a[frame, i], caps_a.b[frame, i], caps_b.a[frame, j], caps_b.b[frame, j]
        )
        keep = gap < caps_a.radius[frame, i] + caps_b.radius[frame, j]  # the capsules intersect
        row, i, j, frame = row[keep], i[keep], j[keep], frame[keep]
        box = (low[row, i, j], high[row, i, j])
        box = _clip_to_box(caps_a.a[frame, i], caps_a.b[frame, i], caps_a.radius[frame, i], *box)
        box = _clip_to_box(caps_b.a[frame, j], caps_b.b[frame, j], caps_b.radius[frame, j], *box)
        found.append((frame, i, j, *box))
    if not found:
        empty = low_a.new_zeros(0, 3)
        index = near.new_zeros(0)
        return index, index, index, empty, empty
    frame, i, j, low, high = (torch.cat(parts) for parts in zip(*found, strict=True))
    return frame, i, j, low, high


def _lattice_range(
    low: torch.Tensor, high: torch.Tensor, pitch: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Integer lattice indices k with centre (k + 1/2) pitch inside [low, high]: first k, count."""
    first = torch.ceil((low - _BOX_SLACK) / pitch - 0.5).long()
    last = torch.floor((high + _BOX_SLACK) / pitch - 0.5).long()
    return first, (last - first + 1).clamp_min(0)


def _capsule_rows(capsules: Capsules, first: torch.Tensor, pitch: float) -> torch.Tensor:
    """Per-pair constants of one capsule, (8, P): the offset from the capsule start to the
    centre of the box's first voxel (3), the axis b - a (3), 1 / |b - a|^2 and radius^2."""
    axis = capsules.b - capsules.a  # (P, 3)
    offset = (first.to(axis.dtype) + 0.5) * pitch - capsules.a
    inverse = 1.0 / (axis * axis).sum(-1).clamp_min(1e-12)  # a sphere: t = 0 below
    return torch.cat((offset.T, axis.T, inverse[None], capsules.radius[None] ** 2)).contiguous()


def _inside(step: tuple[torch.Tensor, ...], rows: torch.Tensor, pair: torch.Tensor) -> torch.Tensor:
    """Box voxels at `step` (3 x (V,), metres from the box's first centre) of pairs `pair` (V,)
    -> (V,) bool: strictly inside the pair's capsule given by `rows` (8, P).

    One contiguous 1-D op at a time (1-D gathers are far faster than indexing (3, P) columns);
    squared distances avoid the sqrt.
    """
    c = [row.index_select(0, pair) for row in rows]
    x, y, z = step[0] + c[0], step[1] + c[1], step[2] + c[2]  # centre - capsule start
    t = (x * c[3]).addcmul_(y, c[4]).addcmul_(z, c[5]).mul_(c[6]).clamp_(0.0, 1.0)
    x.addcmul_(t, c[3], value=-1.0)
    y.addcmul_(t, c[4], value=-1.0)
    z.addcmul_(t, c[5], value=-1.0)
    return (x * x).addcmul_(y, y).addcmul_(z, z) < c[7]


def _count_unique(frame: torch.Tensor, lattice: torch.Tensor, frames: int) -> torch.Tensor:
    """Distinct (frame, lattice index) rows per frame: (S,), (S, 3) -> (frames,) int64."""
    counts = torch.zeros(frames, dtype=torch.long, device=frame.device)
    if frame.numel() == 0:
        return counts
    shifted = lattice - lattice.amin(0)
    span = (shifted.amax(0) + 1).tolist()
    if frames * span[0] * span[1] * span[2] < 2**62:  # one int64 key per voxel: a fast 1-D sort
        key = ((frame * span[0] + shifted[:, 0]) * span[1] + shifted[:, 1]) * span[2]
        unique = torch.unique(key + shifted[:, 2])
        owner = torch.div(unique, span[0] * span[1] * span[2], rounding_mode="floor")
    else:
        owner = torch.unique(torch.cat((frame[:, None], lattice), dim=1), dim=0)[:, 0]
    return counts.index_add_(0, owner, torch.ones_like(owner))


def shared_voxel_counts(
    caps_a: Capsules,
    caps_b: Capsules,
    *,
    pitch: float = DEFAULT_PITCH,
    chunk_voxels: int = DEFAULT_CHUNK_VOXELS,
) -> torch.Tensor:
    """Number of lattice voxel centres inside both bodies, per frame: (F,) int64.

    caps_*: a, b (F, K, 3) and radius (K,) or (F, K) in metres; the two bodies may have
    different K. Voxel centres are (k + 1/2) pitch for integer k on every axis.
    """
    if not pitch > 0:
        raise ValueError(f"intersection volume: pitch must be > 0 metres, got {pitch}")
    if chunk_voxels < 1:
        raise ValueError(f"intersection volume: chunk_voxels must be >= 1, got {chunk_voxels}")
    caps_a, caps_b = (c._replace(radius=c.radius.expand(c.a.shape[:-1])) for c in (caps_a, caps_b))
    frames = caps_a.a.shape[0]
    voxels = torch.zeros(frames, dtype=torch.long, device=caps_a.a.device)
    frame, i, j, low, high = _touching_pairs(caps_a, caps_b)
    first, counts = _lattice_range(low, high, pitch)
    sizes = counts.prod(-1)  # (P,) voxels in each pair's box
    ny, nz = counts[:, 1].contiguous(), counts[:, 2].contiguous()
    rows_i = _capsule_rows(Capsules(*(x[frame, i] for x in caps_a)), first, pitch)
    rows_j = _capsule_rows(Capsules(*(x[frame, j] for x in caps_b)), first, pitch)
    # Chunks hold whole frames (a voxel shared by several pairs must meet its duplicates in one
    # chunk) and about chunk_voxels box voxels; a single larger frame is a chunk of its own.
    per_frame = torch.zeros(frames, dtype=torch.long, device=voxels.device)
    per_frame.index_add_(0, frame, sizes)
    chunk_of_frame = torch.div(per_frame.cumsum(0) - per_frame, chunk_voxels, rounding_mode="floor")
    chunk_of_pair = chunk_of_frame[frame]
    for chunk in torch.unique(chunk_of_pair).tolist():
        pairs = torch.nonzero(chunk_of_pair == chunk).squeeze(-1)
        chunk_sizes = sizes[pairs]
        pair = torch.repeat_interleave(pairs, chunk_sizes)  # (V,) the pair of each box voxel
        starts = torch.repeat_interleave(chunk_sizes.cumsum(0) - chunk_sizes, chunk_sizes)
        local = torch.arange(pair.shape[0], device=pair.device) - starts  # index in its box
        pair_nz = nz.index_select(0, pair)
        iz, rest = local % pair_nz, local.div_(pair_nz, rounding_mode="floor")
        pair_ny = ny.index_select(0, pair)
        iy, ix = rest % pair_ny, rest.div_(pair_ny, rounding_mode="floor")
        index = (ix, iy, iz)
        step = tuple(k.to(rows_i.dtype).mul_(pitch) for k in index)
        inside = _inside(step, rows_i, pair) & _inside(step, rows_j, pair)
        hit = torch.nonzero(inside).squeeze(-1)
        pair = pair[hit]
        lattice = first[pair] + torch.stack([k[hit] for k in index], dim=-1)  # (S, 3)
        voxels += _count_unique(frame[pair], lattice, frames)
    return voxels


def intersection_volume(
    joints_a: torch.Tensor,
    joints_b: torch.Tensor,
    *,
    pitch: float = DEFAULT_PITCH,
    proxy: BodyProxy | None = None,
    frame_mask: torch.Tensor | None = None,
    chunk_voxels: int = DEFAULT_CHUNK_VOXELS,
) -> torch.Tensor:
    """Per-frame intersection volume in cm^3 of two capsule bodies.

    joints_a, joints_b: (..., 22, 3) in metres, any up axis (e.g. (B, T, 22, 3)).
    frame_mask: (...) bool; False frames are skipped and get 0. Returns (...) float32.
    No gradient: it counts voxels (penetration_loss is the differentiable measure).
    """
    _check_pair(joints_a, joints_b, "intersection_volume")
    leading = joints_a.shape[:-2]
    _check_mask(frame_mask, leading, "intersection_volume")
    dtype = torch.promote_types(joints_a.dtype, torch.float32)
    flat_a = rearrange(joints_a.detach().to(dtype), "... j c -> (...) j c")
    flat_b = rearrange(joints_b.detach().to(dtype), "... j c -> (...) j c")
    voxels = torch.zeros(flat_a.shape[0], dtype=torch.long, device=flat_a.device)
    rows = torch.arange(flat_a.shape[0], device=flat_a.device)
    if frame_mask is not None:
        rows = torch.nonzero(frame_mask.reshape(-1).to(flat_a.device)).squeeze(-1)
    with torch.no_grad():
        counts = shared_voxel_counts(
            body_capsules(flat_a[rows], proxy),
            body_capsules(flat_b[rows], proxy),
            pitch=pitch,
            chunk_voxels=chunk_voxels,
        )
    voxels[rows] = counts
    volume = voxels.to(torch.float32) * (pitch * 100.0) ** 3  # cm^3
    return volume.reshape(leading)


def penetrating_frames(
    volume: torch.Tensor, *, tolerance: float = DEFAULT_TOLERANCE
) -> torch.Tensor:
    """(...) per-frame IV in cm^3 -> (...) bool, True where IV exceeds `tolerance` cm^3."""
    if tolerance < 0:
        raise ValueError(f"penetrating_frames: tolerance must be >= 0 cm^3, got {tolerance}")
    return volume > tolerance


def intersection_frequency(
    volume: torch.Tensor,
    *,
    tolerance: float = DEFAULT_TOLERANCE,
    frame_mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """Share in [0, 1] of valid frames whose IV (cm^3, (...)) exceeds `tolerance` cm^3."""
    _check_mask(frame_mask, volume.shape, "intersection_frequency")
    hits = penetrating_frames(volume, tolerance=tolerance)
    valid = torch.ones_like(hits) if frame_mask is None else frame_mask
    if not bool(valid.any()):
        raise ValueError("intersection_frequency: no valid frames (frame_mask is all False)")
    return (hits & valid).sum().double().div(valid.sum()).float()
