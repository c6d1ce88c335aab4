"""Running a command as users run it, optionally with a fault injected (sitecustomize.py here):
a fresh process, from the working directory given, without the test process's PYTHON* settings."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

FAULTS = Path(__file__).parent
CONSOLE = Path(sys.executable).parent / "intermask"  # the console script of this environment
PYTHON = sys.executable


def run_command(
    command: list[str], cwd: Path, *, fault: str | None = None, timeout: float = 600
) -> subprocess.CompletedProcess:
    """``command`` in a fresh process from ``cwd``; ``fault``: an ``INTERMASK_TEST_FAULT`` spec
    (``<ERRNO>:<n>:<glob>``, see sitecustomize.py)."""
    environment = {
        key: value
        for key, value in os.environ.items()
        if not key.startswith("PYTHON") and key != "INTERMASK_TEST_FAULT"
    }
    if fault is not None:
        environment |= {"PYTHONPATH": str(FAULTS), "INTERMASK_TEST_FAULT": fault}
    return subprocess.run(
        [str(part) for part in command],
        cwd=cwd,
        env=environment,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def leftovers(folder: Path) -> list[str]:
    """Temporary files and folders (``*.partial``) anywhere under ``folder``."""
    return sorted(str(path) for path in folder.rglob("*.partial"))
