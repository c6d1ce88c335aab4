"""A NaN loss stops the run naming step, term and clips (last good checkpoint kept), or skips
the step when configured."""

from __future__ import annotations

import pytest
import torch
from lightning.pytorch import Callback
from test_train_vq import _config, _last

from intermask.train import train
from intermask.utils.lightning import NonFiniteLoss


class PoisonBatch(Callback):
    """Puts a NaN into the motion of the batch at (epoch, batch_idx)."""

    def __init__(self, epoch: int, batch_idx: int) -> None:
        self.epoch, self.batch_idx = epoch, batch_idx

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
        if (trainer.current_epoch, batch_idx) == (self.epoch, self.batch_idx):
            batch["motion"][0, 3, 0] = float("nan")
            self.ids = [str(i) for i in batch["id"]]


def _poisoned(root, out, *extra):
    poison = [
        "+callbacks.poison._target_=test_non_finite.PoisonBatch",
        "+callbacks.poison.epoch=1",
        "+callbacks.poison.batch_idx=1",
    ]
    return _config(root, out, ["trainer.max_epochs=2", *poison, *extra])


def _finite(checkpoint: dict) -> bool:
    return all(
        torch.isfinite(v).all() for v in checkpoint["state_dict"].values() if v.is_floating_point()
    )


def test_a_nan_loss_stops_the_run_naming_step_terms_and_clips(synthetic_interhuman_root, tmp_path):
    with pytest.raises(NonFiniteLoss) as stopped:
        train(_poisoned(synthetic_interhuman_root, tmp_path))
    message = str(stopped.value)
    assert message.startswith("step 4: non-finite training loss (total, reconstruction")
    assert "non_finite_loss=skip" in message
    clip = message.split("on the batch of clips [")[1].split(",")[0]
    assert clip.isdigit()  # the synthetic clip ids
    kept = _last(tmp_path)  # epoch 0's checkpoint: the last good weights, untouched
    assert kept["global_step"] == 3 and _finite(kept)


def test_skip_policy_skips_the_step_and_goes_on(synthetic_interhuman_root, tmp_path, caplog):
    with caplog.at_level("WARNING", logger="intermask.utils.lightning"):
        train(_poisoned(synthetic_interhuman_root, tmp_path, "non_finite_loss=skip"))
    assert "step 4: non-finite training loss (total" in caplog.text
    assert "step skipped (1 so far)" in caplog.text
    finished = _last(tmp_path)
    # Lightning counts the skipped step (no gradients, so the optimizer changed nothing)
    assert finished["global_step"] == 6 and _finite(finished)


def test_an_unknown_policy_is_refused(synthetic_interhuman_root, tmp_path):
    with pytest.raises(ValueError, match=r"non_finite_loss must be one of \('stop', 'skip'\)"):
        train(_config(synthetic_interhuman_root, tmp_path, ["non_finite_loss=ignore"]))
