"""One clear line instead of a traceback when a command cannot write where it was told to.

Every command that writes (``intermask``'s sub-commands, ``python -m intermask.train`` and
``python -m intermask.evaluate``, ``intermask.overfit``, ``intermask.bench``) reports an
:class:`OSError` that says the place cannot be written as

    <program>: error: <path>: <what>; <what to do>, then <how to go on>

on stderr, and exits with :data:`EXIT_CODE` (the console script's code for every user error).
The places: no space left (or quota used up), permission denied, a read-only filesystem, a file
where a folder is needed. Any other error propagates unchanged. What was half-written is not
this module's business: the writers stage their output (:mod:`intermask.utils.staging`,
:func:`~intermask.utils.checkpoint_files.atomic_torch_save`) and name the destination in the
error they raise, so the path reported is where the output was to go, not a temporary file.
"""

from __future__ import annotations

import errno
import os
import re
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

EXIT_CODE = 2  # intermask/cli.py: a user error (a bad file, option or place) exits with 2

FREE_SPACE = "free some space there"
# errno -> (what happened, what to do about the place)
PROBLEMS: dict[int, tuple[str, str]] = {
    errno.ENOSPC: ("no space left on the device", FREE_SPACE),
    errno.EDQUOT: ("disk quota exceeded", FREE_SPACE),
    errno.EFBIG: ("file too large for the filesystem", "write to another filesystem"),
    errno.EACCES: ("permission denied", "give yourself write access to it"),
    errno.EPERM: ("operation not permitted", "give yourself write access to it"),
    errno.EROFS: ("the filesystem is read-only", "write to a writable filesystem"),
    errno.EEXIST: ("a file is in the way where a folder is needed", "move that file away"),
    errno.ENOTDIR: ("a file is in the way where a folder is needed", "move that file away"),
}
# numpy's ndarray.tofile (np.save to a real file) reports a short write without an errno
_SHORT_WRITE = re.compile(r"\d+ requested and \d+ written")


def problem_errno(error: OSError) -> int | None:
    """The :data:`PROBLEMS` errno of ``error``, None for any other error. A short write without
    an errno (numpy) is a full disk."""
    if error.errno in PROBLEMS:
        return error.errno
    if error.errno is None and _SHORT_WRITE.search(str(error)):
        return errno.ENOSPC
    return None


def write_error_in(error: BaseException) -> OSError | None:
    """The first :data:`PROBLEMS` OSError in ``error``'s chain (``__cause__``/``__context__``):
    torch.save reports a full disk as a RuntimeError raised while handling the OSError."""
    seen: set[int] = set()
    current: BaseException | None = error
    while current is not None and id(current) not in seen:
        seen.add(id(current))
        if isinstance(current, OSError) and problem_errno(current) is not None:
            return current
        current = current.__cause__ or current.__context__
    return None


def name_destination(error: BaseException, destination: str | Path) -> None:
    """Name ``destination`` in the write error of ``error``'s chain when it names no file (a
    failed ``write`` names none): the report then says where the output was to go."""
    found = write_error_in(error)
    if found is not None and found.filename is None:
        found.filename = str(destination)


def describe(
    error: BaseException,
    *,
    fallback: str | Path | None = None,
    elsewhere: str = "",
    then: str = "run the command again",
) -> str | None:
    """``<path>: <what>; <what to do>, then <then>`` for a write error in ``error``'s chain
    (the path: the error's file, else ``fallback``), None for any other error. ``elsewhere``
    names the option that writes somewhere else (e.g. "choose another --out")."""
    found = write_error_in(error)
    if found is None:
        return None
    code = problem_errno(found)
    what, remedy = PROBLEMS[code]
    path = found.filename if found.filename is not None else fallback
    if code in (errno.ENOTDIR, errno.EEXIST) and path is not None:
        path = _file_in_the_way(Path(os.fsdecode(path)))
    remedy = f"{remedy} or {elsewhere}" if elsewhere else remedy
    return f"{path or 'the output folder'}: {what}; {remedy}, then {then}"


def _file_in_the_way(path: Path) -> Path:
    """``path`` or the first of its folders that is a file (what a mkdir stumbled on)."""
    for candidate in (path, *path.parents):
        if candidate.is_dir():
            return path
        if candidate.exists():
            return candidate
    return path


@contextmanager
def reported_write_errors(
    program: str,
    *,
    fallback: str | Path | None = None,
    elsewhere: str = "",
    then: str = "run the command again",
) -> Iterator[None]:
    """Run the block; a write error (:func:`describe`) becomes ``<program>: error: ...`` on
    stderr and ``SystemExit(EXIT_CODE)``, without a traceback. Other errors propagate."""
    try:
        yield
    except Exception as error:  # KeyboardInterrupt and SystemExit pass untouched
        message = describe(error, fallback=fallback, elsewhere=elsewhere, then=then)
        if message is None:
            raise
        print(f"{program}: error: {message}", file=sys.stderr, flush=True)
        raise SystemExit(EXIT_CODE) from None
