"""Lightning's checkpoint I/O through :mod:`intermask.utils.checkpoint_files`.

Lightning's default writer stages a checkpoint in a temporary file of the system's temporary
folder and moves it into place; when that folder is on another filesystem the move is a copy,
so a SIGKILL during it leaves a truncated ``last.ckpt`` and the previous epoch is gone.
:class:`AtomicCheckpointIO` writes beside the destination instead, and loads with
``weights_only=True`` and named errors.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from lightning.fabric.plugins.io.torch_io import TorchCheckpointIO

from intermask.utils.checkpoint_files import atomic_torch_save, read_checkpoint_file


class AtomicCheckpointIO(TorchCheckpointIO):
    """Lightning checkpoint I/O: atomic local writes, named errors on load (remote URLs keep
    Lightning's fsspec path)."""

    def save_checkpoint(
        self, checkpoint: dict[str, Any], path: str | Path, storage_options: Any = None
    ) -> None:
        if "://" in str(path):
            super().save_checkpoint(checkpoint, path, storage_options)
            return
        if storage_options is not None:
            raise TypeError(f"storage_options are not supported for local checkpoints ({path})")
        atomic_torch_save(checkpoint, path)

    def load_checkpoint(
        self, path: str | Path, map_location: Any = None, weights_only: bool | None = None
    ) -> dict[str, Any]:
        if "://" in str(path):
            return super().load_checkpoint(path, map_location=map_location, weights_only=True)
        return read_checkpoint_file(path, map_location=map_location or "cpu")
