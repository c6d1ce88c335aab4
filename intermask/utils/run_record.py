"""What every run writes next to its outputs: resolved config, git revision, environment.

A result is only as trustworthy as our ability to say which code, configuration and package
versions produced it, so every job calls :func:`write_run_record` before doing work.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from datetime import UTC, datetime
from importlib import metadata
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf

RECORDED_PACKAGES = (
    "intermask",
    "torch",
    "torchvision",
    "lightning",
    "torchmetrics",
    "hydra-core",
    "omegaconf",
    "tensorboard",
    "open_clip_torch",
    "scipy",
    "numpy",
    "h5py",
    "einops",
)


def _git(*args: str, cwd: Path) -> str:
    return subprocess.run(
        ["git", *args], cwd=cwd, capture_output=True, text=True, check=True, timeout=10
    ).stdout.strip()


def git_revision(repo_dir: Path | None = None) -> str:
    """Commit hash of the checkout, with ``-dirty`` when tracked files differ; ``unknown`` outside git."""
    cwd = repo_dir or Path(__file__).resolve().parents[2]
    try:
        commit = _git("rev-parse", "HEAD", cwd=cwd)
        dirty = _git("status", "--porcelain", "--untracked-files=no", cwd=cwd)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return f"{commit}-dirty" if dirty else commit


def package_versions(names: tuple[str, ...] = RECORDED_PACKAGES) -> dict[str, str]:
    """Installed version of each distribution (``not installed`` when absent)."""
    versions = {}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def write_run_record(
    output_dir: Path | str,
    config: DictConfig | dict[str, Any] | None = None,
    extra: dict[str, Any] | None = None,
    *,
    folder: Path | str | None = None,
) -> Path:
    """Write ``config.yaml`` (resolved) and ``run_record.json`` into ``output_dir``; return the
    json path. The record names the working directory and the run folder (``folder``, where the
    run will live when it is written into a staging folder first): what lets a moved run find
    its dependencies (:mod:`intermask.utils.run_location`)."""
    output_dir = Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    if config is not None:
        if not isinstance(config, DictConfig):
            config = OmegaConf.create(config)
        (output_dir / "config.yaml").write_text(OmegaConf.to_yaml(config, resolve=True))
    record = {
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "command": sys.argv,
        "cwd": os.getcwd(),
        "output_dir": os.path.abspath(folder or output_dir),
        "git_revision": git_revision(),
        "python": sys.version.split()[0],
        "platform": platform.platform(),
        "packages": package_versions(),
        **(extra or {}),
    }
    path = output_dir / "run_record.json"
    path.write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
    return path
