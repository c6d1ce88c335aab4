"""Checkpoint writes survive kills at any instant; broken files are refused by name."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

from intermask.utils.checkpoint_files import (
    CorruptCheckpoint,
    atomic_torch_save,
    read_checkpoint_file,
)
from intermask.utils.checkpoint_io import AtomicCheckpointIO

_WRITER = """
import sys, torch
from intermask.utils.checkpoint_files import atomic_torch_save
path, step = sys.argv[1], 0
while True:
    step += 1
    atomic_torch_save({"step": step, "weights": torch.full((1_500_000,), float(step))}, path)
    print(step, flush=True)
"""


def _other_filesystem_tmp(tmp_path: Path) -> str:
    """A temporary folder on another filesystem than tmp_path when the machine has one."""
    shm = Path("/dev/shm")
    if shm.is_dir() and os.access(shm, os.W_OK) and shm.stat().st_dev != tmp_path.stat().st_dev:
        return str(shm)
    return str(tmp_path)


def test_killed_writers_never_leave_an_unreadable_checkpoint(tmp_path):
    path = tmp_path / "checkpoints" / "last.ckpt"
    environment = {**os.environ, "TMPDIR": _other_filesystem_tmp(tmp_path), "OMP_NUM_THREADS": "1"}
    rng = random.Random(0)
    completed = 0
    for _ in range(4):
        writer = subprocess.Popen(
            [sys.executable, "-c", _WRITER, str(path)],
            env=environment,
            stdout=subprocess.PIPE,
            text=True,
        )
        writer.stdout.readline()  # at least one write finished: the kill lands in a later one
        time.sleep(rng.uniform(0.0, 0.3))
        writer.send_signal(signal.SIGKILL)
        printed = writer.communicate()[0].split()
        writer.wait()
        checkpoint = read_checkpoint_file(path)  # never truncated, never empty
        step = checkpoint["step"]
        assert torch.equal(checkpoint["weights"], torch.full((1_500_000,), float(step)))
        assert step >= int(printed[-1]) if printed else step >= 1  # the last finished write
        completed += 1
    assert completed == 4


def test_a_save_replaces_the_file_and_cleans_orphans(tmp_path):
    path = tmp_path / "last.ckpt"
    orphan = tmp_path / ".last.ckpt.4194305.partial"  # above Linux's largest pid: no such process
    orphan.write_bytes(b"half a checkpoint")
    live = tmp_path / f".last.ckpt.{os.getppid()}.partial"  # a running writer's file stays
    live.write_bytes(b"being written")
    atomic_torch_save({"step": 1}, path)
    AtomicCheckpointIO().save_checkpoint({"step": 2}, path)  # what the Trainer calls
    assert read_checkpoint_file(path) == {"step": 2}
    assert sorted(p.name for p in tmp_path.iterdir()) == [live.name, "last.ckpt"]


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", r"checkpoint is empty \(0 bytes\)"),
        (b"not a checkpoint at all", r"not a torch checkpoint \(23 bytes starting with b'not '\)"),
        (None, r"not a readable checkpoint \(\d+ bytes; "),  # truncated
    ],
)
def test_broken_checkpoints_are_refused_by_name(tmp_path, content, message):
    path = tmp_path / "last.ckpt"
    if content is None:
        atomic_torch_save({"weights": torch.zeros(10_000)}, path)
        content = path.read_bytes()[:-5000]
    path.write_bytes(content)
    with pytest.raises(CorruptCheckpoint, match=rf"{path}: {message}"):
        read_checkpoint_file(path)
    with pytest.raises(FileNotFoundError, match=rf"{tmp_path / 'none.ckpt'}: checkpoint not found"):
        read_checkpoint_file(tmp_path / "none.ckpt")
