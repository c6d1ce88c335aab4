"""Fault injection for the subprocesses of tests/test_write_faults.py; not part of the package.

With this folder on PYTHONPATH, Python imports the module at start-up (``site``), and
``INTERMASK_TEST_FAULT=<ERRNO>:<n>:<glob>`` (e.g. ``ENOSPC:2:*/animation.gif``) makes the n-th
``write`` to files opened for writing whose absolute path matches ``<glob>`` (counted over all of
them) raise ``OSError(<ERRNO>)`` without a file name, as a failing write(2) does; ``n = 0`` makes
opening such a file fail (with its name, as open(2) does). Only Python-level writes are seen:
``builtins.open`` and ``io.open`` (pathlib, numpy, PIL, torch.save to a handle, OmegaConf) are
wrapped; a C library writing to the descriptor itself is not. Without the variable nothing is
touched.
"""

from __future__ import annotations

import builtins
import errno
import fnmatch
import io
import os

SPEC = os.environ.get("INTERMASK_TEST_FAULT")


class _FaultyFile:
    """A file object whose writes count toward the fault; everything else is the real file's."""

    def __init__(self, handle, fault):
        object.__setattr__(self, "_handle", handle)
        object.__setattr__(self, "_fault", fault)

    def write(self, data):
        self._fault()
        return self._handle.write(data)

    def writelines(self, lines):
        for line in lines:
            self.write(line)

    def __getattr__(self, name):
        return getattr(self._handle, name)

    def __setattr__(self, name, value):
        setattr(self._handle, name, value)

    def __enter__(self):
        return self

    def __exit__(self, *exc_info):
        self._handle.close()

    def __iter__(self):
        return iter(self._handle)


def install(spec: str) -> None:
    name, nth, pattern = spec.split(":", 2)
    code, nth = getattr(errno, name), int(nth)
    writes = [0]
    real_open = builtins.open

    def fault() -> None:
        writes[0] += 1
        if writes[0] == nth:
            raise OSError(code, os.strerror(code))

    def faulty_open(file, mode="r", *args, **kwargs):
        writing = not isinstance(file, int) and any(flag in mode for flag in "wax+")
        if not writing or not fnmatch.fnmatch(os.path.abspath(os.fsdecode(file)), pattern):
            return real_open(file, mode, *args, **kwargs)
        if nth == 0:
            raise OSError(code, os.strerror(code), os.fsdecode(file))
        return _FaultyFile(real_open(file, mode, *args, **kwargs), fault)

    builtins.open = io.open = faulty_open


if SPEC:
    install(SPEC)
