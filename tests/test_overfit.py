"""The memorisation check (intermask.overfit): its 14-clip set, its report, and (slow) the check."""

from __future__ import annotations

import json

import pytest
import torch

from intermask.data.synthetic import ACTIONS
from intermask.overfit import ClipResult, OverfitReport, _clip_errors, write_memorisation_set


def test_memorisation_set_has_one_clip_per_action_in_every_split(tmp_path):
    root = write_memorisation_set(tmp_path / "data", seed=0)
    meta = json.loads((root / "interaction_meta.json").read_text())["clips"]
    assert sorted(c["action"] for c in meta.values()) == sorted(ACTIONS)
    splits = {
        s: (root / "split" / f"{s}.txt").read_text().split() for s in ("train", "val", "test")
    }
    assert splits["train"] == splits["val"] == splits["test"]
    assert sorted(splits["train"]) == sorted(meta)


def test_clip_errors_average_valid_frames_of_both_persons():
    real = torch.rand(2, 6, 2, 22, 3)
    generated = real.clone()
    generated[0, :, 0, :, 1] += 0.1  # person 1 of sample 0 10 cm too high everywhere
    generated[1, 4:] = 5.0  # sample 1 wrong only beyond its length
    errors = _clip_errors(generated, real, torch.tensor([6, 4]))
    torch.testing.assert_close(errors, torch.tensor([0.05, 0.0]), atol=1e-5, rtol=0)


def test_clip_errors_ignore_person_order_and_the_ground_frame():
    real = torch.rand(1, 5, 2, 22, 3)
    turn = torch.tensor(1.2)
    rotation = torch.tensor(
        [[turn.cos(), 0.0, turn.sin()], [0.0, 1.0, 0.0], [-turn.sin(), 0.0, turn.cos()]]
    )
    moved = real.flip(2) @ rotation.T + torch.tensor([2.0, 0.0, -1.0])  # swapped, turned, shifted
    torch.testing.assert_close(
        _clip_errors(moved, real, torch.tensor([5])), torch.zeros(1), atol=1e-5, rtol=0
    )
    raised = moved.clone()
    raised[..., 1] += 0.2  # heights are not aligned away
    torch.testing.assert_close(
        _clip_errors(raised, real, torch.tensor([5])), torch.tensor([0.2]), atol=1e-5, rtol=0
    )


def test_report_table_counts_successes_and_flags_failures():
    clips = [
        ClipResult("1", "hug", "two people hug", 96, True, 0.031),
        ClipResult("2", "wave", "one waves", 64, False, 0.2),
    ]
    report = OverfitReport(
        vq_mpjpe_mm=20.0, masked_accuracy=0.97, clips=clips, seconds={"VQ-VAE": 60.0}
    )
    assert report.successes == 1
    table = report.table()
    assert "success 1/2" in table and "| wave | 64 | NO | 200 |" in table
    assert "VQ-VAE 1.0 min" in table


@pytest.mark.slow
def test_the_chain_memorises_fourteen_clips(tmp_path):
    """14 of 14 since the arms loss (docs/decisions.md: model.loss_weights.arms); 28 min at one
    thread when first measured."""
    from intermask.overfit import DEFAULT_ACCURACY, run

    report = run(tmp_path / "overfit", seed=0)
    print(report.table())
    assert report.masked_accuracy > DEFAULT_ACCURACY
    assert report.successes == len(ACTIONS), report.table()
