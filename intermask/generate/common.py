"""What every family's generate job shares: the request, the configs' defaults, the length and
captions asked for, the sample folders and the files written in them."""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from intermask.config_files import config_dir
from intermask.utils.files import open_run_checkpoint
from intermask.vq.model import FRAMES_PER_STEP

# longest training clips (multiples of 4); HumanML3D: MoMask's 196 frames
MAX_FRAMES = {"interhuman": 300, "interx": 148, "humanml3d": 196}
# the options that only some family takes -> how the command line spells them, in the order a
# refusal names them (each job lists its own: :attr:`intermask.generate.Job.options`)
FAMILY_OPTIONS = {
    "persons": "--persons",
    "revisits": "--revisits",
    "partner_scale": "--partner-scale",
    "remask_noise": "--remask-noise",
    "schedule": "--schedule",
    "noise": "--noise",
    "reaction": "--reaction",
    "edit": "--edit",
    "frames_range": "--frames",
    "person": "--person",
    "batch_size": "--batch-size",
    "residual": "--residual",
    "residual_cfg_scale": "--residual-cfg-scale",
    "residual_temperature": "--residual-temperature",
}


@dataclass(frozen=True)
class Request:
    """What ``intermask generate`` was asked (the CLI's options, parsed and range-checked);
    None takes the value of configs/generate.yaml. ``sampler`` holds the decoding settings that
    were given, by the key of the family's sampler config (configs/sampler/; ``cfg_scale`` is
    MoMask's ``mask_cfg_scale``); the family's job completes them from the config."""

    checkpoint: str
    residual: str | None = None  # MoMask: the residual transformer run
    text: list[str] | None = None
    prompts: str | None = None
    vq_checkpoint: str | None = None
    seconds: float | None = None
    length_frames: int | None = None
    samples: int | None = None
    seed: int | None = None
    sampler: Mapping[str, Any] = field(default_factory=dict)
    batch_size: int | None = None
    fps: float | None = None
    reaction: str | None = None
    edit: str | None = None
    frames_range: tuple[int, int] | None = None
    person: int | None = None
    device: str | None = None
    precision: str | None = None  # 32 | bf16 | auto
    out: Path | None = None
    no_render: bool = False
    # more files for the sample folders, written before they are moved into place (so that a
    # failure leaves no folder): called with (the staged folders, the folders they become);
    # --body-model's bodies and .glb (intermask.body.command.generate_bodies)
    finish: Callable[[Sequence[Path], Sequence[Path]], None] | None = None

    def given(self, name: str) -> bool:
        """Whether option ``name`` (a field, or a decoding setting) was given."""
        return name in self.sampler or getattr(self, name, None) is not None


def refuse_options(request: Request, takes: frozenset[str], refusal: Callable[[str], str]) -> None:
    """A :data:`FAMILY_OPTIONS` option given that the family does not take -> ValueError with
    ``refusal(option)`` (the first such option, in the table's order)."""
    refused = [
        option
        for name, option in FAMILY_OPTIONS.items()
        if name not in takes and request.given(name)
    ]
    if refused:
        raise ValueError(refusal(refused[0]))


def default_settings() -> dict[str, Any]:
    """configs/generate.yaml composed with its sampler groups (``["sampler"]["iterations"]``,
    ``["momask"]["iterations"]`` ...)."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return OmegaConf.to_container(compose("generate"), resolve=True)


def run_target(checkpoint: str | Path) -> str:
    """``model._target_`` of a train_gen run's config.yaml ("" when it names none): what tells
    the families apart (:data:`intermask.generate.JOBS`). Only the config is read."""
    config = open_run_checkpoint(checkpoint, kind="generator").config
    return str(OmegaConf.select(config, "model._target_", default=""))


def pick_device(request: Request) -> str:
    return request.device or ("cuda" if torch.cuda.is_available() else "cpu")


def frames_from(*, seconds: float | None, frames: int | None, fps: float, max_frames: int) -> int:
    """Requested length -> frames rounded down to a multiple of 4; errors outside the range
    the generator was trained on."""
    if (seconds is None) == (frames is None):
        raise ValueError("give the length either in seconds or in frames (exactly one)")
    requested = int(round(seconds * fps)) if seconds is not None else int(frames)
    rounded = requested - requested % FRAMES_PER_STEP
    if not 2 * FRAMES_PER_STEP <= rounded <= max_frames:
        raise ValueError(
            f"length {requested} frames is out of range: the generator makes "
            f"{2 * FRAMES_PER_STEP}..{max_frames} frames ({max_frames / fps:.1f} s at {fps:g} fps)"
        )
    return rounded


def requested_frames(
    request: Request, defaults: dict[str, Any], *, fps: float, max_frames: int
) -> int:
    """:func:`frames_from` of ``--length-frames``, else ``--seconds``, else the default seconds."""
    seconds = request.seconds if request.length_frames is None else None
    if seconds is None and request.length_frames is None:
        seconds = defaults["seconds"]
    return frames_from(
        seconds=seconds, frames=request.length_frames, fps=fps, max_frames=max_frames
    )


def read_prompts(path: str | Path) -> list[str]:
    """One caption per non-empty line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: prompts file not found")
    prompts = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    if not prompts:
        raise ValueError(f"{path}: no prompt in the file (one caption per line expected)")
    return prompts


def requested_captions(request: Request, *, optional: bool = False) -> list[str]:
    """``--text`` or ``--prompts``: exactly one of them, unless ``optional``."""
    if bool(request.text) == bool(request.prompts) and not optional:
        raise ValueError("give captions with --text or --prompts (one of them)")
    return read_prompts(request.prompts) if request.prompts else list(request.text or [])


@dataclass
class Sample:
    caption: str | None
    index: int  # sample number of this caption
    seed: int
    joints: np.ndarray | None  # (T, P, 22, 3): P = 2 (Inter-M) or 1 (MoMask)
    features: np.ndarray  # (P, T, *F)
    mode: str  # "interaction" | "reaction" | "edit" | "text_to_motion"


def with_progress(iterable, *, enabled: bool, total: int):
    if not enabled or total < 2:
        return iterable
    from rich.progress import track

    return track(iterable, description="generating", total=total)


def slug(text: str | None, limit: int = 40) -> str:
    cleaned = re.sub(r"[^a-z0-9]+", "_", (text or "no_text").lower()).strip("_")
    return cleaned[:limit] or "sample"


def sample_folders(captions: Sequence[str | None], samples: int, out: Path) -> list[Path]:
    """The folder of sample k of caption c, in the jobs' order of samples:
    ``<caption slug>_<c>-<k>`` (the caption's number keeps captions that share their first 40
    characters, or repeat, apart). An existing folder is refused before any work: a re-run would
    mix new arrays with old renders, and samples are never overwritten."""
    folders = [
        out / f"{slug(caption)}_{c:02d}-{k:02d}"
        for c, caption in enumerate(captions)
        for k in range(samples)
    ]
    taken = [str(folder) for folder in folders if folder.exists()]
    if taken:
        raise FileExistsError(
            f"{taken[0]}: a sample folder already exists ({len(taken)} of {len(folders)}); "
            "choose another --out or remove them: samples are never overwritten"
        )
    return folders


def write_files(
    sample: Sample,
    directory: Path,
    record: dict[str, Any],
    *,
    fps: float,
    renders: Sequence[str],
) -> dict[str, Path]:
    """The arrays, ``record`` as sample.json and the requested renders -> {kind: path}."""
    directory.mkdir(parents=True, exist_ok=True)
    paths = {"features": directory / "features.npy", "json": directory / "sample.json"}
    np.save(paths["features"], sample.features.astype(np.float32))
    if sample.joints is not None:
        paths["joints"] = directory / "joints.npy"
        np.save(paths["joints"], sample.joints.astype(np.float32))
    paths["json"].write_text(json.dumps(record, indent=2) + "\n")
    if sample.joints is not None and renders:
        paths |= render_sample(sample, directory, fps=fps, renders=renders)
    return paths


def render_sample(
    sample: Sample, directory: Path, *, fps: float, renders: Sequence[str]
) -> dict[str, Path]:
    """GIF / MP4 / HTML of one sample; the fixed person of a reaction is drawn as reference."""
    from intermask.render import (
        ViewerSample,
        render_frames,
        write_gif,
        write_html_viewer,
        write_mp4,
    )

    reference = 0 if sample.mode == "reaction" else None
    caption = sample.caption or "(no text)"
    paths: dict[str, Path] = {}
    if {"gif", "mp4"} & set(renders):
        # draw once, encode twice
        images = render_frames(
            sample.joints, caption=caption, reference_person=reference, fps=fps, trails=True
        )
        if "gif" in renders:
            paths["gif"] = write_gif(images, directory / "animation.gif", fps=fps)
        if "mp4" in renders:
            paths["mp4"] = write_mp4(images, directory / "animation.mp4", fps=fps)
    if "html" in renders:
        paths["html"] = directory / "viewer.html"
        write_html_viewer(
            [
                ViewerSample(
                    name=directory.name,
                    caption=caption,
                    joints=sample.joints,
                    fps=fps,
                    reference_person=reference,
                )
            ],
            paths["html"],
        )
    return paths
