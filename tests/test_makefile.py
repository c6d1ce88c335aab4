"""What the Makefile picks by default: the newest run that has a checkpoint."""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
def test_runs_without_a_checkpoint_are_never_picked_as_newest(tmp_path):
    runs = {}
    for job in ("train_vq", "train_gen", "train_arflow"):
        older = tmp_path / "outputs" / job / "runs" / "older"
        (older / "checkpoints").mkdir(parents=True)
        (older / "checkpoints" / "last.ckpt").write_bytes(b"x")
        past = time.time() - 60
        os.utime(older / "checkpoints" / "last.ckpt", (past, past))
        # a newer run that died before its first checkpoint (bad data, a kill during setup)
        (tmp_path / "outputs" / job / "runs" / "newer" / "checkpoints").mkdir(parents=True)
        runs[job] = older / "checkpoints" / "last.ckpt"
    printed = subprocess.run(
        ["make", "-s", "-f", str(ROOT / "Makefile"), "checkpoints"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split()
    chosen = dict(line.split("=", 1) for line in printed)
    assert chosen["VQ_CKPT"] == "outputs/train_vq/runs/older/checkpoints/last.ckpt"
    assert chosen["GEN_CKPT"] == "outputs/train_gen/runs/older/checkpoints/last.ckpt"
    assert chosen["ARFLOW_CKPT"] == "outputs/train_arflow/runs/older/checkpoints/last.ckpt"


@pytest.mark.skipif(shutil.which("make") is None, reason="needs make")
@pytest.mark.parametrize("target", ["demo", "demo-momask"])
def test_precision_reaches_every_training_job_of_a_demo_and_nothing_else(target):
    def planned(*variables):  # one line per command: make -n keeps a recipe's continuations
        return (
            subprocess.run(
                ["make", "-n", "-s", "-f", str(ROOT / "Makefile"), target, *variables],
                cwd=ROOT,
                capture_output=True,
                text=True,
                check=True,
            )
            .stdout.replace("\\\n", " ")
            .splitlines()
        )

    jobs = {"demo": 3, "demo-momask": 4}[target]
    forced = planned("PRECISION=32-true")
    trains = [line for line in forced if "-m intermask.train " in line]
    assert len(trains) == jobs
    assert all("trainer.precision=32-true" in line.split() for line in trains), trains
    # the protocol and the samples run without autocast: the switch is for training only
    assert not [
        line for line in forced if "trainer.precision" in line and "-m intermask.train " not in line
    ]
    # without PRECISION the configs' `auto` decides
    assert not [line for line in planned() if "trainer.precision" in line]
