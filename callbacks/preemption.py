"""Pre-emption: a SIGTERM (a scheduler's time limit, ``scancel``, a node drain) saves the run's
state to ``last.ckpt`` before the process exits, so ``ckpt_path=<run>/checkpoints/last.ckpt``
continues from the step it was stopped at instead of the last epoch end.

Lightning turns SIGTERM into a ``SIGTERMException`` after the current batch (all DDP processes
together); this callback writes the checkpoint then, through the Trainer (rank zero writes, the
atomic checkpoint I/O of ``train.py`` keeps the previous file intact until the new one is
complete). SLURM's requeue signal (SIGUSR1 with ``auto_requeue``) keeps Lightning's own
``hpc_ckpt`` path; see docs/cluster.md.
"""

from __future__ import annotations

import logging
from pathlib import Path

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
