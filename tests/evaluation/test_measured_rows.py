"""Penetration and latency columns of protocol rows (`Measured`), and joints from features."""

from __future__ import annotations

import pytest
import torch

from intermask.evaluation.protocol import MotionSource
from intermask.evaluation.sources import Measured, feature_joints
from intermask.metrics.penetration import IntersectionFrequency, IntersectionVolume
from intermask.motion.skeleton import rest_pose_positions


def standing_pair(*, batch: int, frames: int, gap: float) -> torch.Tensor:
    """(B, 2, T, 262) de-normalized features: two rest poses ``gap`` metres apart along X
    (only the 66 position values are set)."""
    rest = rest_pose_positions()
    pair = torch.stack([rest, rest + torch.tensor([gap, 0.0, 0.0])])  # (2, 22, 3)
    motion = torch.zeros(batch, 2, frames, 262)
    motion[..., :66] = pair.reshape(2, 1, 66)
    return motion


class FixedPair(MotionSource):
    """Returns the same two-person motion for every batch and counts its calls."""

    name, generates = "fixed", True

    def __init__(self, motion: torch.Tensor, lengths: torch.Tensor) -> None:
        self.motion, self.lengths, self.calls, self.resets = motion, lengths, 0, 0

    def __call__(self, batch, seeds):
        self.calls += 1
        return self.motion, self.lengths

    def reset(self) -> None:
        self.resets += 1


def test_feature_joints_reads_interhuman_positions_and_rejects_other_shapes():
    motion = standing_pair(batch=1, frames=3, gap=2.0)
    joints = feature_joints(motion)
    assert joints.shape == (1, 2, 3, 22, 3)
    assert torch.equal(joints[0, 1, 0].reshape(-1), motion[0, 1, 0, :66])
    with pytest.raises(ValueError, match=r"no joint positions for features of shape \(2, 5, 7\)"):
        feature_joints(torch.zeros(2, 5, 7))


def test_overlapping_bodies_give_volume_and_frequency_only_on_valid_frames():
    overlapping = standing_pair(batch=2, frames=4, gap=0.3)
    lengths = torch.tensor([4, 2])
    row = Measured(FixedPair(overlapping, lengths))
    row(None, torch.zeros(2))
    values = row.extra_metrics()
    assert values["if"] == 1.0 and values["iv_cm3"] > 1000.0  # two torsos 30 cm apart
    assert values["latency_ms"] > 0.0
    assert row.name == "fixed" and row.generates


def test_the_row_reports_what_the_penetration_metrics_compute_on_the_same_batch():
    motion = standing_pair(batch=3, frames=5, gap=0.3)
    motion[1] = standing_pair(batch=1, frames=5, gap=2.0)[0]  # the second pair apart
    lengths = torch.tensor([5, 3, 4])
    row = Measured(FixedPair(motion, lengths), tolerance=2000.0)
    row(None, torch.zeros(3))
    values = row.extra_metrics()
    joints = feature_joints(motion)
    valid = torch.arange(5)[None, :] < lengths[:, None]
    volume, frequency = IntersectionVolume(), IntersectionFrequency(tolerance=2000.0)
    volume.update(joints[:, 0], joints[:, 1], valid)
    frequency.update(joints[:, 0], joints[:, 1], valid)
    assert values["iv_cm3"] == float(volume.compute()) > 0.0
    assert values["if"] == float(frequency.compute()) == pytest.approx(9 / 12)  # 5 + 0 + 4 frames


def test_distant_bodies_give_zero_and_measurement_covers_the_evaluation_pass_only():
    apart = FixedPair(standing_pair(batch=2, frames=4, gap=2.0), torch.tensor([4, 4]))
    row = Measured(apart, latency=False)
    assert apart.resets == 1  # construction starts a pass
    row(None, torch.zeros(2))
    assert row.extra_metrics() == {"iv_cm3": 0.0, "if": 0.0}
    # after extra_metrics (MultiModality batches) nothing is counted until the next reset
    row.source.motion = standing_pair(batch=2, frames=4, gap=0.3)
    row(None, torch.zeros(2))
    assert row.extra_metrics() == {"iv_cm3": 0.0, "if": 0.0}
    row.reset()
    row(None, torch.zeros(2))
    assert row.extra_metrics()["if"] == 1.0 and apart.resets == 2 and apart.calls == 3


def test_penetration_can_be_switched_off():
    source = FixedPair(standing_pair(batch=1, frames=2, gap=0.3), torch.tensor([2]))
    row = Measured(source, penetration=False)
    row(None, torch.zeros(1))
    assert set(row.extra_metrics()) == {"latency_ms"}


def test_a_body_model_adds_the_mesh_columns(tmp_path):
    """With a body model (here the generated stand-in), the row also reports IV / IF on the
    fitted meshes and the fit's error; two T-posed bodies 30 cm apart overlap in every frame."""
    from intermask.body.model import load_body_model
    from intermask.body.penetration import MeshPenetration
    from intermask.body.standin import write_standin_model

    model = load_body_model(write_standin_model(tmp_path, "smplx"), dtype=torch.float64)
    motion = standing_pair(batch=2, frames=3, gap=0.3)
    motion[..., 132:258] = torch.tensor([1.0, 0.0, 0.0, 1.0, 0.0, 0.0]).repeat(21)  # identity 6D
    row = Measured(FixedPair(motion, torch.tensor([3, 2])), mesh=MeshPenetration(model, pitch=0.02))
    row(None, torch.zeros(2))
    values = row.extra_metrics()
    assert values["mesh_if"] == 1.0 and values["mesh_iv_cm3"] > 100.0
    assert values["mesh_fit_error_mm"] < 5.0 and values["if"] == 1.0
    off = Measured(FixedPair(motion, torch.tensor([3, 2])), penetration=False, mesh=row.mesh)
    off(None, torch.zeros(2))
    assert set(off.extra_metrics()) == {"latency_ms"}  # no penetration: no mesh columns either
