"""Commands that fail for want of space or permission leave nothing half-done (#54).

Each command runs as users run it: the console script or ``python -m``, in a fresh process,
from another working directory. A write fails at the n-th write of a file (ENOSPC, as a full
disk; tests/faults/sitecustomize.py) or the disk really is full (a small tmpfs, as root). The
command says so in one line naming the path and what to do, exits with 2, leaves no partial
output, and the same command then succeeds without any clean-up.
"""

from __future__ import annotations

import errno
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch
from faults.harness import CONSOLE, PYTHON, leftovers, run_command
from test_train_evaluator import TINY_INTERCLIP
from test_train_evaluator import _config as evaluator_config
from test_train_gen import _gen_config
from test_train_vq import _config as vq_config

from intermask.train import train
from intermask.utils.write_errors import EXIT_CODE, describe

FULL = "no space left on the device; free some space there"
ONE_BATCH = ["trainer.limit_train_batches=1", "trainer.limit_val_batches=1"]


@pytest.fixture(scope="module")
def runs(synthetic_interhuman_root, tmp_path_factory) -> dict[str, Path]:
    """Tiny tokenizer, generator and evaluator runs (debug configs), trained in this process."""
    root, data = tmp_path_factory.mktemp("fault_runs"), synthetic_interhuman_root
    train(vq_config(data, root / "vq", ONE_BATCH))
    vq_ckpt = root / "vq" / "checkpoints" / "last.ckpt"
    train(_gen_config(data, vq_ckpt, root / "gen", extra=tuple(ONE_BATCH)))
    train(evaluator_config("synthetic", data, root / "ev", [*TINY_INTERCLIP, *ONE_BATCH]))
    evaluator = sorted((root / "ev" / "checkpoints").glob("best*.ckpt"))[0]
    return {"vq": root / "vq", "gen": root / "gen", "evaluator": evaluator}


def _elsewhere(tmp_path: Path) -> Path:
    folder = tmp_path / "elsewhere"
    folder.mkdir()
    return folder


def _assert_reported(done: subprocess.CompletedProcess, line: str) -> None:
    assert done.returncode == EXIT_CODE, done.stderr
    assert line in done.stderr.splitlines(), done.stderr
    assert "Traceback" not in done.stderr


def _generate(runs: dict[str, Path], out: str) -> list[str]:
    return [CONSOLE, "generate", "--checkpoint", runs["gen"], "--text", "two people hug",
            "--seconds", "1", "--samples", "2", "--iterations", "1", "--out", out]  # fmt: skip


def test_generate_on_a_full_disk_leaves_no_sample_and_the_same_command_then_works(runs, tmp_path):
    """The disk fills in the first GIF, after the arrays and sample.json of both samples."""
    cwd = _elsewhere(tmp_path)
    failed = run_command(_generate(runs, "out"), cwd, fault="ENOSPC:3:*/animation.gif")
    _assert_reported(
        failed,
        f"intermask generate: error: {cwd / 'out'}: {FULL} or choose another --out, then run "
        "the command again",
    )
    assert sorted(p.name for p in cwd.iterdir()) == []  # no sample folder, no staging folder
    done = run_command(_generate(runs, "out"), cwd)
    assert done.returncode == 0, done.stderr
    folders = sorted((cwd / "out").iterdir())
    assert [f.name for f in folders] == ["two_people_hug_00-00", "two_people_hug_00-01"]
    for folder in folders:
        assert np.load(folder / "joints.npy").shape == (28, 2, 22, 3)
        assert (folder / "animation.gif").stat().st_size > 1000
    assert leftovers(cwd) == []


@pytest.mark.parametrize(
    ("fault", "problem"),
    [
        ("EACCES:0:*/features.npy", "permission denied; give yourself write access to it"),
        ("EROFS:0:*/features.npy", "the filesystem is read-only; write to a writable filesystem"),
    ],
)
def test_generate_names_an_unwritable_file_where_it_would_have_been(runs, tmp_path, fault, problem):
    cwd = _elsewhere(tmp_path)
    failed = run_command(_generate(runs, "out"), cwd, fault=fault)
    sample = cwd / "out" / "two_people_hug_00-00" / "features.npy"
    _assert_reported(
        failed,
        f"intermask generate: error: {sample}: {problem} or choose another --out, then run the "
        "command again",
    )
    assert sorted(p.name for p in cwd.iterdir()) == []


def test_generate_under_a_file_names_the_file_in_the_way(runs, tmp_path):
    cwd = _elsewhere(tmp_path)
    (cwd / "results").write_text("keep me")
    failed = run_command(_generate(runs, "results/out"), cwd)
    _assert_reported(
        failed,
        f"intermask generate: error: {cwd / 'results'}: a file is in the way where a folder is "
        "needed; move that file away or choose another --out, then run the command again",
    )
    assert sorted(p.name for p in cwd.iterdir()) == ["results"]
    assert (cwd / "results").read_text() == "keep me"


def _train_vq(data_root: Path, run: Path) -> list[str]:
    return [PYTHON, "-m", "intermask.train", "--config-name", "train_vq", "data=synthetic",
            f"data.root={data_root}", "debug=vq", "trainer.limit_train_batches=1",
            "trainer.limit_val_batches=1", f"hydra.run.dir={run}"]  # fmt: skip


def test_a_checkpoint_that_does_not_fit_stops_training_in_one_line_and_the_run_resumes(
    synthetic_interhuman_root, tmp_path
):
    """The disk fills while Lightning writes the first checkpoint: the run folder keeps Hydra's
    record and the job's log, no partial checkpoint; the same command then trains to the end in
    the same run folder."""
    cwd, run = _elsewhere(tmp_path), tmp_path / "run"
    command = _train_vq(synthetic_interhuman_root, run)
    failed = run_command(command, cwd, fault="ENOSPC:1:*/checkpoints/.*.partial")
    first = sorted(p.name for p in (run / "checkpoints").iterdir())
    assert first == [], first  # neither best-epoch000.ckpt nor its temporary file
    _assert_reported(
        failed,
        f"python -m intermask.train: error: {run / 'checkpoints' / 'best-epoch000.ckpt'}: {FULL} "
        f"or choose another hydra.run.dir, then run the command again (hydra.run.dir={run} "
        "continues from its last checkpoint, if any)",
    )
    assert (run / ".hydra" / "config.yaml").is_file()
    done = run_command(command, cwd)
    assert done.returncode == 0, done.stderr
    stored = torch.load(run / "checkpoints" / "last.ckpt", weights_only=True)
    assert stored["global_step"] == 1
    assert leftovers(run) == [] and sorted(p.name for p in cwd.iterdir()) == []


def test_a_run_folder_under_a_file_is_refused_before_hydra_writes_there(
    synthetic_interhuman_root, tmp_path
):
    """Hydra writes its record before the job runs: the run folder check (a Hydra callback)
    says what is wrong first, and creates nothing."""
    cwd = _elsewhere(tmp_path)
    (tmp_path / "outputs").write_text("keep me")
    failed = run_command(_train_vq(synthetic_interhuman_root, tmp_path / "outputs" / "run"), cwd)
    _assert_reported(
        failed,
        f"python -m intermask.train: error: {tmp_path / 'outputs'}: a file is in the way where "
        "a folder is needed; move that file away or choose another hydra.run.dir, then run the "
        "command again",
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["elsewhere", "outputs"]
    assert (tmp_path / "outputs").read_text() == "keep me" and list(cwd.iterdir()) == []


def _evaluate(data_root: Path, runs: dict[str, Path], out: Path) -> list[str]:
    return [PYTHON, "-m", "intermask.evaluate", "data=synthetic", f"data.root={data_root}",
            "data.num_workers=0", "split=val", "mode=reconstruction",
            f"eval_ckpt={runs['evaluator']}", f"vq_ckpt={runs['vq']}", "fast=true",
            "fast_replications=1", "protocol.eval_batch_size=4", "protocol.diversity_pairs=4",
            f"hydra.run.dir={out}"]  # fmt: skip


def test_an_evaluation_table_that_does_not_fit_is_not_written_and_the_same_command_then_is(
    synthetic_interhuman_root, runs, tmp_path
):
    """The disk fills in results.md, after results.json: neither appears, nor TensorBoard's."""
    cwd, out = _elsewhere(tmp_path), tmp_path / "eval"
    command = _evaluate(synthetic_interhuman_root, runs, out)
    failed = run_command(command, cwd, fault="ENOSPC:1:*/results.md")
    _assert_reported(
        failed,
        f"python -m intermask.evaluate: error: {out}: {FULL} or choose another hydra.run.dir, "
        "then run the command again",
    )
    assert not {"results.json", "results.md", "tensorboard"} & {p.name for p in out.iterdir()}
    assert leftovers(tmp_path) == []
    done = run_command(command, cwd)
    assert done.returncode == 0, done.stderr
    assert json.loads((out / "results.json").read_text())["header"]["mode"] == "reconstruction"
    assert "| VQ-VAE reconstruction |" in (out / "results.md").read_text()
    assert list((out / "tensorboard").glob("events.out.tfevents.*"))
    assert sorted(p.name for p in cwd.iterdir()) == []


def test_data_synth_on_a_full_disk_keeps_the_earlier_dataset_and_then_replaces_it(tmp_path):
    """The disk fills at the last file (README.txt): the earlier dataset stays as it was."""
    cwd = _elsewhere(tmp_path)
    command = [CONSOLE, "data", "synth", "--out", "data", "--format", "interhuman", "--clips"]
    assert run_command([*command, "6"], cwd).returncode == 0
    before = {p: p.read_bytes() for p in (cwd / "data").rglob("*") if p.is_file()}
    failed = run_command([*command, "8"], cwd, fault="ENOSPC:1:*/README.txt")
    _assert_reported(
        failed,
        f"intermask data: error: {cwd / 'data'}: {FULL} or choose another --out, then run the "
        "command again",
    )
    assert {p: p.read_bytes() for p in (cwd / "data").rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in cwd.iterdir()) == ["data"]
    done = run_command([*command, "8"], cwd)
    assert done.returncode == 0, done.stderr
    assert "wrote 8 synthetic interhuman clips" in done.stdout
    assert leftovers(cwd) == [] and sorted(p.name for p in cwd.iterdir()) == ["data"]


def _mount_tmpfs(folder: Path, size: str) -> None:
    folder.mkdir()
    try:
        subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
            check=True,
            capture_output=True,
            text=True,
        )
    except (OSError, subprocess.CalledProcessError) as error:
        reason = getattr(error, "stderr", "") or error
        pytest.skip(f"a small tmpfs is needed (root and mount): {str(reason).strip()}")


def test_generate_on_a_really_full_tmpfs(runs, tmp_path):
    """No injection: PIL, numpy and ffmpeg meet a full 200 KiB tmpfs; freeing space (a larger
    tmpfs) lets the same command through."""
    disk = tmp_path / "disk"
    _mount_tmpfs(disk, "200k")
    try:
        cwd = _elsewhere(tmp_path)
        failed = run_command(_generate(runs, str(disk / "out")), cwd)
        _assert_reported(
            failed,
            f"intermask generate: error: {disk / 'out'}: {FULL} or choose another --out, then "
            "run the command again",
        )
        assert list(disk.iterdir()) == []
        subprocess.run(["mount", "-o", "remount,size=16m", str(disk)], check=True)
        done = run_command(_generate(runs, str(disk / "out")), cwd)
        assert done.returncode == 0, done.stderr
        assert len(list((disk / "out").iterdir())) == 2
    finally:
        subprocess.run(["umount", str(disk)], check=False)


def test_write_errors_are_told_apart_from_other_errors():
    chained = RuntimeError("[enforce fail at inline_container.cc:672] . unexpected pos 704")
    chained.__context__ = OSError(errno.ENOSPC, "No space left on device")
    assert describe(chained, fallback="run") == (f"run: {FULL}, then run the command again")
    short = OSError("200000 requested and 32752 written")  # numpy's tofile: no errno
    assert describe(short, fallback="x.npy", elsewhere="choose another --out").startswith(
        f"x.npy: {FULL} or choose another --out"
    )
    quota = OSError(errno.EDQUOT, "Disk quota exceeded", "/home/me/out/a.npy")
    assert describe(quota).startswith("/home/me/out/a.npy: disk quota exceeded;")
    assert describe(FileNotFoundError(errno.ENOENT, "No such file", "x")) is None
    assert describe(ValueError("bad value")) is None


def test_generate_with_bodies_on_a_full_disk_leaves_no_sample_and_then_works(runs, tmp_path):
    """--body-model writes the bodies into the staged sample folders: a .glb that does not fit
    (after every sample's arrays, renders and fit) leaves no folder; then the command works."""
    from intermask.body.standin import write_standin_model

    models = tmp_path / "models"
    write_standin_model(models, "smplx")
    cwd = _elsewhere(tmp_path)
    command = [*_generate(runs, "out"), "--no-render", "--body-model", models]
    failed = run_command(command, cwd, fault="ENOSPC:1:*/bodies.glb")
    _assert_reported(
        failed,
        f"intermask generate: error: {cwd / 'out'}: {FULL} or choose another --out, then run "
        "the command again",
    )
    assert sorted(p.name for p in cwd.iterdir()) == []
    missing = run_command([*command[:-1], models / "SMPLX_FEMALE.npz"], cwd)
    assert missing.returncode == 2 and "SMPLX_FEMALE.npz" in missing.stderr, missing.stderr
    assert sorted(p.name for p in cwd.iterdir()) == []  # a missing body model: no folder either
    assert missing.stdout == ""  # ... and it is found missing before anything is generated
    done = run_command(command, cwd)
    assert done.returncode == 0, done.stderr
    for folder in sorted((cwd / "out").iterdir()):
        assert (folder / "bodies.glb").stat().st_size > 1000, folder
        assert json.loads((folder / "body_fit.json").read_text())["persons"] == 2
    assert "out/two_people_hug_00-00: body_person1.npz" in done.stdout  # its place, not staged
    assert leftovers(cwd) == []
