"""Callbacks the slurm tests add to a job (``+callbacks.hold._target_=slurm_callbacks.HoldForSignal``):
they make nothing happen, they only hold training still until Slurm has done what is tested."""

from __future__ import annotations

import time
from pathlib import Path

from lightning.pytorch import Callback

from callbacks.preemption import RequeueOnSignal


class HoldForSignal(Callback):
    """At the start of training batch ``batch`` of epoch ``epoch`` (once per run: a marker file),
    write ``<marker>`` (the step reached) and wait, at most ``timeout`` seconds, until a signal
    has come: Slurm's requeue warning (noted by :class:`RequeueOnSignal`) or a SIGTERM (noted by
    Lightning). The batch then runs, and the run reacts to the signal at its end.

    Without it a job would have to be long enough for Slurm's signal to land in training (the
    warning comes at a 30-second tick of slurmctld) and the test could not say at which step."""

    def __init__(self, marker: str, epoch: int, batch: int, timeout: float = 150) -> None:
        self.marker = Path(marker)
        self.epoch, self.batch, self.timeout = epoch, batch, timeout

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        if (trainer.current_epoch, batch_idx) != (self.epoch, self.batch) or self.marker.exists():
            return
        self.marker.write_text(f"{trainer.global_step}\n")
        requeue = [cb for cb in trainer.callbacks if isinstance(cb, RequeueOnSignal)]
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            if trainer.received_sigterm or any(cb.received is not None for cb in requeue):
                return
            time.sleep(0.1)
        raise RuntimeError(f"no signal came in {self.timeout} s at step {trainer.global_step}")
