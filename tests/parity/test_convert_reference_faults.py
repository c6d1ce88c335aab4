"""``intermask convert-reference`` on a full disk (#54), as users run it: the console script in a
fresh process from another working directory, the generator's checkpoint failing at its second
write (tests/faults/sitecustomize.py). One line names the checkpoint, exit 2, no output and no
staging folder; the same command then converts."""

from __future__ import annotations

import os

import torch
from faults.harness import CONSOLE, leftovers, run_command


def test_a_full_disk_while_converting_leaves_nothing_and_the_same_command_then_works(
    release, tmp_path
):
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    command = [CONSOLE, "convert-reference", "--vq", release["vq_interx"], "--generator",
               release["generator"], "--out", "converted"]  # fmt: skip
    failed = run_command(command, cwd, fault="ENOSPC:2:*/gen/checkpoints/.last.ckpt.*.partial")
    assert failed.returncode == 2, failed.stderr
    checkpoint = cwd / "converted" / "gen" / "checkpoints" / "last.ckpt"
    assert (
        f"intermask convert-reference: error: {checkpoint}: no space left on the device; free "
        "some space there or choose another --out, then run the command again"
    ) in failed.stderr.splitlines(), failed.stderr
    assert "Traceback" not in failed.stderr
    assert os.listdir(cwd) == []  # not even the tokenizer's run, complete in the staging folder
    done = run_command(command, cwd)
    assert done.returncode == 0, done.stderr
    assert sorted(os.listdir(cwd / "converted")) == ["gen", "vq"]
    stored = torch.load(checkpoint, weights_only=True)
    assert stored["hyper_parameters"]["reference_options"]["n_heads"] == "6"
    assert leftovers(cwd) == []
