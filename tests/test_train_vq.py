"""The train_vq job end to end on a small synthetic dataset: compose, fit, checkpoint, resume."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from lightning.pytorch import Callback
from omegaconf import open_dict
from PIL import Image

from intermask.train import CONFIG_DIR, train


def _config(data_root: Path, output_dir: Path, overrides: list[str] = (), data: str = "synthetic"):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(
            "train_vq",
            overrides=[
                f"data={data}",
                f"data.root={data_root}",
                "debug=vq",
                *overrides,
            ],
        )
    with open_dict(cfg):
        cfg.paths.output_dir = str(output_dir)
    return cfg


def test_train_vq_writes_record_checkpoints_and_tensorboard(
    synthetic_interhuman_root, tmp_path, caplog
):
    with caplog.at_level("INFO", logger="intermask.train"):
        metrics = train(_config(synthetic_interhuman_root, tmp_path))
    assert re.search(r"VQVAEModule: \d+\.\d\dM parameters", caplog.text)
    assert "effective batch 16 = 16 per process x 1 process(es) x 1 accumulated" in caplog.text
    assert metrics["val/mpjpe_mm"] > 0 and torch.isfinite(torch.tensor(metrics["train/loss"]))
    assert (tmp_path / "config.yaml").is_file() and (tmp_path / "run_record.json").is_file()
    precision = json.loads((tmp_path / "run_record.json").read_text())["precision"]
    assert precision["requested"] == "auto" and precision["precision"] in ("32-true", "bf16-mixed")
    assert f"precision: {precision['precision']} ({precision['reason']})" in caplog.text
    assert (tmp_path / "checkpoints" / "last.ckpt").is_file()
    events = list((tmp_path / "tensorboard").rglob("events.out.tfevents.*"))
    assert events, "no TensorBoard event file"
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    accumulator = EventAccumulator(str(events[0].parent))
    accumulator.Reload()
    tags = set(accumulator.Tags()["scalars"])
    expected = {
        "train/reconstruction",
        "train/velocity",
        "train/foot_contact",
        "train/bone_length",
        "train/commitment",
        "codebook/usage_0",
        "codebook/perplexity_0",
        "val/mpjpe_mm",
    }
    assert expected <= tags, expected - tags
    # SampleAnimations: GT beside its reconstruction, an animated GIF TensorBoard plays
    images = accumulator.Tags()["images"]
    assert "samples/reconstruction_0" in images
    image = accumulator.Images("samples/reconstruction_0")[-1]
    gif = image.encoded_image_string
    # one control block per frame: the 64-frame window at 30 fps drawn at 10 fps (every 3rd frame)
    assert gif[:6] == b"GIF89a" and Image.open(io.BytesIO(gif)).n_frames == 22
    assert (image.width, image.height) == (160, 120)
    # the small defaults of configs/callbacks/sample_animations.yaml: 101 kB here (398 kB before)
    assert events[0].stat().st_size < 150_000
    # the checkpoint carries the normalization statistics and loads with weights_only=True
    state = _last(tmp_path)["state_dict"]
    assert bool(state["net.view.has_statistics"]) and state["net.view.std"].shape == (262,)
    assert bool(state["net.quantizer.layers.0.initialized"])


class CrashAtEpoch(Callback):
    """Simulates a job killed at the start of an epoch (after last.ckpt of the previous one)."""

    def __init__(self, epoch: int) -> None:
        self.epoch = epoch

    def on_train_epoch_start(self, trainer, pl_module) -> None:
        if trainer.current_epoch == self.epoch:
            raise RuntimeError("simulated crash")


def _last(path: Path) -> dict:
    return torch.load(path / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=True)


@pytest.mark.slow
def test_resume_from_last_continues_steps_and_schedule(synthetic_interhuman_root, tmp_path):
    epochs = ["trainer.max_epochs=2"]
    train(_config(synthetic_interhuman_root, tmp_path / "uninterrupted", epochs))
    crash = ["+callbacks.crash._target_=test_train_vq.CrashAtEpoch", "+callbacks.crash.epoch=1"]
    with pytest.raises(RuntimeError, match="simulated crash"):
        train(_config(synthetic_interhuman_root, tmp_path / "crashed", epochs + crash))
    assert _last(tmp_path / "crashed")["global_step"] == 3
    resume = [f"ckpt_path={tmp_path / 'crashed' / 'checkpoints' / 'last.ckpt'}"]
    train(_config(synthetic_interhuman_root, tmp_path / "resumed", epochs + resume))
    reference, resumed = _last(tmp_path / "uninterrupted"), _last(tmp_path / "resumed")
    assert resumed["global_step"] == reference["global_step"] == 6
    assert (
        resumed["lr_schedulers"][0] == reference["lr_schedulers"][0]
    )  # same point of the same schedule


def test_train_vq_on_interx_selects_by_reconstruction_and_writes_checkpoints(
    synthetic_interx_root, tmp_path, caplog
):
    # the Inter-X view has no positions without a body model, so no val/mpjpe_mm: `monitor: auto`
    # selects by val/reconstruction (a fixed val/mpjpe_mm ended every Inter-X run at epoch 0)
    epochs = [
        "trainer.max_epochs=2",
        "trainer.limit_train_batches=2",
        "trainer.limit_val_batches=1",
    ]
    cfg = _config(synthetic_interx_root, tmp_path, epochs, data="synthetic_interx")
    with caplog.at_level("INFO", logger="intermask.train"):
        metrics = train(cfg)
    assert "best checkpoint by val/reconstruction" in caplog.text
    assert "val/mpjpe_mm" not in metrics and metrics["val/reconstruction"] > 0
    names = sorted(p.name for p in (tmp_path / "checkpoints").iterdir())
    assert names[-1] == "last.ckpt" and names[0].startswith("best-epoch")
    assert _last(tmp_path)["global_step"] == 4
    saved = (tmp_path / "config.yaml").read_text()
    assert "monitor: val/reconstruction" in saved  # the run's config says what was used
