"""A SIGTERM saves last.ckpt at the current step; the run resumes from it, mid-epoch, and ends
with the weights of the run that was never stopped."""

from __future__ import annotations

import os
import signal

import pytest
import torch
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


def _differing(one: dict, two: dict) -> list[str]:
    return [name for name, value in one.items() if not torch.equal(two[name], value)]


@pytest.mark.skipif(not hasattr(signal, "SIGTERM") or os.name == "nt", reason="POSIX signals")
def test_sigterm_saves_the_current_step_and_the_resumed_run_equals_the_uninterrupted_one(
    synthetic_interhuman_root, tmp_path
):
    # dropout on (the VQ preset's 0.2): the resumed run must continue torch's random stream;
    # fp32: the equality is of the same arithmetic (a bf16 run repeats itself too, but pinning
    # keeps the proof the same on every CPU)
    steps = [
        "trainer.limit_train_batches=4",
        "trainer.max_epochs=2",
        "trainer.precision=32-true",
        "callbacks.sample_animations=null",
    ]
    stop = ["+callbacks.stop._target_=test_preemption.TerminateAt", "+callbacks.stop.batch_idx=1"]
    train(_config(synthetic_interhuman_root, tmp_path / "whole", steps))
    with pytest.raises(SIGTERMException):
        train(_config(synthetic_interhuman_root, tmp_path / "run", steps + stop))
    saved = _last(tmp_path / "run")
    assert saved["global_step"] == 2 and saved["epoch"] == 0  # mid-epoch, not the epoch end
    # the training loader's place travels with the checkpoint: epoch 0, 2 batches handed out
    assert saved["InteractionDataModule"] == {"train_loader": {"epoch": 0, "batches": 2}}
    resume = [f"ckpt_path={tmp_path / 'run' / 'checkpoints' / 'last.ckpt'}"]
    train(_config(synthetic_interhuman_root, tmp_path / "resumed", steps + resume))
    whole, resumed = _last(tmp_path / "whole"), _last(tmp_path / "resumed")
    assert resumed["global_step"] == whole["global_step"] == 8  # on to the end of epoch 1
    assert _differing(whole["state_dict"], resumed["state_dict"]) == []
    optimizer = whole["optimizer_states"][0]["state"]
    for name, state in resumed["optimizer_states"][0]["state"].items():
        assert torch.equal(state["exp_avg_sq"], optimizer[name]["exp_avg_sq"]), name

    # the same resume without the random state in the checkpoint draws other dropout masks
    broken = [*resume, "callbacks.random_state=null"]
    train(_config(synthetic_interhuman_root, tmp_path / "broken", steps + broken))
    assert _differing(whole["state_dict"], _last(tmp_path / "broken")["state_dict"])


class SignalAt(Callback):
    """Sends this process ``signum`` at the start of training batch ``batch_idx`` of epoch 0."""

    def __init__(self, signum: str, batch_idx: int) -> None:
        self.signum, self.batch_idx = signal.Signals[signum], batch_idx

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
        if trainer.current_epoch == 0 and batch_idx == self.batch_idx:
            os.kill(os.getpid(), self.signum)


@pytest.mark.skipif(not hasattr(signal, "SIGUSR2"), reason="POSIX signals")
def test_a_requeue_signal_saves_at_the_batch_end_then_hands_over_to_the_jobs_handler(
    synthetic_interhuman_root, tmp_path, monkeypatch
):
    # a job's own handler for the signal, as submitit installs one (it requeues and exits)
    calls = []
    monkeypatch.delenv("SLURM_JOB_ID", raising=False)
    previous = signal.signal(signal.SIGUSR2, lambda signum, frame: calls.append(signum))
    try:
        steps = ["trainer.limit_train_batches=4", "callbacks.sample_animations=null"]
        send = [
            "+callbacks.send._target_=test_preemption.SignalAt",
            "+callbacks.send.signum=SIGUSR2",
            "+callbacks.send.batch_idx=1",
        ]
        handler = signal.getsignal(signal.SIGUSR2)
        with pytest.raises(SystemExit, match=r"SIGUSR2: step 2 \(epoch 0\) saved to .*last\.ckpt"):
            train(_config(synthetic_interhuman_root, tmp_path / "run", steps + send))
        assert calls == [signal.SIGUSR2]  # handed over once, after the save
        assert signal.getsignal(signal.SIGUSR2) is handler  # and put back
        saved = _last(tmp_path / "run")
        assert saved["global_step"] == 2  # batch 1 finished: the end of a step
        assert saved["InteractionDataModule"] == {"train_loader": {"epoch": 0, "batches": 2}}
    finally:
        signal.signal(signal.SIGUSR2, previous)


class LookAtHandlers(Callback):
    """Records the USR1 and USR2 handlers while training runs."""

    seen: dict = {}

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx):
        LookAtHandlers.seen = {s: signal.getsignal(s) for s in (signal.SIGUSR1, signal.SIGUSR2)}


@pytest.mark.skipif(not hasattr(signal, "SIGUSR2"), reason="POSIX signals")
def test_outside_slurm_and_without_a_handler_no_signal_handler_is_touched(
    synthetic_interhuman_root, tmp_path, monkeypatch
):
    monkeypatch.delenv("SLURM_JOB_ID", raising=False)
    before = {s: signal.getsignal(s) for s in (signal.SIGUSR1, signal.SIGUSR2)}
    look = ["+callbacks.look._target_=test_preemption.LookAtHandlers"]
    train(_config(synthetic_interhuman_root, tmp_path, ["callbacks.sample_animations=null", *look]))
    assert LookAtHandlers.seen == before
