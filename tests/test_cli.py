"""The `intermask data ...` commands, called through the console-script entry point."""

from __future__ import annotations

import json

import numpy as np

from intermask.cli import main


def test_synth_check_stats_item_round_trip(tmp_path, capsys):
    root = tmp_path / "ih"
    assert (
        main(
            [
                "data",
                "synth",
                "--out",
                str(root),
                "--format",
                "interhuman",
                "--clips",
                "12",
                "--seed",
                "3",
            ]
        )
        == 0
    )
    assert "12 synthetic interhuman clips" in capsys.readouterr().out
    record = json.loads((root / "run_record.json").read_text())
    assert record["job"] == "data synth" and record["seed"] == 3 and "torch" in record["packages"]

    assert main(["data", "check", str(root)]) == 0
    assert "no problems found" in capsys.readouterr().out

    assert main(["data", "stats", str(root)]) == 0
    mean, std = np.load(root / "stats" / "mean.npy"), np.load(root / "stats" / "std.npy")
    assert mean.shape == std.shape == (262,) and (std > 0).all()
    assert main(["data", "stats", str(root), "--out", str(tmp_path / "elsewhere")]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "elsewhere" / "std.npy"), std)

    clip = (root / "split" / "test.txt").read_text().split()[0]
    out = tmp_path / "clip.npz"
    assert (
        main(["data", "item", str(root), "--split", "test", "--id", clip, "--out", str(out)]) == 0
    )
    item = np.load(out)
    length = int(item["length"])
    assert item["features"].shape == (2, length, 262) and item["joints"].shape == (length, 2, 22, 3)
    np.testing.assert_allclose(
        item["joints"][0, 0, 0, [0, 2]], 0.0, atol=1e-5
    )  # person 1 root at origin
    assert len(item["captions"]) == 3


def test_check_reports_every_problem_and_fails(tmp_path, capsys):
    root = tmp_path / "ix"
    main(
        ["data", "synth", "--out", str(root), "--format", "interx", "--clips", "10", "--seed", "1"]
    )
    train_ids = (root / "splits" / "train.txt").read_text().split()
    captions = [root / "texts_processed" / f"{name}.txt" for name in train_ids[:2]]
    captions[0].unlink()
    captions[1].write_text("")
    capsys.readouterr()
    assert main(["data", "check", str(root)]) == 1
    out, err = capsys.readouterr()
    assert captions[0].name in out and captions[1].name in out
    assert "2 problem(s)" in err


def test_unknown_root_is_a_one_line_error(tmp_path, capsys):
    assert main(["data", "check", str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("intermask data: error:") and "nowhere" in err and "Traceback" not in err


def test_the_generate_help_gives_the_values_of_the_configs(monkeypatch, tmp_path):
    """The help's defaults are read from configs/generate.yaml and configs/sampler/ (their one
    owner): a changed config changes the help."""
    import argparse
    import shutil

    import intermask.config_files
    from intermask.cli import build_parser

    def generate_help() -> str:
        parser = build_parser()
        commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        return " ".join(commands.choices["generate"].format_help().split())

    shipped = generate_help()
    # as a user reads it: the console script in a fresh process, from another folder
    import subprocess
    import sys
    from pathlib import Path

    script = Path(sys.executable).parent / "intermask"
    done = subprocess.run(
        [str(script), "generate", "--help"], cwd=tmp_path, capture_output=True, text=True
    )
    assert done.returncode == 0 and " ".join(done.stdout.split()) == shipped
    for text in (
        "length in seconds (default 4)",
        "samples per forward batch (32)",
        "decoding iterations (20; reaction 12; MoMask 10)",
        "guidance scale (2; MoMask: the masked transformer's, 4)",
        "frame rate of the dataset (30; MoMask 20)",
        "(default together)",
    ):
        assert text in shipped, text
    configs = tmp_path / "configs"
    shutil.copytree(intermask.config_files.config_dir(), configs)
    for name, old, new in (
        ("generate.yaml", "seconds: 4.0", "seconds: 6.5"),
        ("generate.yaml", "reaction_iterations: 12", "reaction_iterations: 9"),
        ("sampler/paper.yaml", "iterations: 20", "iterations: 25"),
        ("sampler/paper.yaml", "cfg_scale: 2.0", "cfg_scale: 2.5"),
        ("sampler/momask.yaml", "iterations: 10", "iterations: 12"),
    ):
        path = configs / name
        assert old in path.read_text(), (name, old)
        path.write_text(path.read_text().replace(old, new, 1))
    monkeypatch.setattr(intermask.config_files, "config_dir", lambda: configs)
    changed = generate_help()
    assert "length in seconds (default 6.5)" in changed
    assert "decoding iterations (25; reaction 9; MoMask 12)" in changed
    assert "guidance scale (2.5; MoMask: the masked transformer's, 4)" in changed
