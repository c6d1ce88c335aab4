"""Animated samples in TensorBoard: a fixed set of prompts (generator) or fixed validation clips
(VQ-VAE, ground truth beside its reconstruction), every ``every_n_epochs`` validations.

Animations are logged as GIF image summaries, which TensorBoard's image tab plays; the decoded
joint statistics go next to them as scalars. Rank zero only; the metrics of the modules are not
touched. Every GIF is a glance, not a record: at most ``max_frames`` frames drawn at ``gif_fps``
(every k-th frame of the data, k = round(fps / gif_fps)) and ``size`` pixels, so that the images
do not swamp a run's event file (``animation_joints``; the defaults are in
``configs/callbacks/sample_animations.yaml``).
"""

from __future__ import annotations

import logging
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback
from PIL import Image

log = logging.getLogger(__name__)


def gif_summary(tag: str, images: Sequence[Image.Image], *, fps: float):
    """-> a TensorBoard ``Summary`` holding one animated GIF image (what ``add_video`` writes,
    without its moviepy dependency)."""
    from tensorboard.compat.proto.summary_pb2 import Summary

    from intermask.render import write_gif

    with tempfile.TemporaryDirectory() as folder:
        encoded = write_gif(images, Path(folder) / "sample.gif", fps=fps).read_bytes()
    width, height = images[0].size
    image = Summary.Image(height=height, width=width, colorspace=3, encoded_image_string=encoded)
    return Summary(value=[Summary.Value(tag=tag, image=image)])


def animation_joints(
    joints: torch.Tensor, *, fps: float, gif_fps: float, max_frames: int
) -> tuple[torch.Tensor, float]:
    """(T, ...) joints at ``fps`` -> (every k-th frame, at most ``max_frames`` of them; the rate
    they play at, fps / k), k = max(1, round(fps / gif_fps))."""
    stride = max(1, round(fps / gif_fps))
    return joints[::stride][:max_frames], fps / stride


def _experiment_writers(trainer: L.Trainer) -> list[Any]:
    """The SummaryWriters of the trainer's TensorBoard loggers."""
    writers = []
    for logger in trainer.loggers:
        experiment = getattr(logger, "experiment", None)
        if experiment is not None and hasattr(experiment, "_get_file_writer"):
            writers.append(experiment)
    return writers


class SampleAnimations(Callback):
    """Log animations of fixed samples.

    Args:
        prompts: captions the generator animates (ignored for the VQ-VAE).
        seconds: length of the generated samples.
        clips: validation clips the VQ-VAE reconstructs (ground truth drawn grey beside it).
        every_n_epochs: log after every n-th validation (sanity checks never log).
        fps: frame rate of the data; gif_fps: frames per second drawn (every k-th frame of
            the data, k = round(fps / gif_fps)); max_frames: at most this many frames per GIF
            (the rest of the motion is left out); size: (width, height) of a frame in pixels.
        iterations: decoding iterations for the generated samples.
    """

    def __init__(
        self,
        *,
        prompts: Sequence[str] = ("two people shake hands", "one person pushes the other"),
        seconds: float = 3.0,
        clips: int = 2,
        every_n_epochs: int = 1,
        fps: float = 30.0,
        gif_fps: float = 10.0,
        max_frames: int = 30,
        size: tuple[int, int] = (160, 120),
        iterations: int = 10,
    ) -> None:
        if every_n_epochs < 1:
            raise ValueError(f"every_n_epochs must be >= 1, got {every_n_epochs}")
        if fps <= 0 or gif_fps <= 0 or max_frames < 1:
            raise ValueError(
                f"need fps > 0, gif_fps > 0 and max_frames >= 1, got {fps}, {gif_fps}, {max_frames}"
            )
        self.prompts, self.seconds, self.clips = list(prompts), seconds, clips
        self.every_n_epochs, self.fps, self.size = every_n_epochs, fps, tuple(size)
        self.gif_fps, self.max_frames = gif_fps, max_frames
        self.iterations = iterations

    def on_validation_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if trainer.sanity_checking or not trainer.is_global_zero:
            return
        if trainer.current_epoch % self.every_n_epochs:
            return
        writers = _experiment_writers(trainer)
        if not writers:
            return
        with torch.no_grad():
            animations = self._animations(trainer, pl_module)
        step = trainer.global_step
        from intermask.render import render_frames

        for tag, joints, reference in animations:
            joints, rate = animation_joints(
                joints, fps=self.fps, gif_fps=self.gif_fps, max_frames=self.max_frames
            )
            images = render_frames(
                joints, caption=tag, size=self.size, reference_person=reference, fps=rate
            )
            summary = gif_summary(f"samples/{tag}", images, fps=rate)
            for writer in writers:
                writer._get_file_writer().add_summary(summary, step)

    def _animations(self, trainer, pl_module) -> list[tuple[str, torch.Tensor, int | None]]:
        if hasattr(pl_module, "sampler"):
            return self._generated(pl_module)
        if hasattr(pl_module, "net") and hasattr(pl_module.net, "view"):
            return self._reconstructed(trainer, pl_module)
        log.warning("SampleAnimations: %s is neither a generator nor a VQ-VAE", type(pl_module))
        return []

    def _generated(self, pl_module) -> list[tuple[str, torch.Tensor, int | None]]:
        frames = int(self.seconds * self.fps) // 4 * 4
        lengths = torch.full((len(self.prompts),), frames)
        out = pl_module.sampler(iterations=self.iterations)(
            self.prompts, lengths, seeds=list(range(len(self.prompts)))
        )
        if out.joints is None:
            return []
        return [(p, out.joints[i].cpu(), None) for i, p in enumerate(self.prompts)]

    def _reconstructed(self, trainer, pl_module) -> list[tuple[str, torch.Tensor, int | None]]:
        dataset = trainer.datamodule.datasets.get("val") if trainer.datamodule else None
        if dataset is None or len(dataset) == 0:
            return []
        vq = pl_module.net
        count = min(self.clips, len(dataset))
        step = max(1, len(dataset) // count)
        items = [dataset[i * step] for i in range(count)]
        motion = torch.stack([item["motion"] for item in items]).to(pl_module.device).float()
        if motion.ndim != 3:
            return []  # two-person windows: the interaction-level ablation
        frames = motion.shape[1] - motion.shape[1] % 4
        motion = motion[:, :frames]
        real = vq.view.geometry(motion).positions
        predicted = vq.view.geometry(vq(motion).reconstruction).positions
        if real is None:
            return []
        # ground truth (person 1, grey) and the reconstruction (person 2) overlaid
        pairs = torch.stack([real, predicted], dim=2)  # (N, T, 2, 22, 3)
        return [(f"reconstruction_{i}", pairs[i].cpu(), 0) for i in range(count)]
