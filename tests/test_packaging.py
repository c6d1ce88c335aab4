"""The wheel runs outside the checkout: built here, installed into a fresh environment, it runs
``intermask --help`` and a composed training job from an empty folder, reading the configs it
ships (``intermask/_configs``), not the checkout's."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _uv() -> list[str]:
    found = shutil.which("uv")
    return [found] if found else [sys.executable, "-m", "uv"]


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """A fresh environment holding only the wheel; its dependencies come from this
    environment's site-packages through a path file (nothing downloaded, no editable hook)."""
    work = tmp_path_factory.mktemp("wheel")
    subprocess.run(
        [sys.executable, "-m", "hatchling", "build", "-t", "wheel", "-d", str(work / "dist")],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    (wheel,) = (work / "dist").glob("intermask-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "intermask/_configs/train_vq.yaml" in names and "callbacks/preemption.py" in names
    env = work / "env"
    venv.EnvBuilder(with_pip=False).create(env)
    python = env / "bin" / "python"
    site = subprocess.run(
        [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout.strip()
    Path(site, "dependencies.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run(
        [*_uv(), "pip", "install", "--no-deps", "--offline", "--python", str(python), str(wheel)],
        check=True,
        capture_output=True,
    )
    return env


def _run(env: Path, folder: Path, *args: str) -> subprocess.CompletedProcess:
    environment = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    environment["OMP_NUM_THREADS"] = "1"
    return subprocess.run(args, cwd=folder, env=environment, capture_output=True, text=True)


def test_the_installed_command_runs_from_an_empty_folder(installed, tmp_path):
    where = _run(
        installed,
        tmp_path,
        str(installed / "bin" / "python"),
        "-c",
        "import intermask, intermask.config_files as c; print(intermask.__file__); print(c.config_dir())",
    )
    assert where.returncode == 0, where.stderr
    package, configs = where.stdout.split()
    assert package.startswith(str(installed)) and configs.endswith("intermask/_configs")
    done = _run(installed, tmp_path, str(installed / "bin" / "intermask"), "--help")
    assert done.returncode == 0, done.stderr
    assert "generate" in done.stdout


def test_a_composed_job_trains_from_an_empty_folder(installed, tmp_path, synthetic_interhuman_root):
    done = _run(
        installed,
        tmp_path,
        str(installed / "bin" / "python"),
        "-m",
        "intermask.train",
        "--config-name",
        "train_vq",
        f"data.root={synthetic_interhuman_root}",
        "debug=vq",  # the shipped configs/debug group
        "+trainer.fast_dev_run=2",
        "callbacks.sample_animations=null",
        f"hydra.run.dir={tmp_path / 'run'}",
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "VQVAEModule" in (tmp_path / "run" / "train.log").read_text()
    assert not (tmp_path / "configs").exists()  # nothing copied next to the job
