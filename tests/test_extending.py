"""docs/extending.md as a user follows it: the files written as the page gives them, the commands
run as the page gives them (bash, in a project folder laid out as a clone after ``make demo``,
with small stand-ins for the demo's runs and data). The evaluation's ``rows`` seam itself, with
its errors, is tested in tests/evaluation/test_user_rows.py."""

from __future__ import annotations

import ast
import json
import math
import os
import re
import subprocess
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "extending.md"
# a file of the tutorial: its path in bold on a line of its own, then its fenced block
FILE_BLOCK = re.compile(r"^\*\*(toy/[^*\n]+)\*\*\n\n```[a-z]*\n(.*?)^```", re.S | re.M)
BASH_BLOCK = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)
# the clone's files the page's commands use (make's install target is a no-op on a built .venv)
CLONE_FILES = ("Makefile", "pyproject.toml", "uv.lock", ".venv")


def page_files() -> dict[str, str]:
    return dict(FILE_BLOCK.findall(PAGE.read_text()))


def page_commands() -> list[str]:
    return BASH_BLOCK.findall(PAGE.read_text())


def test_the_page_gives_every_file_it_lists_and_each_parses():
    text = PAGE.read_text()
    listed = re.findall(r"^\| `(toy/[^`]+)` \|", text, re.M)
    files = page_files()
    assert listed and sorted(listed) == sorted(files)
    for path, source in files.items():
        if path.endswith(".py"):
            ast.parse(source, filename=path)
        else:
            assert isinstance(yaml.safe_load(source), dict), path
    assert len(page_commands()) == 1  # one block: what test_the_tutorial_runs_as_written runs


def _clone_after_demo(project: Path) -> None:
    """``project`` as a clone after ``make demo``: the clone's Makefile and environment, the
    demo's synthetic data (700 clips here: 70 test clips, two evaluation batches of 32, as
    Diversity's 64 pairs need) and tiny evaluator, tokenizer and generator runs in outputs/demo."""
    from test_runs_move import _gen_config
    from test_train_evaluator import TINY_INTERCLIP
    from test_train_evaluator import _config as evaluator_config
    from test_train_vq import _config as vq_config

    from intermask.data.synthetic import generate_dataset
    from intermask.train import train

    project.mkdir()
    assert (REPO / ".venv").is_dir(), "no .venv beside the Makefile: run make install first"
    for name in CLONE_FILES:
        (project / name).symlink_to(REPO / name)
    data = project / "data" / "synthetic" / "interhuman"
    generate_dataset(data, format="interhuman", clips=700, seed=0)
    demo = project / "outputs" / "demo"
    train(vq_config(data, demo / "vq"))
    train(_gen_config(data, demo / "vq" / "checkpoints" / "last.ckpt", demo / "gen"))
    train(evaluator_config("synthetic", data, demo / "evaluator", TINY_INTERCLIP))


@pytest.mark.slow  # trains the toy for 4 epochs and runs the demo's 5-replication protocol (~3 min)
def test_the_tutorial_runs_as_written(tmp_path):
    project = tmp_path / "clone"
    _clone_after_demo(project)
    for path, source in page_files().items():
        (project / path).parent.mkdir(parents=True, exist_ok=True)
        (project / path).write_text(source)
    environment = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MAKEFLAGS")}
    environment.pop("ARGS", None)  # as a user types it, not under `make test ARGS=...`
    for block in page_commands():
        done = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", block],
            cwd=project,
            env=environment,
            capture_output=True,
            text=True,
            timeout=1800,
        )
        assert done.returncode == 0, done.stderr[-4000:]

    run = project / "outputs" / "caption_regression"
    assert (run / "checkpoints" / "last.ckpt").is_file()
    assert list((run / "tensorboard").rglob("events.out.tfevents.*"))
    results = json.loads((project / "outputs" / "eval_toy" / "results.json").read_text())
    rows = results["rows"]
    assert list(rows) == [
        "Ground Truth",
        "VQ-VAE reconstruction",
        "InterMask",
        "Caption regression",
    ]
    toy = {name: summary["mean"] for name, summary in rows["Caption regression"].items()}
    for name in ("top1", "top3", "fid", "mm_dist", "diversity", "multimodality"):
        assert math.isfinite(toy[name]), name
    assert 0.0 <= toy["top1"] <= toy["top3"] <= 1.0
    assert toy["multimodality"] > 0.0  # its noise draws differ per generation
    assert results["header"]["replications"] == 5  # eval_demo's protocol
    recorded = results["header"]["rows.caption_regression"]
    assert recorded == {
        "_target_": "toy_regression.load_row",
        "checkpoint": "outputs/caption_regression",
        "name": "Caption regression",
    }
    table = (project / "outputs" / "eval_toy" / "results.md").read_text()
    assert "| Caption regression |" in table and "| InterMask |" in table
