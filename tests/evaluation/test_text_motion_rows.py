"""The single-person rows of the text-to-motion table, and the evaluate job's mode checks."""

from __future__ import annotations

import pytest
import torch
from omegaconf import OmegaConf

from intermask.evaluate import build_sources
from intermask.evaluation.sources import token_lengths
from intermask.evaluation.text_motion import SoloReconstruction, TextToMotion
from intermask.metrics.mpjpe import per_joint_errors
from intermask.motion.masks import length_mask
from tests.momask.momask_tiny import LAYERS, make_batch, make_vq


def test_step_lengths_round_down_to_whole_tokens_within_the_frames():
    batch = {"length": torch.tensor([63, 40, 3, 200])}
    assert token_lengths(batch, 196).tolist() == [60, 40, 4, 196]


def test_reconstruction_row_decodes_the_items_codes_and_measures_mpjpe():
    vq, batch = make_vq(), make_batch(lengths=(64, 40, 30, 16))
    row = SoloReconstruction(vq=vq)
    motion, lengths = row(batch, torch.zeros(4, dtype=torch.int64))
    assert lengths.tolist() == [64, 40, 28, 16]
    indices = vq.encode(batch["motion"], lengths)
    expected = vq.view.denormalize(vq.decode_valid(indices))
    torch.testing.assert_close(motion, expected)
    real, fake = (
        vq.view.geometry(x).positions for x in (batch["motion"], vq.decode_valid(indices))
    )
    mask = length_mask(lengths, 64)
    expected_mm = 1000.0 * per_joint_errors(fake, real)[mask].mean()
    assert row.extra_metrics()["mpjpe_mm"] == pytest.approx(float(expected_mm.detach()), rel=1e-5)
    row.reset()
    assert row.extra_metrics() == {}
    base = SoloReconstruction(vq=vq, layers=1)(batch, torch.zeros(4, dtype=torch.int64))[0]
    only_first = vq.view.denormalize(vq.decode_valid(indices[:, :1]))
    torch.testing.assert_close(base, only_first)
    assert not torch.allclose(base, motion)  # the residual layers add detail
    with pytest.raises(
        ValueError, match=f"layers must be in \\[1, {LAYERS}\\] for this tokenizer, got 4"
    ):
        SoloReconstruction(vq=vq, layers=4)


def test_generation_row_asks_for_the_rounded_lengths():
    calls = []

    def generate(captions, lengths, seeds):
        calls.append((captions, lengths.tolist(), seeds.tolist()))
        return torch.zeros(len(captions), int(lengths.max()), 263)

    row = TextToMotion(generate=generate, name="fake")
    batch = make_batch(lengths=(63, 40))
    motion, lengths = row(batch, torch.tensor([7, 8]))
    assert calls == [(batch["caption"], [60, 40], [7, 8])] and lengths.tolist() == [60, 40]
    assert motion.shape == (2, 60, 263) and row.generates


def _cfg(dataset: str, mode: str, **extra):
    return OmegaConf.create(
        {"data": {"dataset": dataset}, "mode": mode, "vq_ckpt": None, "mask_ckpt": None, **extra}
    )


@pytest.mark.parametrize(
    ("dataset", "mode", "message"),
    [
        (
            "humanml3d",
            "interaction",
            "mode=interaction does not apply to humanml3d: single-person data takes mode=text_to_motion or reconstruction",
        ),
        (
            "interhuman",
            "text_to_motion",
            "mode=text_to_motion needs single-person data \\(data=humanml3d\\), got interhuman",
        ),
        (
            "humanml3d",
            "text_to_motion",
            "mode=text_to_motion needs mask_ckpt=<masked transformer run>",
        ),
    ],
)
def test_evaluate_refuses_modes_that_do_not_fit_the_data(dataset, mode, message):
    with pytest.raises(ValueError, match=message):
        build_sources(_cfg(dataset, mode), None, torch.device("cpu"))
