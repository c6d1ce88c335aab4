"""IntersectionVolume / IntersectionFrequency accumulate the functional IV over valid frames."""

from __future__ import annotations

import math

import pytest
import torch

from intermask.metrics.penetration import IntersectionFrequency, IntersectionVolume
from intermask.motion.rotations import rotation_about_axis
from intermask.motion.skeleton import rest_pose_positions
from intermask.physics import BodyProxy, intersection_volume

PITCH = 0.02


def _batch() -> tuple[torch.Tensor, torch.Tensor]:
    """(3, 4, 22, 3) two persons facing each other at gaps from 0.12 m (deep overlap) to 3 m."""
    rest = rest_pose_positions().double() + torch.tensor([0.0, 0.95, 0.0], dtype=torch.float64)
    turned = rest @ rotation_about_axis(torch.tensor(math.pi, dtype=torch.float64), "y").T
    gaps = torch.tensor([[0.12, 0.2, 3.0, 0.25], [0.3, 0.15, 0.2, 3.0], [3.0, 3.0, 0.18, 0.22]])
    b = turned + gaps.double()[..., None, None] * torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    return rest.expand(3, 4, 22, 3).clone(), b


def test_metrics_match_the_per_frame_volumes_over_valid_frames():
    a, b = _batch()
    mask = torch.ones(3, 4, dtype=torch.bool)
    mask[1, 2:] = False  # padding
    b[1, 2:] += 1.0e3  # garbage in padding must not count
    per_frame = intersection_volume(a, b, pitch=PITCH).numpy()
    valid = mask.numpy()
    iv, freq = IntersectionVolume(pitch=PITCH), IntersectionFrequency(pitch=PITCH, tolerance=60.0)
    for metric in (iv, freq):
        metric.update(a[:2], b[:2], mask[:2])
        metric.update(a[2:], b[2:], mask[2:])
    assert iv.compute().item() == pytest.approx(per_frame[valid].mean(), rel=1e-6)
    assert freq.compute().item() == pytest.approx((per_frame[valid] > 60.0).mean(), rel=1e-6)
    assert 0 < freq.compute().item() < (per_frame[valid] > 0).mean()  # the tolerance matters


def test_states_merge_like_ddp_ranks():
    a, b = _batch()
    whole, first, second = (IntersectionVolume(pitch=PITCH) for _ in range(3))
    whole.update(a, b)
    first.update(a[:1], b[:1])
    second.update(a[1:], b[1:])
    first.merge_state(second)
    assert first.compute().item() == pytest.approx(whole.compute().item(), rel=1e-9)
    assert {name: fn.__name__ for name, fn in whole._reductions.items()} == {
        "total": "dim_zero_sum",
        "frames": "dim_zero_sum",
    }
    assert whole.total.dtype == torch.float64


def test_proxy_and_pitch_are_used():
    a, b = _batch()
    thin = BodyProxy(radii={part: 0.5 * r for part, r in BodyProxy().radii.items()})
    default, slim = IntersectionVolume(pitch=PITCH), IntersectionVolume(pitch=PITCH, proxy=thin)
    default.update(a, b)
    slim.update(a, b)
    assert 0 < slim.compute().item() < default.compute().item()


def test_errors():
    a, b = _batch()
    with pytest.raises(
        ValueError,
        match=r"IntersectionVolume.update: joints must be \(B, T, 22, 3\), got \(4, 22, 3\)",
    ):
        IntersectionVolume().update(a[0], b[0])
    with pytest.raises(ValueError, match="IntersectionFrequency: pitch must be > 0 metres"):
        IntersectionFrequency(pitch=-1.0)
    with pytest.raises(ValueError, match="tolerance must be >= 0 cm\\^3"):
        IntersectionFrequency(tolerance=-1.0)
    with (
        pytest.raises(ValueError, match="compute\\(\\) called before any valid frame"),
        pytest.warns(UserWarning, match="before the ``update``"),
    ):
        IntersectionVolume().compute()
    empty = IntersectionFrequency(pitch=PITCH)
    empty.update(a, b, torch.zeros(3, 4, dtype=torch.bool))
    with pytest.raises(ValueError, match="before any valid frame"):
        empty.compute()


def test_precomputed_volumes_are_counted_and_an_empty_update_is_refused():
    volumes = torch.tensor([0.0, 5.0, 12.0, 0.5])
    volume, frequency = IntersectionVolume(), IntersectionFrequency(tolerance=1.0)
    volume.update(volumes=volumes)
    frequency.update(volumes=volumes)
    assert float(volume.compute()) == pytest.approx(17.5 / 4) and float(frequency.compute()) == 0.5
    with pytest.raises(ValueError, match="IntersectionVolume.update: give joints_a and joints_b"):
        IntersectionVolume().update()
