"""Checkpoint files that survive a kill at any instant and name themselves when broken.

:func:`atomic_torch_save` writes beside the destination (same filesystem), flushes and fsyncs
the file, renames it over the destination (atomic on POSIX) and fsyncs the folder: at every
instant the destination holds either the previous checkpoint or the new one, complete.
:func:`read_checkpoint_file` reads with ``weights_only=True`` and turns a truncated or foreign
file into a :class:`CorruptCheckpoint` error that names the file and the cause. No Lightning
import here: :mod:`intermask.utils.checkpoint_io` plugs these into the Trainer.
"""

from __future__ import annotations

import os
import pickle
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

from intermask.utils.write_errors import write_error_in

TEMPORARY_SUFFIX = ".partial"  # "<name>.<pid>.partial" beside the destination while writing


class CorruptCheckpoint(ValueError):
    """A checkpoint file that cannot be read: truncated, empty or not a torch checkpoint."""


def _fsync_folder(folder: Path) -> None:
    try:
        descriptor = os.open(folder, os.O_RDONLY)
    except OSError:  # a platform without directory descriptors: the rename is still atomic
        return
    try:
        os.fsync(descriptor)
    finally:
        os.close(descriptor)


def _process_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def write_atomically(path: str | Path, write: Callable[[Path], object]) -> Path:
    """``write(temporary)`` into a temporary file beside ``path``, then rename it over ``path``:
    ``path`` holds the old content or the new, whole. On failure the temporary file is removed
    and a write error names ``path`` (a full disk surfaces as torch's RuntimeError over the
    OSError, which names no file or the temporary one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.name}.{os.getpid()}{TEMPORARY_SUFFIX}")
    try:
        write(temporary)
        os.replace(temporary, path)
    except BaseException as error:
        temporary.unlink(missing_ok=True)
        found = write_error_in(error)
        if found is not None and found.filename in (None, str(temporary)):
            found.filename = str(path)
        raise
    return path


def atomic_torch_save(payload: Any, path: str | Path) -> None:
    """``torch.save`` that replaces ``path`` atomically (:func:`write_atomically`), synced to
    the disk with its folder entry."""

    def save(temporary: Path) -> None:
        with temporary.open("wb") as handle:
            torch.save(payload, handle)
            handle.flush()
            os.fsync(handle.fileno())

    path = write_atomically(path, save)
    _fsync_folder(path.parent)
    # what writers killed mid-write left behind (a SIGKILL runs no cleanup); a file of a
    # process that still runs here is left alone
    for orphan in path.parent.glob(f".{path.name}.*{TEMPORARY_SUFFIX}"):
        pid = orphan.name.removesuffix(TEMPORARY_SUFFIX).rsplit(".", 1)[-1]
        if not (pid.isdigit() and _process_alive(int(pid))):
            orphan.unlink(missing_ok=True)


def read_checkpoint_file(path: str | Path, *, map_location: Any = "cpu") -> Any:
    """``torch.load(path, weights_only=True)`` with errors that name the file: FileNotFoundError,
    :class:`CorruptCheckpoint` (truncated, empty, not a checkpoint) or ``pickle.UnpicklingError``
    (it holds Python objects beyond tensors and plain values, which are never unpickled)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: checkpoint not found")
    size = path.stat().st_size
    if size == 0:
        raise CorruptCheckpoint(f"{path}: checkpoint is empty (0 bytes): an interrupted write?")
    with path.open("rb") as handle:
        head = handle.read(4)
    # torch.save writes a zip archive; files from before torch 1.6 are a bare pickle (0x80)
    if not head.startswith(b"PK\x03\x04") and not head.startswith(b"\x80"):
        raise CorruptCheckpoint(
            f"{path}: not a torch checkpoint ({size} bytes starting with {head!r})"
        )
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as error:
        first_line = str(error).strip().splitlines()[0]
        raise pickle.UnpicklingError(f"{path}: {first_line}") from error
    except (EOFError, OSError, RuntimeError, zipfile.BadZipFile, ValueError) as error:
        raise CorruptCheckpoint(
            f"{path}: not a readable checkpoint ({size} bytes; {type(error).__name__}: "
            f"{str(error).strip().splitlines()[0] if str(error).strip() else 'no detail'})"
        ) from error
