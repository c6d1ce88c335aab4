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
