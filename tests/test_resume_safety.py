"""Resuming reads a checkpoint with weights_only=True whatever the environment, and refuses
URLs unless explicitly allowed: a checkpoint never runs code."""

from __future__ import annotations

import pickle

import pytest
import torch
from payloads import ExecPayload
from test_train_vq import _config

from intermask.train import resume_checkpoint, train
from intermask.utils.checkpoint_files import CorruptCheckpoint


def test_a_url_is_refused_before_any_work(synthetic_interhuman_root, tmp_path):
    cfg = _config(synthetic_interhuman_root, tmp_path / "run", ["ckpt_path=https://x.org/a.ckpt"])
    with pytest.raises(ValueError, match=r"ckpt_path=https://x.org/a.ckpt: refusing to resume"):
        train(cfg)
    assert not (tmp_path / "run").exists()  # nothing written, no run folder to mistake for a run
    assert resume_checkpoint("s3://b/a.ckpt", allow_remote=True) == "s3://b/a.ckpt"


def test_a_missing_checkpoint_is_named():
    with pytest.raises(FileNotFoundError, match=r"ckpt_path=nowhere/last.ckpt: no such checkpoint"):
        resume_checkpoint("nowhere/last.ckpt")
    assert resume_checkpoint(None) is None


def test_a_pickled_payload_is_refused_even_when_the_environment_asks_for_full_unpickling(
    synthetic_interhuman_root, tmp_path, monkeypatch
):
    marker = tmp_path / "marker"
    evil = tmp_path / "evil.ckpt"
    torch.save({"state_dict": {}, "epoch": ExecPayload(marker)}, evil)
    monkeypatch.setenv("TORCH_FORCE_NO_WEIGHTS_ONLY_LOAD", "1")
    cfg = _config(synthetic_interhuman_root, tmp_path / "run", [f"ckpt_path={evil}"])
    with pytest.raises(pickle.UnpicklingError, match="Weights only load failed"):
        train(cfg)
    assert not marker.exists()


def test_a_truncated_checkpoint_is_refused_by_name(synthetic_interhuman_root, tmp_path):
    broken = tmp_path / "last.ckpt"
    torch.save({"state_dict": {"w": torch.zeros(10_000)}}, broken)
    broken.write_bytes(broken.read_bytes()[:-5000])
    cfg = _config(synthetic_interhuman_root, tmp_path / "run", [f"ckpt_path={broken}"])
    with pytest.raises(CorruptCheckpoint, match=rf"{broken}: not a readable checkpoint"):
        train(cfg)
