"""Outputs that appear whole or not at all.

:func:`staged_outputs` gives a command a temporary folder beside its output folder to write its
units (``out/<name>`` for each name) into. Only when the block finishes are they moved into
place: the whole folder in one rename when ``out`` does not exist yet, else one rename per unit,
the ones already moved taken back if a later one fails (with ``replace``, the units they
replaced put back too). On any failure the temporary folder is removed, so a failed command
leaves nothing behind and the same command can simply be run again. :func:`write_atomically`
does the same for a single file. A write error raised inside names the destination, not the
temporary path (:mod:`intermask.utils.write_errors` reports it).
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from intermask.utils.checkpoint_files import TEMPORARY_SUFFIX, write_atomically
from intermask.utils.write_errors import name_destination, write_error_in

REPLACED = ".replaced"  # inside the staging folder: what ``replace`` moved aside


@contextmanager
def staged_outputs(
    out: str | Path, names: Sequence[str] | None, *, replace: bool = False
) -> Iterator[Path]:
    """Yield a temporary sibling of ``out``; write ``<yielded>/<name>`` for each of ``names``
    (None: whatever the block writes there, with ``replace`` only).

    Raises FileExistsError (before anything is written) when ``out/<name>`` exists already
    (unless ``replace``: then it is replaced when the block succeeds, kept when it fails), or
    ``out`` is not a folder.
    """
    out = Path(out).absolute()
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder")
    if names is None and not replace:
        raise ValueError("staged_outputs: names=None (whatever is written) needs replace=True")
    for name in () if replace else names:
        if (out / name).exists():
            raise FileExistsError(
                f"{out / name} exists: choose another --out (nothing was overwritten)"
            )
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.parent / f".{out.name}.{os.getpid()}{TEMPORARY_SUFFIX}"
    shutil.rmtree(staging, ignore_errors=True)  # a dead run of this process id
    try:
        staging.mkdir()
        yield staging
        written = sorted(os.listdir(staging)) if names is None else names
        _move_into_place(staging, out, written)
    except BaseException as error:
        _name_in_place(error, staging, out)
        raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _name_in_place(error: BaseException, staging: Path, out: Path) -> None:
    """The write error's file as it would have been named in place (or ``out``)."""
    found = write_error_in(error)
    if found is None or found.filename is None:
        name_destination(error, out)
        return
    path = Path(os.fsdecode(found.filename)).absolute()
    if path == staging or staging in path.parents:
        found.filename = str(out / path.relative_to(staging))


def _move_into_place(staging: Path, out: Path, names: Sequence[str]) -> None:
    missing = [name for name in names if not (staging / name).exists()]
    if missing:
        raise RuntimeError(f"staged output incomplete: {', '.join(missing)} not written")
    if not out.exists():
        os.rename(staging, out)
        staging.mkdir()  # for the caller's cleanup, which removes it again
        return
    replaced = staging / REPLACED
    moved, kept = [], []
    try:
        for name in names:
            if (out / name).exists() or (out / name).is_symlink():
                replaced.mkdir(exist_ok=True)
                os.rename(out / name, replaced / name)
                kept.append(name)
            os.rename(staging / name, out / name)
            moved.append(name)
    except BaseException:
        for name in moved:
            _remove(out / name)
        for name in kept:
            os.rename(replaced / name, out / name)
        raise


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


def write_text_atomically(path: str | Path, text: str) -> Path:
    """:func:`write_atomically` of a UTF-8 text file."""
    return write_atomically(path, lambda temporary: temporary.write_text(text, encoding="utf-8"))
