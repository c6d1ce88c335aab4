"""Hydra's own writes on a full or unwritable disk: a check before them.

Hydra creates the run folder, opens the job's log there and writes its record (``.hydra/``)
before the job function runs, outside :func:`~intermask.utils.write_errors.reported_write_errors`
around it: a failure there would end in Hydra's traceback. :class:`RunFolderCheck` (a Hydra
callback, configs/hydra/default.yaml) creates the run (or sweep) folder first and writes and
removes a probe of :data:`PROBE_BYTES` in it, so a read-only or full disk, a missing permission or
a file in the way is said in one line, exit 2, before anything else is written.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from intermask.utils.checkpoint_files import TEMPORARY_SUFFIX
from intermask.utils.write_errors import reported_write_errors

PROBE_BYTES = 1 << 16  # more than Hydra's record, the resolved config and the run record


def check_writable(folder: Path, *, program: str) -> None:
    """Create ``folder`` and write, fsync and remove a probe there; a write error is reported
    as ``<program>: error: ...`` with exit code 2."""
    created = not folder.exists()
    with reported_write_errors(program, fallback=folder, elsewhere="choose another hydra.run.dir"):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            _probe(folder)
        except BaseException:
            if created and folder.is_dir():
                shutil.rmtree(folder, ignore_errors=True)  # the empty folder made here
            raise


def _probe(folder: Path) -> None:
    probe = folder / f".write-check.{os.getpid()}{TEMPORARY_SUFFIX}"
    try:
        with probe.open("wb") as handle:
            handle.write(bytes(PROBE_BYTES))
            handle.flush()
            os.fsync(handle.fileno())
    finally:
        probe.unlink(missing_ok=True)


def _program(config: DictConfig) -> str:
    return f"python -m intermask.{config.hydra.job.name}"  # the job's module: train, evaluate


class RunFolderCheck(Callback):
    """Check the run folder (a single run) or the sweep folder (a multirun) is writable before
    Hydra writes there."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        check_writable(Path(config.hydra.run.dir), program=_program(config))

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        check_writable(Path(config.hydra.sweep.dir), program=_program(config))
