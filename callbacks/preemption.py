"""Pre-emption: a SIGTERM (a scheduler's time limit, ``scancel``, a node drain) saves the run's
state to ``last.ckpt`` before the process exits, so ``ckpt_path=<run>/checkpoints/last.ckpt``
continues from the step it was stopped at instead of the last epoch end.

Lightning turns SIGTERM into a ``SIGTERMException`` after the current batch (all DDP processes
together); this callback writes the checkpoint then, through the Trainer (rank zero writes, the
atomic checkpoint I/O of ``train.py`` keeps the previous file intact until the new one is
complete).

Requeue: Slurm's warning before a time limit (``#SBATCH --signal=SIGUSR1@90``) or submitit's
(``USR2``) makes :class:`RequeueOnSignal` save ``last.ckpt`` at the end of the current batch and
requeue the job; the requeued job restarts in the same run folder and resumes from that step
(``existing_run: resume``), bit for bit. docs/cluster.md describes the whole path.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import lightning as L
from lightning.pytorch.callbacks import Callback
from lightning.pytorch.utilities.exceptions import SIGTERMException

log = logging.getLogger(__name__)


class SaveOnSigterm(Callback):
    """On SIGTERM during fit, save ``<dirpath>/<filename>.ckpt`` before exiting."""

    def __init__(self, dirpath: str | Path, filename: str = "last") -> None:
        self.path = Path(dirpath) / f"{filename}.ckpt"

    def on_exception(
        self, trainer: L.Trainer, pl_module: L.LightningModule, exception: BaseException
    ) -> None:
        if not isinstance(exception, SIGTERMException):
            return
        trainer.save_checkpoint(self.path)
        if trainer.is_global_zero:
            log.warning(
                "SIGTERM at step %d (epoch %d): state saved to %s; resume with ckpt_path=%s",
                trainer.global_step,
                trainer.current_epoch,
                self.path,
                self.path,
            )


REQUEUE_SIGNALS = ("SIGUSR1", "SIGUSR2")  # Lightning's and sbatch scripts' convention, submitit's


def slurm_job_id() -> str | None:
    """The id ``scontrol requeue`` takes for this job (``<array job>_<task>`` in an array)."""
    array_job = os.environ.get("SLURM_ARRAY_JOB_ID")
    if array_job is not None and "SLURM_ARRAY_TASK_ID" in os.environ:
        return f"{array_job}_{os.environ['SLURM_ARRAY_TASK_ID']}"
    return os.environ.get("SLURM_JOB_ID")


def requeue_slurm_job(job_id: str) -> None:
    """``scontrol requeue JOB``; a refusal (a job submitted with ``--no-requeue``, a cluster with
    ``JobRequeue=0`` and no ``--requeue``) is raised with scontrol's message."""
    done = subprocess.run(
        ["scontrol", "requeue", job_id], capture_output=True, text=True, timeout=60
    )
    if done.returncode != 0:
        raise RuntimeError(
            f"scontrol requeue {job_id} failed ({done.returncode}): "
            f"{(done.stderr or done.stdout).strip()}"
        )


class RequeueOnSignal(Callback):
    """Slurm's warning signal (``--signal=SIGUSR1@<seconds>`` before the time limit, submitit's
    ``USR2``): save ``<dirpath>/<filename>.ckpt`` at the end of the current training batch, then
    requeue the job and exit.

    The signal handler only notes the signal; the save waits for the batch to end, so the
    checkpoint holds a state the uninterrupted run also passed through (a save from inside the
    handler, as Lightning's own auto-requeue does, can catch a step half applied). All processes
    of a data-parallel run agree on the batch. The job is then requeued: by the handler that was
    there before (submitit's, which requeues its job and exits), else with ``scontrol requeue``
    from rank zero. The requeued job restarts in the same run folder and resumes from this
    checkpoint (``existing_run: resume``).

    Listens from the start of training, under Slurm (``SLURM_JOB_ID`` set) and wherever a
    handler for the signal is already installed (submitit's, also its local executor); elsewhere
    it changes no handler. After the fit the previous handlers are back, except that under Slurm
    a signal with no handler before is ignored from then on: the run is complete, and the default
    action would kill the job.
    """

    def __init__(
        self,
        dirpath: str | Path,
        filename: str = "last",
        signals: Sequence[str] = REQUEUE_SIGNALS,
    ) -> None:
        self.path = Path(dirpath) / f"{filename}.ckpt"
        self.signals = [signal.Signals[name] for name in signals]
        self.received: signal.Signals | None = None
        self._previous: dict[signal.Signals, Any] = {}

    @property
    def active(self) -> bool:
        """Whether this fit listens for the signals."""
        return bool(self._previous)

    def on_train_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        # after Lightning has installed its handlers: it puts back what it found when the fit
        # ends, also when the fit ends in an exception (when a callback's teardown is not called)
        if threading.current_thread() is not threading.main_thread():
            return
        under_slurm = "SLURM_JOB_ID" in os.environ
        self.received = None
        for signum in self.signals:
            previous = signal.getsignal(signum)
            if callable(previous) or under_slurm:
                self._previous[signum] = previous
                signal.signal(signum, self._note)

    def _note(self, signum: int, frame: Any) -> None:
        # nothing but a note: the handler may run anywhere in a step
        self.received = signal.Signals(signum)

    def on_train_batch_end(
        self,
        trainer: L.Trainer,
        pl_module: L.LightningModule,
        outputs: Any,
        batch: Any,
        batch_idx: int,
    ) -> None:
        if not self.active:
            return
        if not trainer.strategy.reduce_boolean_decision(self.received is not None, all=False):
            return
        signum = self.received or self.signals[0]  # a rank the signal has not reached yet
        trainer.save_checkpoint(self.path)
        previous = self._restore()
        handler = previous.get(signum)
        where = f"step {trainer.global_step} (epoch {trainer.current_epoch}) saved to {self.path}"
        if callable(handler):  # submitit: it requeues its job (rank 0) and exits
            if trainer.is_global_zero:
                log.warning("%s: %s; handing over to the job's handler", signum.name, where)
            handler(signum, None)
            raise SystemExit(f"{signum.name}: {where}; the job is being requeued")
        job = slurm_job_id()
        if trainer.is_global_zero:
            if job is None:
                raise RuntimeError(f"{signum.name}: {where}, but this is no Slurm job to requeue")
            requeue_slurm_job(job)
            log.warning("%s: %s; Slurm job %s requeued", signum.name, where, job)
        raise SystemExit(f"{signum.name}: {where}; Slurm job {job} requeued")

    def on_exception(
        self, trainer: L.Trainer, pl_module: L.LightningModule, exception: BaseException
    ) -> None:
        self._restore()

    def teardown(self, trainer: L.Trainer, pl_module: L.LightningModule, stage: str) -> None:
        self._restore()

    def _restore(self) -> dict[signal.Signals, Any]:
        """Put the previous handlers back (ignore where there was none under Slurm)."""
        previous, self._previous = self._previous, {}
        if threading.current_thread() is threading.main_thread():
            for signum, handler in previous.items():
                if handler in (None, signal.SIG_DFL) and "SLURM_JOB_ID" in os.environ:
                    handler = signal.SIG_IGN
                signal.signal(signum, handler)
        return previous
