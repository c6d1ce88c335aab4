"""Input handling of `intermask generate` that needs no trained checkpoint."""

from __future__ import annotations

import re
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from intermask import generate as gen
from intermask.cli import main
from intermask.generate import interm as interm_job
from intermask.interm.decoding import Decoding
from intermask.vq.views import InterHumanView


def test_lengths_round_down_to_token_steps_and_stay_in_range():
    assert gen.frames_from(seconds=4.0, frames=None, fps=30, max_frames=300) == 120
    assert gen.frames_from(seconds=None, frames=123, fps=30, max_frames=300) == 120
    with pytest.raises(ValueError, match=r"length 330 frames is out of range: .*8\.\.300 frames"):
        gen.frames_from(seconds=11.0, frames=None, fps=30, max_frames=300)
    with pytest.raises(ValueError, match="either in seconds or in frames"):
        gen.frames_from(seconds=1.0, frames=30, fps=30, max_frames=300)


def test_edit_region_covers_the_token_steps_of_the_frames():
    region = gen.edit_region(10, (6, 17), person=2, rows=5)
    assert region.shape == (2, 5, 10)
    assert not region[0].any()
    assert region[1, :, 1:5].all() and not region[1, :, 0].any() and not region[1, :, 5:].any()
    assert gen.edit_region(10, (0, 40), person=None, rows=5).all()
    with pytest.raises(ValueError, match=r"edit frames 30:50 must satisfy 0 <= A < B <= 40"):
        gen.edit_region(10, (30, 50), person=None, rows=5)


def test_prompts_file_is_read_line_by_line(tmp_path):
    path = tmp_path / "prompts.txt"
    path.write_text("two people hug\n\n  one waves, the other bows  \n")
    assert gen.read_prompts(path) == ["two people hug", "one waves, the other bows"]
    path.write_text("\n \n")
    with pytest.raises(ValueError, match="no prompt in the file"):
        gen.read_prompts(path)


def _interhuman_generator():
    view = InterHumanView(mean=torch.zeros(262), std=torch.ones(262))
    return SimpleNamespace(
        vq=SimpleNamespace(view=view),
        config=SimpleNamespace(data=SimpleNamespace(dataset="interhuman")),
    )


def test_motion_files_are_checked(tmp_path):
    generator = _interhuman_generator()
    good = tmp_path / "pair.npy"
    np.save(good, np.zeros((2, 42, 262), dtype=np.float32))
    assert gen.load_motion_file(good, generator).shape == (2, 40, 262)  # cropped to 4k frames
    single = tmp_path / "one.npy"
    np.save(single, np.zeros((16, 262), dtype=np.float32))
    assert gen.load_motion_file(single, generator).shape == (1, 16, 262)
    wrong = tmp_path / "joints.npy"
    np.save(wrong, np.zeros((16, 22, 3), dtype=np.float32))
    with pytest.raises(
        ValueError, match=r"joints.npy: expected features .*got shape \(16, 22, 3\)"
    ):
        gen.load_motion_file(wrong, generator)
    corrupt = tmp_path / "corrupt.npy"
    corrupt.write_bytes(b"not numpy")
    with pytest.raises(ValueError, match="corrupt.npy: not a readable .npy motion file"):
        gen.load_motion_file(corrupt, generator)
    nan = tmp_path / "nan.npy"
    np.save(nan, np.full((16, 262), np.nan, dtype=np.float32))
    with pytest.raises(ValueError, match="finite values"):
        gen.load_motion_file(nan, generator)
    with pytest.raises(FileNotFoundError, match="missing.npy: motion file not found"):
        gen.load_motion_file(tmp_path / "missing.npy", generator)


def test_cli_reports_an_unknown_checkpoint(tmp_path, capsys):
    code = main(["generate", "--checkpoint", str(tmp_path / "nope.ckpt"), "--text", "hi"])
    assert code == 2
    assert "nope.ckpt: generator checkpoint not found" in capsys.readouterr().err
    code = main(["generate", "--checkpoint", str(tmp_path), "--text", "hi"])
    assert (
        "not a generator checkpoint and no checkpoints/last.ckpt inside" in capsys.readouterr().err
    )


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("--samples", "0", "expected an integer >= 1, got 0"),
        ("--batch-size", "-1", "expected an integer >= 1, got -1"),
        ("--iterations", "0", "expected an integer >= 1, got 0"),
        ("--revisits", "-1", "expected an integer >= 0, got -1"),
        ("--partner-scale", "-0.5", "expected a finite number >= 0, got -0.5"),
        ("--remask-noise", "-1", "expected a finite number >= 0, got -1"),
        ("--seconds", "nan", "expected a finite number > 0, got nan"),
        ("--seconds", "-2", "expected a finite number > 0, got -2"),
        ("--temperature", "inf", "expected a finite number > 0, got inf"),
        ("--cfg-scale", "-1", "expected a finite number >= 0, got -1"),
        ("--top-k", "5", r"expected a ratio in \(0, 1\], got 5"),
        ("--top-k", "nan", r"expected a ratio in \(0, 1\], got nan"),
        (
            "--schedule",
            "momask",
            r"invalid choice: 'momask' \(choose from '?paper'?, '?reference'?\)",
        ),
        (
            "--persons",
            "alone",
            r"invalid choice: 'alone' \(choose from '?together'?, '?in_turn'?\)",
        ),
    ],
)
def test_cli_numbers_are_checked_before_any_work(tmp_path, capsys, option, value, message):
    argv = ["generate", "--checkpoint", str(tmp_path / "nope.ckpt"), "--text", "hi"]
    with pytest.raises(SystemExit) as exit_info:
        main([*argv, option, value])
    assert exit_info.value.code == 2
    assert re.search(rf"argument {option}: {message}", capsys.readouterr().err)


def test_cli_refuses_a_file_as_output_folder(tmp_path, capsys):
    target = tmp_path / "results.txt"
    target.write_text("keep me")
    argv = ["generate", "--checkpoint", str(tmp_path / "nope.ckpt"), "--text", "hi"]
    with pytest.raises(SystemExit):
        main([*argv, "--out", str(target)])
    assert f"{target} exists and is not a folder" in capsys.readouterr().err
    assert target.read_text() == "keep me"


def test_an_inter_m_job_decodes_with_the_config_and_the_settings_given():
    """The sampler config whole (a reaction: its own iterations), the settings given replacing
    single keys; a rule they break is said in the options' words, before any work."""
    defaults = gen.default_settings()
    paper = Decoding(**defaults["sampler"])
    assert interm_job.decoding(gen.Request(checkpoint="run"), defaults) == paper
    given = gen.Request(checkpoint="run", reaction="a.npy", sampler={"cfg_scale": 3.0})
    assert interm_job.decoding(given, defaults) == replace(paper, iterations=12, cfg_scale=3.0)
    refused = {
        "--revisits 2 needs --persons in_turn, got 'together'": {"revisits": 2},
        "--partner-scale 1.0 needs --persons in_turn or --reaction (one person decoded beside "
        "the other's tokens), got --persons together": {"partner_scale": 1.0},
        "--remask-noise 1.0 draws each sample's noise from its own seed; it needs --noise "
        "per_sample, got --noise reference": {"remask_noise": 1.0, "noise": "reference"},
    }
    for message, sampler in refused.items():
        with pytest.raises(ValueError) as error:
            interm_job.decoding(gen.Request(checkpoint="run", sampler=sampler), defaults)
        assert str(error.value) == message
    reaction = gen.Request(checkpoint="run", reaction="a.npy", sampler={"partner_scale": 1.0})
    assert interm_job.decoding(reaction, defaults).partner_scale == 1.0
