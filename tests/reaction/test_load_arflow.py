"""load_arflow: the errors that name what is wrong with a run folder (loading itself is covered
by the reaction protocol test in tests/test_evaluate.py)."""

from __future__ import annotations

import pytest

from intermask.reaction.load import load_arflow


def test_missing_checkpoint_and_run_config_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="no checkpoints/last.ckpt inside"):
        load_arflow(tmp_path)
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "last.ckpt").write_bytes(b"")
    with pytest.raises(FileNotFoundError, match=r"config.yaml: the run config of the ARFlow"):
        load_arflow(tmp_path)


def test_a_run_of_another_job_is_refused(tmp_path):
    (tmp_path / "checkpoints").mkdir()
    (tmp_path / "checkpoints" / "last.ckpt").write_bytes(b"")
    (tmp_path / "config.yaml").write_text("model:\n  _target_: intermask.vq.module.VQVAEModule\n")
    with pytest.raises(ValueError, match="not a train_arflow run config"):
        load_arflow(tmp_path / "checkpoints" / "last.ckpt")
