"""SampleAnimations stays small: the GIFs it logs have bounded frames, size and rate (#54)."""

from __future__ import annotations

import io
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
from hydra.utils import instantiate
from omegaconf import OmegaConf
from PIL import Image

from callbacks.samples import SampleAnimations, animation_joints
from intermask.motion.skeleton import rest_pose_positions
from intermask.train import CONFIG_DIR

DEFAULTS = Path(CONFIG_DIR) / "callbacks" / "sample_animations.yaml"


@pytest.mark.parametrize(
    ("frames", "fps", "gif_fps", "max_frames", "expected", "rate"),
    [
        (64, 30.0, 10.0, 30, 22, 10.0),  # a VQ window: every 3rd frame
        (600, 30.0, 10.0, 30, 30, 10.0),  # 20 s: cut at max_frames
        (196, 20.0, 10.0, 30, 30, 10.0),  # HumanML3D: every 2nd frame
        (10, 20.0, 50.0, 30, 10, 20.0),  # never more frames than the data has
    ],
)
def test_animation_joints_bounds(frames, fps, gif_fps, max_frames, expected, rate):
    joints = torch.arange(frames, dtype=torch.float32)[:, None, None, None].expand(-1, 2, 22, 3)
    drawn, played = animation_joints(joints, fps=fps, gif_fps=gif_fps, max_frames=max_frames)
    assert drawn.shape == (expected, 2, 22, 3) and played == rate
    stride = round(fps / gif_fps) if gif_fps < fps else 1
    assert drawn[:, 0, 0, 0].tolist() == list(range(0, stride * expected, stride))


def test_bad_settings_are_refused():
    with pytest.raises(ValueError, match="max_frames >= 1"):
        SampleAnimations(max_frames=0)
    with pytest.raises(ValueError, match="gif_fps > 0"):
        SampleAnimations(gif_fps=0.0)


class _Writer:
    def __init__(self) -> None:
        self.summaries = []

    def _get_file_writer(self):
        return self

    def add_summary(self, summary, step) -> None:
        self.summaries.append((summary, step))


def _generator(frames_seen: list[int]):
    """A stand-in generator module: every prompt walks the rest pose along +X for its length."""

    def sample(prompts, lengths, seeds):
        frames = int(lengths[0])
        frames_seen.append(frames)
        body = rest_pose_positions()[None, None].expand(frames, 2, 22, 3).clone()
        body[..., 0] += torch.linspace(0, 2, frames)[:, None, None]
        body[:, 1, :, 2] += 1.0
        return SimpleNamespace(joints=body[None].expand(len(prompts), -1, -1, -1, -1))

    return SimpleNamespace(sampler=lambda iterations: sample)


def test_default_config_logs_small_gifs():
    """The shipped defaults, through the callback's own path: 3 s generated at 30 fps (90 frames)
    become 30 frames of 160 x 120 played at 10 fps, well under 100 kB per sample."""
    callback = instantiate(OmegaConf.load(DEFAULTS).sample_animations)
    assert (callback.max_frames, callback.size, callback.gif_fps) == (30, (160, 120), 10.0)
    writer, frames_seen = _Writer(), []
    trainer = SimpleNamespace(
        sanity_checking=False,
        is_global_zero=True,
        current_epoch=0,
        global_step=7,
        loggers=[SimpleNamespace(experiment=writer)],
    )
    callback.on_validation_epoch_end(trainer, _generator(frames_seen))
    assert frames_seen == [88]  # 3 s at 30 fps, in whole tokens of 4 frames
    assert len(writer.summaries) == len(callback.prompts) == 3
    for summary, step in writer.summaries:
        image = summary.value[0].image
        gif = Image.open(io.BytesIO(image.encoded_image_string))
        assert step == 7 and (image.width, image.height) == (160, 120)
        assert gif.n_frames <= callback.max_frames and gif.info["duration"] == 100  # 10 fps
        assert len(image.encoded_image_string) < 100_000
