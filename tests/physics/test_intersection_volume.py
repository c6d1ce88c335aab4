"""Intersection Volume / Frequency: closed-form lens, convergence, a dense numpy reference."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch
from physics_builders import dense_shared_voxels, facing_pair, lens_volume

from intermask.motion.interhuman import yup_to_zup
from intermask.physics import (
    Capsules,
    body_capsules,
    intersection_frequency,
    intersection_volume,
    penetrating_frames,
    shared_voxel_counts,
)


def _spheres(centres: torch.Tensor, radius: float) -> Capsules:
    """(F, 3) centres -> one zero-length capsule per frame, (F, 1, 3)."""
    return Capsules(centres[:, None], centres[:, None].clone(), torch.tensor([radius]))


@functools.cache
def _lens_estimates(pitch: float, placements: int = 4) -> tuple[np.ndarray, float]:
    """Relative errors of the voxel estimate for two balls at random sub-voxel placements."""
    r1, r2, d = 0.10, 0.08, 0.12
    rng = np.random.default_rng(0)
    origin = torch.tensor(rng.uniform(-1.0, 1.0, size=(placements, 3)))
    direction = torch.nn.functional.normalize(
        torch.tensor(rng.normal(size=(placements, 3))), dim=-1
    )
    counts = shared_voxel_counts(
        _spheres(origin, r1)._replace(radius=torch.tensor([r1], dtype=torch.float64)),
        _spheres(origin + d * direction, r2)._replace(
            radius=torch.tensor([r2], dtype=torch.float64)
        ),
        pitch=pitch,
    )
    exact = lens_volume(r1, r2, d)
    return (counts.double().numpy() * pitch**3 - exact) / exact, r1 + r2 - d


@pytest.mark.parametrize("pitch", [0.02, 0.01, 0.005])
def test_two_spheres_match_the_lens_volume(pitch):
    errors, thickness = _lens_estimates(pitch)
    # Voxel miscounts live in a shell about one pitch thick around the lens.
    assert np.abs(errors).max() < 0.25 * pitch / thickness


def test_estimate_converges_as_the_pitch_shrinks():
    mean_error = [np.abs(_lens_estimates(pitch)[0]).mean() for pitch in (0.02, 0.01, 0.005)]
    assert mean_error[-1] < 0.01
    assert all(coarse > fine for coarse, fine in zip(mean_error, mean_error[1:], strict=False))


def test_disjoint_bodies_give_exactly_zero():
    a, b = facing_pair(3.0, frames=4)
    assert intersection_volume(a, b, pitch=0.01).tolist() == [0.0] * 4
    gap = 0.005  # two balls 5 mm apart: their boxes overlap, the balls do not
    near = torch.tensor([[0.0, 0.0, 0.0]], dtype=torch.float64)
    far = near + torch.tensor([0.2 + gap, 0.0, 0.0], dtype=torch.float64)
    radius = torch.tensor([0.1], dtype=torch.float64)
    caps = (
        Capsules(near[:, None], near[:, None], radius),
        Capsules(far[:, None], far[:, None], radius),
    )
    assert shared_voxel_counts(*caps, pitch=0.001).item() == 0


def test_bodies_match_a_dense_voxelization_of_the_box_overlap():
    a, b = facing_pair(0.2, frames=2)
    turn = torch.tensor([0.0, 0.7], dtype=torch.float64)
    b = b + turn[:, None, None] * torch.tensor([0.05, 0.0, 0.0], dtype=torch.float64)  # drift
    pitch = 0.02
    got = intersection_volume(a, b, pitch=pitch)
    expected = []
    for frame in range(2):
        ends = [tuple(x.numpy() for x in body_capsules(body[frame])) for body in (a, b)]
        ends = [(x, y, np.broadcast_to(r, x.shape[:1])) for x, y, r in ends]
        expected.append(dense_shared_voxels(ends[0], ends[1], pitch) * (pitch * 100) ** 3)
    assert min(expected) > 0
    np.testing.assert_allclose(got.numpy(), expected, rtol=1e-6)


def test_same_volume_for_y_up_and_z_up_and_any_chunking():
    a, b = facing_pair(0.2, frames=2)
    yup = intersection_volume(a, b, pitch=0.02)
    assert yup.min() > 0 and yup.dtype == torch.float32
    assert torch.equal(intersection_volume(yup_to_zup(a), yup_to_zup(b), pitch=0.02), yup)
    assert torch.equal(intersection_volume(a, b, pitch=0.02, chunk_voxels=50), yup)


def test_batch_shapes_and_frame_mask():
    a, b = facing_pair(0.2, frames=6)
    a, b = a.reshape(2, 3, 22, 3), b.reshape(2, 3, 22, 3)
    b = b.clone()
    b[1, 2] += 5.0  # one frame far apart
    full = intersection_volume(a, b, pitch=0.02)
    assert full.shape == (2, 3) and full[1, 2] == 0 and (full.flatten()[:5] > 0).all()
    mask = torch.tensor([[True, False, True], [False, True, True]])
    masked = intersection_volume(a, b, pitch=0.02, frame_mask=mask)
    assert torch.equal(masked, torch.where(mask, full, torch.zeros_like(full)))


def test_intersection_frequency_counts_frames():
    volume = torch.tensor([[0.0, 0.5, 3.0, 0.0], [12.0, 0.0, 0.0, 1.0]])
    assert intersection_frequency(volume).item() == pytest.approx(4 / 8)
    assert intersection_frequency(volume, tolerance=1.0).item() == pytest.approx(2 / 8)
    mask = torch.tensor([[True, True, True, False], [True, False, False, False]])
    assert intersection_frequency(volume, frame_mask=mask).item() == pytest.approx(3 / 4)
    assert penetrating_frames(volume, tolerance=2.0).sum().item() == 2
    # From bodies: frames 0 and 2 overlap, frame 1 is apart.
    a, b = facing_pair(0.2, frames=3)
    b = b.clone()
    b[1] += torch.tensor([0.0, 0.0, 2.0], dtype=torch.float64)
    assert intersection_frequency(intersection_volume(a, b, pitch=0.02)).item() == pytest.approx(
        2 / 3
    )


def test_errors_name_the_problem():
    a, b = facing_pair(0.2, frames=2)
    with pytest.raises(
        ValueError,
        match=r"must both be \(\.\.\., 22, 3\) of one shape, got \(2, 22, 3\) and \(1, 22, 3\)",
    ):
        intersection_volume(a, b[:1])
    bad = a.clone()
    bad[1, 3, 0] = torch.nan
    with pytest.raises(
        ValueError, match="intersection_volume: joints_a contains 1 NaN or inf values"
    ):
        intersection_volume(bad, b)
    with pytest.raises(ValueError, match="pitch must be > 0 metres, got 0.0"):
        intersection_volume(a, b, pitch=0.0)
    with pytest.raises(
        ValueError,
        match=r"frame_mask must be a bool tensor of shape \(2,\), got torch.int64 \(2,\)",
    ):
        intersection_volume(a, b, frame_mask=torch.ones(2, dtype=torch.long))
    with pytest.raises(ValueError, match="chunk_voxels must be >= 1"):
        intersection_volume(a, b, chunk_voxels=0)
    with pytest.raises(ValueError, match="no valid frames"):
        intersection_frequency(torch.zeros(3), frame_mask=torch.zeros(3, dtype=torch.bool))
    with pytest.raises(ValueError, match="tolerance must be >= 0 cm\\^3, got -1"):
        intersection_frequency(torch.zeros(3), tolerance=-1)
