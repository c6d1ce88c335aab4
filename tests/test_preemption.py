"""A SIGTERM saves last.ckpt at the current step; the run resumes from it."""

from __future__ import annotations

import os
import signal

import pytest
from lightning.pytorch import Callback
from lightning.pytorch.utilities.exceptions import SIGTERMException
from test_train_vq import _config, _last

from intermask.train import train


class TerminateAt(Callback):
    """Sends this process SIGTERM after training batch ``batch_idx`` of epoch 0."""

    def __init__(self, batch_idx: int) -> None:
        self.batch_idx = batch_idx

    def on_train_batch_end(self, trainer, pl_module, outputs, batch, batch_idx):
        if trainer.current_epoch == 0 and batch_idx == self.batch_idx:
            os.kill(os.getpid(), signal.SIGTERM)


@pytest.mark.skipif(not hasattr(signal, "SIGTERM") or os.name == "nt", reason="POSIX signals")
def test_sigterm_saves_the_current_step_and_the_run_resumes(synthetic_interhuman_root, tmp_path):
    steps = ["trainer.limit_train_batches=4", "trainer.max_epochs=2"]
    stop = ["+callbacks.stop._target_=test_preemption.TerminateAt", "+callbacks.stop.batch_idx=1"]
    with pytest.raises(SIGTERMException):
        train(_config(synthetic_interhuman_root, tmp_path / "run", steps + stop))
    saved = _last(tmp_path / "run")
    assert saved["global_step"] == 2 and saved["epoch"] == 0  # mid-epoch, not the epoch end
    resume = [f"ckpt_path={tmp_path / 'run' / 'checkpoints' / 'last.ckpt'}"]
    train(_config(synthetic_interhuman_root, tmp_path / "resumed", steps + resume))
    assert _last(tmp_path / "resumed")["global_step"] == 8  # continued to the end of epoch 1
