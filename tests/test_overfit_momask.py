"""MoMask's memorisation check (intermask.overfit_momask): its clip set, its measurements, its
report and (slow) the check itself."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from intermask.data.humanml3d import HumanML3DDataset
from intermask.overfit_momask import (
    ClipBatch,
    MoMaskClipResult,
    MoMaskOverfitReport,
    _base_only,
    _mpjpe_mm,
    masked_accuracy_from_text,
    residual_accuracy_per_layer,
    write_momask_memorisation_set,
)
from tests.momask.momask_tiny import CODES, LAYERS, make_vq


def test_memorisation_set_lists_every_clip_whole_in_every_split(tmp_path):
    root = write_momask_memorisation_set(tmp_path / "data", clips=4, seed=0)
    splits = {s: (root / f"{s}.txt").read_text().split() for s in ("train", "val", "test")}
    assert splits["train"] == splits["val"] == splits["test"] == [f"{i:06d}" for i in range(4)]
    dataset = HumanML3DDataset(root=root, split="test", max_length=196, length_jitter=False)
    assert [span.item_id for span in dataset.items] == splits["test"]  # no sub-clip items
    for index in range(len(dataset)):  # whole clips of whole token steps: one crop each
        item = dataset[index]
        assert item["start"] == 0 and item["length"] == dataset.frames[index]
        assert item["length"] % 4 == 0


def _clip(name: str, base_mm: float, full_mm: float, base_codes: float = 1.0) -> MoMaskClipResult:
    return MoMaskClipResult(
        name, "a person waves", 64, base_codes, [1.0, 0.9], base_mm, full_mm, 30.0, 20.0
    )


def test_report_passes_only_when_every_threshold_is_met():
    clips = [_clip("0", 40.0, 25.0), _clip("1", 50.0, 30.0)]
    report = MoMaskOverfitReport(20.0, 0.99, [0.97, 0.96], clips, {"rvq": 60.0})
    assert report.passed and report.residual_helps
    assert report.mean("base_mm") == pytest.approx(45.0)
    table = report.table()
    assert "| mean | | | | 45.0 | 27.5 | 30.0 | 20.0 | |" in table and "rvq 1.0 min" in table
    assert not MoMaskOverfitReport(20.0, 0.99, [0.97, 0.94], clips, {}).passed  # one layer short
    assert not MoMaskOverfitReport(20.0, 0.90, [0.97, 0.96], clips, {}).passed
    one_worse = [_clip("0", 40.0, 25.0), _clip("1", 30.0, 31.0)]  # better on average
    assert MoMaskOverfitReport(20.0, 0.99, [0.97, 0.96], one_worse, {}).passed
    worse = [_clip("0", 40.0, 41.0), _clip("1", 30.0, 31.0)]  # residual layers hurt
    assert not MoMaskOverfitReport(20.0, 0.99, [0.97, 0.96], worse, {}).passed
    clips = [_clip("0", 40.0, 25.0, base_codes=0.5), _clip("1", 50.0, 30.0)]  # 0.75 < 0.9
    assert not MoMaskOverfitReport(20.0, 0.99, [0.97, 0.96], clips, {}).passed


def _batch(vq, lengths=(16, 12)) -> ClipBatch:
    """Clips that are the decoding of random codes: their own codes decode to them exactly."""
    generator = torch.Generator().manual_seed(0)
    steps = torch.tensor(lengths) // 4
    tokens = torch.randint(0, CODES, (len(lengths), LAYERS, int(steps.max())), generator=generator)
    tokens = tokens.masked_fill(torch.arange(tokens.shape[-1]) >= steps[:, None, None], -1)
    with torch.no_grad():
        motion = vq.decode_valid(tokens[:, :, None])
    return ClipBatch(
        ["a", "b"], ["a person waves", "a person bows"], motion, torch.tensor(lengths), tokens
    )


def test_joint_error_is_zero_for_the_clips_own_decoding_and_not_for_its_base_alone():
    vq = make_vq()
    batch = _batch(vq)
    with torch.no_grad():
        torch.testing.assert_close(_mpjpe_mm(vq, batch.tokens, batch), torch.zeros(2))
        assert bool((_mpjpe_mm(vq, _base_only(batch.tokens), batch) > 0).all())
    assert bool((_base_only(batch.tokens)[:, 1:] == -1).all())


class _Oracle(nn.Module):
    """Logits peaked on the true codes of ``answer`` (layer j, or the base for the masked
    transformer), wrong at the steps listed in ``wrong``."""

    def __init__(self, answer: torch.Tensor, wrong: tuple[int, ...] = ()) -> None:
        super().__init__()
        self.answer, self.wrong = answer, wrong
        self.num_quantizers, self.vocabulary = answer.shape[1], type("V", (), {"mask_id": CODES})
        self.inputs = []

    def forward(self, tokens, text, lengths, drop_condition=None, *, layer=0):
        self.inputs.append(tokens)
        codes = self.answer[:, layer].clamp_min(0).clone()
        codes[:, list(self.wrong)] = (codes[:, list(self.wrong)] + 1) % CODES
        return nn.functional.one_hot(codes, CODES).float()


def test_accuracies_count_the_valid_steps_of_each_layer():
    batch = _batch(make_vq())  # 4 and 3 valid steps
    text = torch.zeros(2, 8)
    assert residual_accuracy_per_layer(_Oracle(batch.tokens), text, batch) == [1.0] * (LAYERS - 1)
    wrong_last = residual_accuracy_per_layer(_Oracle(batch.tokens, wrong=(3,)), text, batch)
    assert wrong_last == pytest.approx([6 / 7] * (LAYERS - 1))  # step 3 is valid in clip "a" only
    oracle = _Oracle(batch.tokens, wrong=(0,))
    assert masked_accuracy_from_text(oracle, text, batch) == pytest.approx(5 / 7)
    expected = torch.tensor([[CODES] * 4, [CODES] * 3 + [-1]])  # every valid step [MASK]
    assert torch.equal(oracle.inputs[0], expected)


@pytest.mark.slow
def test_the_momask_chain_memorises_eight_clips(tmp_path):
    """Every layer memorised, the captions give back their clips' codes, and the residual layers
    bring the generated motions closer to the clips than the base layer alone."""
    from intermask.overfit_momask import (
        GENERATED_BASE_CODES,
        MASKED_ACCURACY,
        RESIDUAL_ACCURACY,
        run,
    )

    report = run(tmp_path / "overfit_momask", seed=0)
    print(report.table())
    assert report.masked_accuracy >= MASKED_ACCURACY, report.table()
    assert min(report.residual_accuracy) >= RESIDUAL_ACCURACY, report.table()
    assert report.mean("base_codes") >= GENERATED_BASE_CODES, report.table()
    assert report.mean("full_mm") < report.mean("base_mm"), report.table()
