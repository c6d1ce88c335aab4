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


def _existing_run(tmp_path):
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "last.ckpt").write_bytes(b"the previous run's checkpoint")
    return run


def test_a_folder_holding_a_run_is_never_overwritten(synthetic_interhuman_root, tmp_path):
    run = _existing_run(tmp_path)
    last = run / "checkpoints" / "last.ckpt"
    refuse = _config(synthetic_interhuman_root, run, ["existing_run=refuse"])
    with pytest.raises(FileExistsError, match=rf"{last} exists: .*\(existing_run=resume\)"):
        train(refuse)
    other = tmp_path / "other.ckpt"
    torch.save({"state_dict": {}}, other)
    elsewhere = _config(synthetic_interhuman_root, run, [f"ckpt_path={other}"])
    with pytest.raises(FileExistsError, match=rf"Resume it \(ckpt_path={last}\) or choose"):
        train(elsewhere)
    bad = _config(synthetic_interhuman_root, run, ["existing_run=overwrite"])
    with pytest.raises(ValueError, match="existing_run must be one of .*got 'overwrite'"):
        train(bad)
    assert last.read_bytes() == b"the previous run's checkpoint"


@pytest.mark.slow
def test_a_requeued_job_resumes_the_checkpoint_in_its_run_folder(
    synthetic_interhuman_root, tmp_path, caplog
):
    run = tmp_path / "run"
    train(_config(synthetic_interhuman_root, run))  # 1 epoch of 3 steps, then "pre-empted"
    with caplog.at_level("WARNING", logger="intermask.train"):
        train(_config(synthetic_interhuman_root, run, ["trainer.max_epochs=2"]))  # same command
    assert "already holds" in caplog.text and "resuming from it" in caplog.text
    checkpoint = torch.load(run / "checkpoints" / "last.ckpt", weights_only=True)
    assert checkpoint["global_step"] == 6  # continued at step 3, not restarted
