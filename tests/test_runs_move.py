"""Run folders that move: a generator run trained with a relative tokenizer path (as
``make train-gen`` passes it) is used from another working directory, after its tree was moved,
and after the tree was copied elsewhere with the original gone; the user commands run as console
scripts in fresh processes. A dependency found nowhere is named with every place looked at."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import open_dict
from test_train_evaluator import TINY_INTERCLIP
from test_train_evaluator import _config as evaluator_config
from test_train_vq import _config as vq_config

from intermask.train import CONFIG_DIR, train
from intermask.utils.run_location import RunLocation

CAPTION = "two people shake hands"
VQ = Path("checkpoints") / "last.ckpt"


def _gen_config(data_root: Path, vq_ckpt: Path, output_dir: Path, extra: tuple[str, ...] = ()):
    with initialize_config_dir(config_dir=CONFIG_DIR, version_base="1.3"):
        cfg = compose(
            "train_gen",
            overrides=[
                "data=synthetic",
                f"data.root={data_root}",
                "debug=gen",
                f"vq_ckpt={vq_ckpt}",  # as given: here relative to the working directory
                *extra,
            ],
        )
    with open_dict(cfg):
        cfg.paths.output_dir = str(output_dir)
    return cfg


@pytest.fixture(scope="module")
def trained(synthetic_interhuman_root, tmp_path_factory) -> dict[str, Path]:
    """A project folder whose tokenizer and generator runs lie in ``outputs/demo``, trained from
    the project folder with relative paths (the text cache ``./data/text_cache`` too), and an
    evaluator trained elsewhere."""
    base = tmp_path_factory.mktemp("moving")
    project = base / "project"
    project.mkdir()
    previous = os.getcwd()
    os.chdir(project)
    try:
        train(vq_config(synthetic_interhuman_root, project / "outputs" / "demo" / "vq"))
        relative_vq = Path("outputs") / "demo" / "vq" / VQ
        train(
            _gen_config(
                synthetic_interhuman_root, relative_vq, project / "outputs" / "demo" / "gen"
            )
        )
    finally:
        os.chdir(previous)
    train(evaluator_config("synthetic", synthetic_interhuman_root, base / "ev", TINY_INTERCLIP))
    evaluator = sorted((base / "ev" / "checkpoints").glob("best*.ckpt"))[0]
    return {"base": base, "project": project, "evaluator": evaluator}


def _intermask(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    script = Path(sys.executable).parent / "intermask"
    return subprocess.run(
        [str(script), *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )


def _generate(run: Path, out: Path, cwd: Path) -> subprocess.CompletedProcess:
    return _intermask(
        "generate", "--checkpoint", str(run), "--text", CAPTION, "--seconds", "1",
        "--samples", "1", "--iterations", "2", "--no-render", "--out", str(out), cwd=cwd,
    )  # fmt: skip


def _recorded_vq(out: Path) -> Path:
    (sample,) = out.iterdir()
    return Path(json.loads((sample / "sample.json").read_text())["vq"]["path"])


def test_a_generator_run_follows_its_tree_wherever_it_goes(trained, tmp_path):
    project, elsewhere = trained["project"], tmp_path / "elsewhere"
    elsewhere.mkdir()
    config = (project / "outputs" / "demo" / "gen" / "config.yaml").read_text()
    assert "vq_ckpt: outputs/demo/vq/checkpoints/last.ckpt" in config  # recorded as given

    # 1. in place, from another working directory: the relative path is the project's
    done = _generate(project / "outputs" / "demo" / "gen", tmp_path / "s1", cwd=elsewhere)
    assert done.returncode == 0, done.stderr
    assert _recorded_vq(tmp_path / "s1") == project / "outputs" / "demo" / "vq" / VQ
    assert not (elsewhere / "data").exists()  # the text cache stayed the project's

    # 2. the tree moved: the tokenizer is found beside the generator, where it was
    moved = tmp_path / "moved" / "demo"
    moved.parent.mkdir()
    shutil.move(project / "outputs" / "demo", moved)
    try:
        done = _generate(moved / "gen", tmp_path / "s2", cwd=elsewhere)
        assert done.returncode == 0, done.stderr
        assert _recorded_vq(tmp_path / "s2") == moved / "vq" / VQ

        # 3. copied to "another machine": the original tree and the project are gone
        copy = tmp_path / "copy" / "runs"
        shutil.copytree(moved, copy)
        gone = [project, moved]  # hidden while the copy is used, restored after
        for path in gone:
            path.rename(path.with_name(path.name + ".hidden"))
        try:
            done = _generate(copy / "gen", tmp_path / "s3", cwd=elsewhere)
        finally:
            for path in gone:
                path.with_name(path.name + ".hidden").rename(path)
        assert done.returncode == 0, done.stderr
        assert _recorded_vq(tmp_path / "s3") == copy / "vq" / VQ
        assert not (elsewhere / "data").exists()  # no cache folder appears in the cwd

        # 4. found nowhere: every place looked at is named, nothing is written
        shutil.rmtree(copy / "vq")
        done = _generate(copy / "gen", tmp_path / "s4", cwd=elsewhere)
        assert done.returncode == 2
        assert (
            "the generator's VQ checkpoint recorded in "
            f"{copy / 'gen' / 'config.yaml'} as 'outputs/demo/vq/checkpoints/last.ckpt' is missing"
        ) in done.stderr
        assert f"looked for {copy / 'vq' / VQ} (relative to the run folder" in done.stderr
        assert f"{project / 'outputs' / 'demo' / 'vq' / VQ} (as the run's command found it)" in (
            done.stderr
        )
        assert "pass vq_checkpoint=" in done.stderr and "Traceback" not in done.stderr
        assert not (tmp_path / "s4").exists()
    finally:
        shutil.move(moved, project / "outputs" / "demo")


def test_a_copied_run_tree_evaluates_and_resumes_from_another_directory(
    trained, synthetic_interhuman_root, tmp_path
):
    copy = tmp_path / "copy"
    shutil.copytree(trained["project"] / "outputs" / "demo", copy)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    done = subprocess.run(
        [sys.executable, "-m", "intermask.evaluate", "data=synthetic",
         f"data.root={synthetic_interhuman_root}", "data.num_workers=0", "split=train",
         "mode=interaction", f"eval_ckpt={trained['evaluator']}", f"gen_ckpt={copy / 'gen'}",
         "fast=true", "fast_replications=2", "protocol.eval_batch_size=8",
         "protocol.diversity_pairs=8", "sampler.iterations=2", f"hydra.run.dir={tmp_path / 'eval'}"],
        cwd=elsewhere, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert results["header"]["vq"].startswith(f"{copy / 'vq' / VQ} (")
    assert not (elsewhere / "data").exists() and not (elsewhere / "outputs").exists()

    # resuming the copied generator run in place, from the other directory
    done = subprocess.run(
        [sys.executable, "-m", "intermask.train", "--config-name", "train_gen", "data=synthetic",
         f"data.root={synthetic_interhuman_root}", "debug=gen", f"vq_ckpt={copy / 'vq' / VQ}",
         "trainer.max_epochs=2", f"hydra.run.dir={copy / 'gen'}"],
        cwd=elsewhere, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    assert "resuming" in done.stderr.lower() + done.stdout.lower()
    record = json.loads((copy / "gen" / "run_record.json").read_text())
    assert record["cwd"] == str(elsewhere) and record["output_dir"] == str(copy / "gen")


def test_candidates_come_from_the_run_folder_first_then_as_recorded(tmp_path):
    run = tmp_path / "now" / "gen"
    location = RunLocation(
        run, cwd=Path("/then/project"), recorded_folder=Path("/then/project/o/gen")
    )
    assert location.candidates("o/vq/last.ckpt") == [
        (tmp_path / "now" / "vq" / "last.ckpt", "relative to the run folder, as when the run was written"),
        (Path("/then/project/o/vq/last.ckpt"), "as the run's command found it"),
        (Path.cwd() / "o" / "vq" / "last.ckpt", "relative to the working directory"),
    ]  # fmt: skip
    # an unknown cwd: both relative paths share it, so the relation still holds
    unknown = RunLocation(run, cwd=None, recorded_folder=Path("out/gen"))
    assert unknown.candidates("out/vq/last.ckpt")[0][0] == tmp_path / "now" / "vq" / "last.ckpt"
    # an absolute run folder and a relative path of an unknown cwd: nothing to relate
    lost = RunLocation(run, cwd=None, recorded_folder=Path("/then/gen"))
    assert lost.candidates("vq/last.ckpt") == [
        (Path.cwd() / "vq" / "last.ckpt", "relative to the working directory")
    ]


def test_a_text_cache_not_written_yet_is_created_where_its_parent_is(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a working directory without data/
    project = tmp_path / "project"
    (project / "data").mkdir(parents=True)
    location = RunLocation(
        tmp_path / "elsewhere" / "gen", cwd=project, recorded_folder=project / "o" / "gen"
    )
    text = {"_target_": "intermask.text.cache.TextFeatureCache", "cache_dir": "data/text_cache"}
    assert location.relocated(text)["cache_dir"] == str(project / "data" / "text_cache")
    lost = RunLocation(tmp_path / "elsewhere" / "gen", cwd=tmp_path / "gone", recorded_folder=None)
    assert lost.relocated(text)["cache_dir"] is None  # nowhere to put it: in memory
