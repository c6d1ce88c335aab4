"""Outputs that appear whole or not at all.

:func:`staged_outputs` gives a command a temporary folder beside its output folder to write its
units (``out/<name>`` for each name) into. Only when the block finishes are they moved into
place: the whole folder in one rename when ``out`` does not exist yet, else one rename per unit,
the ones already moved taken back if a later one fails. On any failure the temporary folder is
removed, so a failed command leaves nothing behind and the same command can simply be run again.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

from intermask.utils.checkpoint_files import TEMPORARY_SUFFIX


@contextmanager
def staged_outputs(out: str | Path, names: Sequence[str]) -> Iterator[Path]:
    """Yield a temporary sibling of ``out``; write ``<yielded>/<name>`` for each of ``names``.

    Raises FileExistsError (before anything is written) when ``out/<name>`` exists already, or
    ``out`` is not a folder.
    """
    out = Path(out).absolute()
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder")
    for name in names:
        if (out / name).exists():
            raise FileExistsError(
                f"{out / name} exists: choose another --out (nothing was overwritten)"
            )
    out.parent.mkdir(parents=True, exist_ok=True)
    staging = out.parent / f".{out.name}.{os.getpid()}{TEMPORARY_SUFFIX}"
    shutil.rmtree(staging, ignore_errors=True)  # a dead run of this process id
    staging.mkdir()
    try:
        yield staging
        _move_into_place(staging, out, names)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def _move_into_place(staging: Path, out: Path, names: Sequence[str]) -> None:
    missing = [name for name in names if not (staging / name).exists()]
    if missing:
        raise RuntimeError(f"staged output incomplete: {', '.join(missing)} not written")
    if not out.exists():
        os.rename(staging, out)
        staging.mkdir()  # for the caller's cleanup, which removes it again
        return
    moved = []
    try:
        for name in names:
            os.rename(staging / name, out / name)
            moved.append(name)
    except BaseException:
        for name in moved:
            shutil.rmtree(out / name, ignore_errors=True)
        raise
