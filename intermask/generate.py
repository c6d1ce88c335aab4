"""Text (and optionally a reference or an edited motion) to motions on disk: two-person
interactions from an Inter-M run, single-person motions from a MoMask run.

``intermask generate --checkpoint RUN --text "two people shake hands" --seconds 4 --samples 2``
loads a train_gen run, generates every (caption, sample) pair, and writes per sample:
``joints.npy`` (T, P, 22, 3) metres Y-up, ``features.npy`` (P, T, *F) in the dataset
representation (de-normalized), ``sample.json`` (caption, settings, seed, checkpoint hashes) and
the renderings (GIF, MP4, HTML). Defaults live in ``configs/generate.yaml``.

The kind of run is read from its ``config.yaml`` (``model._target_``). Inter-M runs give P = 2
persons at the dataset's rate (30 fps). A MoMask masked transformer run (``MaskTransformerModule``),
optionally with its residual transformer run (``--residual RUN``; without it the base layer
alone is decoded), gives one HumanML3D person (P = 1, F = 263) at 20 fps, at most 196 frames:
``intermask generate --checkpoint MASK_RUN --residual RESIDUAL_RUN --text "a person walks
forward" --seconds 4 --samples 2``. Each MoMask sample is generated on its own from its own
seeded generator, so its recorded seed reproduces it whatever else was generated with it; the
options of two-person decoding (``--persons``, ``--reaction``, ``--edit`` ...) are refused.
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from intermask.config_files import config_dir
from intermask.interm.decoding import (
    CFG_SCALE,
    ITERATIONS,
    NOISE,
    PARTNER_SCALE,
    PERSONS,
    REMASK_NOISE,
    REVISITS,
    SCHEDULE,
    TEMPERATURE,
    TOP_K_RATIO,
    Edit,
)
from intermask.interm.load import LoadedGenerator, load_generator
from intermask.interm.sampler import InteractionSampler
from intermask.momask.load import load_momask_sampler
from intermask.momask.sampler import MoMaskSampler
from intermask.motion import humanml3d as hml
from intermask.motion import interhuman
from intermask.utils.files import file_hash, open_run_checkpoint
from intermask.utils.precision import FP32, OPTIONS, resolve_precision
from intermask.vq.model import FRAMES_PER_STEP

# longest training clips (multiples of 4); HumanML3D: MoMask's 196 frames
MAX_FRAMES = {"interhuman": 300, "interx": 148, "humanml3d": 196}
# model._target_ of a MoMask train_gen run -> its role
MASK_MODULE = "intermask.momask.module.MaskTransformerModule"
RESIDUAL_MODULE = "intermask.momask.module.ResidualTransformerModule"
MOMASK_MODULES = {MASK_MODULE: "mask", RESIDUAL_MODULE: "residual"}
# Request fields of two-person decoding -> their option, refused with a MoMask run
INTERM_ONLY = {
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
}
# Request fields of MoMask decoding -> their option, refused with an Inter-M run
MOMASK_ONLY = {
    "residual": "--residual",
    "residual_cfg_scale": "--residual-cfg-scale",
    "residual_temperature": "--residual-temperature",
}


@dataclass(frozen=True)
class Settings:
    """Decoding settings of one generation job (paper defaults in configs/sampler/paper.yaml)."""

    iterations: int = ITERATIONS
    cfg_scale: float = CFG_SCALE
    top_k_ratio: float = TOP_K_RATIO
    temperature: float = TEMPERATURE
    schedule: str = SCHEDULE
    noise: str = NOISE
    persons: str = PERSONS
    revisits: int = REVISITS
    partner_scale: float = PARTNER_SCALE
    remask_noise: float = REMASK_NOISE
    batch_size: int = 32
    fps: float = float(interhuman.FPS)
    precision: str = FP32  # or bf16-mixed: the decoding under bf16 autocast


@dataclass(frozen=True)
class MoMaskSettings:
    """Decoding settings of a MoMask job: :class:`MoMaskSampler`'s arguments (MoMask section 4;
    defaults in configs/generate.yaml ``momask``), and the frame rate of the data (HumanML3D)."""

    iterations: int
    mask_cfg_scale: float
    residual_cfg_scale: float
    top_k_ratio: float
    temperature: float
    residual_temperature: float
    schedule: str = SCHEDULE
    noise: str = NOISE
    fps: float = float(hml.FPS)

    def sampler_arguments(self) -> dict[str, Any]:
        """The keyword arguments of :func:`load_momask_sampler` (everything but ``fps``)."""
        return {k: v for k, v in asdict(self).items() if k != "fps"}


@dataclass
class Sample:
    caption: str | None
    index: int  # sample number of this caption
    seed: int
    joints: np.ndarray | None  # (T, P, 22, 3): P = 2 (Inter-M) or 1 (MoMask)
    features: np.ndarray  # (P, T, *F)
    mode: str  # "interaction" | "reaction" | "edit" | "text_to_motion"


def default_settings() -> dict[str, Any]:
    """configs/generate.yaml composed with its sampler group (``["sampler"]["iterations"]``...)."""
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        return OmegaConf.to_container(compose("generate"), resolve=True)


def dataset_kind(generator: LoadedGenerator) -> str:
    return str(generator.config.data.dataset)


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


def read_prompts(path: str | Path) -> list[str]:
    """One caption per non-empty line."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: prompts file not found")
    prompts = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    if not prompts:
        raise ValueError(f"{path}: no prompt in the file (one caption per line expected)")
    return prompts


def normalize(generator: LoadedGenerator, features: torch.Tensor) -> torch.Tensor:
    """De-normalized (..., T, *F) -> the VQ's normalized space (identity without statistics)."""
    view = generator.vq.view
    if hasattr(view, "std"):
        return (features - view.mean) / view.std
    return features


def load_motion_file(path: str | Path, generator: LoadedGenerator) -> torch.Tensor:
    """A motion file -> (P, T, *F) de-normalized features (P = 1 or 2), T a multiple of 4.

    Accepted: ``.npy`` of dataset features, (T, *F) for one person or (2, T, *F) for both;
    for InterHuman also an official ``person1/<id>.npy`` (T, 492) raw file, whose
    ``person2/<id>.npy`` sibling is read too and both are converted to 262-d features.
    """
    from intermask.motion import interhuman as ih

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: motion file not found")
    try:
        array = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as error:
        raise ValueError(f"{path}: not a readable .npy motion file ({error})") from error
    feature_shape = tuple(generator.vq.view.feature_shape)
    motion = torch.as_tensor(array, dtype=torch.float32)
    if dataset_kind(generator) == "interhuman" and motion.ndim == 2 and motion.shape[1] == 492:
        partner = path.parent.parent / "person2" / path.name
        if path.parent.name != "person1" or not partner.is_file():
            raise ValueError(
                f"{path}: a raw (T, 492) InterHuman file must be person1/<id>.npy with its "
                f"person2/<id>.npy beside it; {partner} not found"
            )
        other = torch.as_tensor(np.load(partner), dtype=torch.float32)
        motion = ih.interaction_features(torch.stack([motion, other], dim=1)).transpose(0, 1)
    elif tuple(motion.shape[-len(feature_shape) :]) == feature_shape and motion.ndim in (
        1 + len(feature_shape),
        2 + len(feature_shape),
    ):
        motion = motion if motion.ndim == 2 + len(feature_shape) else motion[None]
    else:
        raise ValueError(
            f"{path}: expected features (T, {feature_shape}) or (2, T, {feature_shape})"
            f"{' or a raw (T, 492) person1 file' if len(feature_shape) == 1 else ''}, "
            f"got shape {tuple(motion.shape)}"
        )
    if motion.shape[0] > 2 or not bool(torch.isfinite(motion).all()):
        raise ValueError(f"{path}: at most 2 persons of finite values expected")
    frames = motion.shape[1] - motion.shape[1] % FRAMES_PER_STEP
    if frames < 2 * FRAMES_PER_STEP:
        raise ValueError(f"{path}: {motion.shape[1]} frames is too short (at least 8 needed)")
    return motion[:, :frames]


def edit_region(steps: int, frames: tuple[int, int], person: int | None, rows: int) -> torch.Tensor:
    """(2, rows, T') bool: the token steps covering frames [A, B) of one person (1 or 2) or both."""
    start, stop = frames
    if not 0 <= start < stop <= steps * FRAMES_PER_STEP:
        raise ValueError(
            f"edit frames {start}:{stop} must satisfy 0 <= A < B <= {steps * FRAMES_PER_STEP}"
        )
    region = torch.zeros(2, rows, steps, dtype=torch.bool)
    persons = [0, 1] if person is None else [person - 1]
    region[persons, :, start // FRAMES_PER_STEP : -(-stop // FRAMES_PER_STEP)] = True
    return region


def generate_samples(
    generator: LoadedGenerator,
    captions: Sequence[str | None],
    *,
    frames: int,
    samples: int,
    seed: int,
    settings: Settings,
    reaction: torch.Tensor | None = None,
    edit: tuple[torch.Tensor, torch.Tensor] | None = None,
    progress: bool = False,
) -> list[Sample]:
    """Every caption x ``samples`` in batches of ``settings.batch_size``; sample k of caption c
    uses seed ``seed + c * samples + k``.

    reaction: (T, *F) de-normalized features of the reference person (person 1 is fixed).
    edit: ((2, T, *F) de-normalized motion, (2, rows, T/4) region to regenerate).
    """
    sampler = InteractionSampler(
        net=generator.net,
        vq=generator.vq,
        text=generator.text,
        iterations=settings.iterations,
        cfg_scale=settings.cfg_scale,
        top_k_ratio=settings.top_k_ratio,
        temperature=settings.temperature,
        schedule=settings.schedule,
        noise=settings.noise,
        persons=settings.persons,
        revisits=settings.revisits,
        partner_scale=settings.partner_scale,
        remask_noise=settings.remask_noise,
        precision=settings.precision,
    )
    jobs = [(c, k) for c in range(len(captions)) for k in range(samples)]
    fixed_tokens = None
    if reaction is not None or edit is not None:
        source = (reaction[None] if reaction is not None else edit[0]).to(sampler.device)
        frames = source.shape[1]
        motion = normalize(generator, source)
        lengths = torch.full((motion.shape[0],), frames)
        fixed_tokens = torch.stack(
            [generator.vq.encode(m[None], lengths[:1])[0, 0] for m in motion]
        )
    mode = "reaction" if reaction is not None else "edit" if edit is not None else "interaction"
    results: list[Sample] = []
    chunks = range(0, len(jobs), settings.batch_size)
    for start in _progress(chunks, enabled=progress, total=len(chunks)):
        chunk = jobs[start : start + settings.batch_size]
        texts = [captions[c] for c, _ in chunk]
        seeds = [seed + c * samples + k for c, k in chunk]
        lengths = torch.full((len(chunk),), frames)
        kwargs: dict[str, Any] = {}
        if mode == "reaction":
            kwargs["reference_tokens"] = fixed_tokens[0][None].expand(len(chunk), -1, -1)
        elif mode == "edit":
            tokens = fixed_tokens[None].expand(len(chunk), -1, -1, -1)
            region = edit[1].to(tokens.device)[None].expand_as(tokens)
            kwargs["edit"] = Edit(tokens, region)
        use_text = None if all(t is None for t in texts) else [t or "" for t in texts]
        out = sampler(use_text, lengths, seeds=seeds, **kwargs)
        for i, (c, k) in enumerate(chunk):
            joints = None if out.joints is None else out.joints[i].cpu().numpy()
            results.append(
                Sample(captions[c], k, seeds[i], joints, out.features[i].cpu().numpy(), mode)
            )
    return results


def _progress(iterable, *, enabled: bool, total: int):
    if not enabled or total < 2:
        return iterable
    from rich.progress import track

    return track(iterable, description="generating", total=total)


def slug(text: str | None, limit: int = 40) -> str:
    cleaned = re.sub(r"[^a-z0-9]+", "_", (text or "no_text").lower()).strip("_")
    return cleaned[:limit] or "sample"


def sample_folders(captions: Sequence[str | None], samples: int, out: Path) -> list[Path]:
    """The folder of sample k of caption c, in :func:`generate_samples`' order:
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


def write_sample(
    sample: Sample,
    directory: Path,
    *,
    generator: LoadedGenerator,
    settings: Settings,
    renders: Sequence[str],
) -> dict[str, Path]:
    """Write the arrays, the JSON record and the requested renders -> {kind: path}."""
    record = {
        "caption": sample.caption,
        "mode": sample.mode,
        "sample": sample.index,
        "seed": sample.seed,
        "frames": int(sample.features.shape[1]),
        "settings": asdict(settings),
        "generator": {"path": str(generator.checkpoint), "sha256": file_hash(generator.checkpoint)},
        "vq": {"path": str(generator.vq_checkpoint), "sha256": file_hash(generator.vq_checkpoint)},
        "text_encoder": generator.text.encoder.extra_repr(),
    }
    return _write_files(sample, directory, record, fps=settings.fps, renders=renders)


def write_momask_sample(
    sample: Sample,
    directory: Path,
    *,
    checkpoints: dict[str, Path],
    text_encoder: str,
    settings: MoMaskSettings,
    renders: Sequence[str],
) -> dict[str, Path]:
    """The MoMask counterpart of :func:`write_sample`: the record names the masked transformer,
    the residual one (null for the base layer alone) and the tokenizer by path and hash, and its
    ``settings`` are the sampler's arguments."""

    def named(role: str) -> dict[str, str] | None:
        path = checkpoints.get(role)
        return None if path is None else {"path": str(path), "sha256": file_hash(path)}

    record = {
        "caption": sample.caption,
        "mode": sample.mode,
        "model": "momask",
        "sample": sample.index,
        "seed": sample.seed,
        "frames": int(sample.features.shape[1]),
        "fps": settings.fps,
        "settings": settings.sampler_arguments(),
        "mask": named("mask"),
        "residual": named("residual"),
        "vq": named("vq"),
        "text_encoder": text_encoder,
    }
    return _write_files(sample, directory, record, fps=settings.fps, renders=renders)


def _write_files(
    sample: Sample,
    directory: Path,
    record: dict[str, Any],
    *,
    fps: float,
    renders: Sequence[str],
) -> dict[str, Path]:
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


@dataclass(frozen=True)
class Request:
    """What ``intermask generate`` was asked (the CLI's options, parsed and range-checked);
    None takes the value of configs/generate.yaml and its sampler group (MoMask runs: its
    ``momask`` block)."""

    checkpoint: str
    residual: str | None = None  # MoMask: the residual transformer run
    text: list[str] | None = None
    prompts: str | None = None
    vq_checkpoint: str | None = None
    seconds: float | None = None
    length_frames: int | None = None
    samples: int | None = None
    seed: int | None = None
    cfg_scale: float | None = None  # MoMask: the masked transformer's
    residual_cfg_scale: float | None = None
    residual_temperature: float | None = None
    iterations: int | None = None
    top_k: float | None = None
    temperature: float | None = None
    schedule: str | None = None
    noise: str | None = None
    persons: str | None = None
    revisits: int | None = None
    partner_scale: float | None = None
    remask_noise: float | None = None
    batch_size: int | None = None
    fps: float | None = None
    reaction: str | None = None
    edit: str | None = None
    frames_range: tuple[int, int] | None = None
    person: int | None = None
    device: str | None = None
    precision: str | None = None  # 32 | bf16 | auto (None: 32)
    out: Path | None = None
    no_render: bool = False


def run(request: Request) -> list[Path]:
    """The generate job: captions (or a reaction / edit input) -> sample folders with arrays,
    JSON and renders; returns the folders. A MoMask run (read from its config) goes to
    :func:`run_momask`. Inputs are checked before the generator is loaded, and no existing
    sample folder is overwritten."""
    defaults = default_settings()
    target = run_target(request.checkpoint)
    if target in MOMASK_MODULES:
        return run_momask(request, MOMASK_MODULES[target], defaults)
    given = [option for name, option in MOMASK_ONLY.items() if getattr(request, name) is not None]
    if given:
        raise ValueError(
            f"{given[0]} applies to MoMask runs only; --checkpoint {request.checkpoint} is not "
            f"a MoMask masked transformer run (its model is {target or 'not named'})"
        )
    if bool(request.text) == bool(request.prompts) and not request.reaction:
        raise ValueError("give captions with --text or --prompts (one of them)")
    captions: list[str | None] = list(request.text or [])
    if request.prompts:
        captions = read_prompts(request.prompts)
    if not captions:
        captions = [None]  # reaction without text
    if (request.edit is None) != (request.frames_range is None):
        raise ValueError("--edit FILE needs --frames A:B (and --frames A:B needs --edit)")
    if request.reaction and request.edit:
        raise ValueError("--reaction and --edit are exclusive")
    persons = request.persons or defaults["sampler"]["persons"]
    if request.revisits and persons != "in_turn":
        raise ValueError(f"--revisits {request.revisits} needs --persons in_turn, got {persons!r}")
    if request.partner_scale and persons != "in_turn" and not request.reaction:
        raise ValueError(
            f"--partner-scale {request.partner_scale} needs --persons in_turn or --reaction "
            f"(one person decoded beside the other's tokens), got --persons {persons}"
        )
    noise = request.noise or defaults["sampler"]["noise"]
    if request.remask_noise and noise != "per_sample":
        raise ValueError(
            f"--remask-noise {request.remask_noise} draws each sample's noise from its own seed; "
            f"it needs --noise per_sample, got --noise {noise}"
        )
    count = request.samples or defaults["samples"]
    out = Path(request.out or defaults["out"])
    folders = sample_folders(captions, count, out)
    generator = load_generator(request.checkpoint, vq_checkpoint=request.vq_checkpoint)
    device = request.device or ("cuda" if torch.cuda.is_available() else "cpu")
    generator.net.to(device)
    generator.vq.to(device)
    generator.text.encoder.to(device)
    kind = dataset_kind(generator)
    fps = request.fps or defaults["fps"]
    sampler = defaults["sampler"]
    mode_iterations = defaults["reaction_iterations"] if request.reaction else sampler["iterations"]
    settings = Settings(
        iterations=request.iterations or mode_iterations,
        cfg_scale=sampler["cfg_scale"] if request.cfg_scale is None else request.cfg_scale,
        top_k_ratio=request.top_k or sampler["top_k_ratio"],
        temperature=sampler["temperature"] if request.temperature is None else request.temperature,
        schedule=request.schedule or sampler["schedule"],
        noise=noise,
        persons=persons,
        revisits=sampler["revisits"] if request.revisits is None else request.revisits,
        partner_scale=(
            sampler["partner_scale"] if request.partner_scale is None else request.partner_scale
        ),
        remask_noise=(
            sampler["remask_noise"] if request.remask_noise is None else request.remask_noise
        ),
        batch_size=request.batch_size or defaults["batch_size"],
        fps=fps,
        precision=resolve_precision(
            OPTIONS[request.precision or "32"], torch.device(device).type
        ).precision,
    )
    reaction = edit = None
    frames = 0
    if request.reaction:
        reaction = load_motion_file(request.reaction, generator)[0]
    elif request.edit:
        motion = load_motion_file(request.edit, generator)
        if motion.shape[0] != 2:
            raise ValueError(f"{request.edit}: editing needs both persons, (2, T, ...) features")
        region = edit_region(
            motion.shape[1] // FRAMES_PER_STEP,
            request.frames_range,
            request.person,
            generator.net.rows,
        )
        edit = (motion, region)
    else:
        seconds = request.seconds if request.length_frames is None else None
        if seconds is None and request.length_frames is None:
            seconds = defaults["seconds"]
        frames = frames_from(
            seconds=seconds, frames=request.length_frames, fps=fps, max_frames=MAX_FRAMES[kind]
        )
    start = time.perf_counter()
    samples = generate_samples(
        generator,
        captions,
        frames=frames,
        samples=count,
        seed=defaults["seed"] if request.seed is None else request.seed,
        settings=settings,
        reaction=reaction,
        edit=edit,
        progress=True,
    )
    renders = [] if request.no_render else list(defaults["renders"])
    for sample, directory in zip(samples, folders, strict=True):
        paths = write_sample(
            sample, directory, generator=generator, settings=settings, renders=renders
        )
        frames_out = sample.features.shape[1]
        print(
            f"{directory}: {sample.mode}, {frames_out} frames ({frames_out / fps:.1f} s), seed "
            f"{sample.seed}, {sample.caption or '(no text)'!r} -> {', '.join(sorted(paths))}"
        )
    print(f"{len(samples)} sample(s) in {time.perf_counter() - start:.1f} s under {out}")
    return folders


def run_target(checkpoint: str | Path) -> str:
    """``model._target_`` of a train_gen run's config.yaml ("" when it names none): what tells
    a MoMask run (:data:`MOMASK_MODULES`) from an Inter-M one. Only the config is read."""
    config = open_run_checkpoint(checkpoint, kind="generator").config
    return str(OmegaConf.select(config, "model._target_", default=""))


def momask_settings(request: Request, defaults: dict[str, Any]) -> MoMaskSettings:
    """The request's MoMask decoding settings, each missing one from configs/generate.yaml."""
    base = defaults["momask"]

    def pick(value: Any, key: str) -> Any:
        return base[key] if value is None else value

    return MoMaskSettings(
        iterations=int(pick(request.iterations, "iterations")),
        mask_cfg_scale=float(pick(request.cfg_scale, "mask_cfg_scale")),
        residual_cfg_scale=float(pick(request.residual_cfg_scale, "residual_cfg_scale")),
        top_k_ratio=float(pick(request.top_k, "top_k_ratio")),
        temperature=float(pick(request.temperature, "temperature")),
        residual_temperature=float(pick(request.residual_temperature, "residual_temperature")),
        schedule=str(pick(request.schedule, "schedule")),
        noise=str(pick(request.noise, "noise")),
        fps=float(pick(request.fps, "fps")),
    )


def generate_momask_samples(
    sampler: MoMaskSampler,
    captions: Sequence[str],
    *,
    frames: int,
    samples: int,
    seed: int,
    progress: bool = False,
) -> list[Sample]:
    """Every caption x ``samples``, one sampler call each: sample k of caption c draws from a
    generator seeded ``seed + c * samples + k`` on the networks' device, so its seed alone
    reproduces it. Features are de-normalized (1, T, 263), joints (T, 1, 22, 3)."""
    jobs = [(c, k) for c in range(len(captions)) for k in range(samples)]
    lengths = torch.tensor([frames])
    results: list[Sample] = []
    for c, k in _progress(jobs, enabled=progress, total=len(jobs)):
        sample_seed = seed + c * samples + k
        generator = torch.Generator(device=sampler.device).manual_seed(sample_seed)
        out = sampler([captions[c]], lengths, generator=generator)
        features = sampler.vq.view.denormalize(out.features[:, :frames]).float()  # (1, T, 263)
        joints = hml.recover_from_ric(features).transpose(0, 1)  # (T, 1, 22, 3)
        results.append(
            Sample(
                captions[c],
                k,
                sample_seed,
                joints.cpu().numpy(),
                features.cpu().numpy(),
                "text_to_motion",
            )
        )
    return results


def run_momask(request: Request, role: str, defaults: dict[str, Any]) -> list[Path]:
    """:func:`run` for a MoMask masked transformer run (``role`` of :data:`MOMASK_MODULES`), with
    ``request.residual`` its optional residual transformer run: captions -> single-person
    sample folders. Inputs are checked before the networks are loaded."""
    if role != "mask":
        raise ValueError(
            f"--checkpoint {request.checkpoint}: a MoMask residual transformer run; pass the "
            "masked transformer run as --checkpoint and this one as --residual"
        )
    if request.precision not in (None, "32"):
        raise ValueError(
            f"--precision {request.precision}: MoMask runs decode in fp32 only (--checkpoint "
            f"{request.checkpoint})"
        )
    given = [option for name, option in INTERM_ONLY.items() if getattr(request, name) is not None]
    if given:
        raise ValueError(
            f"{given[0]} does not apply to a MoMask run: --checkpoint {request.checkpoint} "
            "generates one person from text, each sample on its own"
        )
    if request.residual is not None:
        residual = run_target(request.residual)
        if MOMASK_MODULES.get(residual) != "residual":
            raise ValueError(
                f"--residual {request.residual}: not a MoMask residual transformer run (its "
                f"model is {residual or 'not named'}, not {RESIDUAL_MODULE})"
            )
    if bool(request.text) == bool(request.prompts):
        raise ValueError("give captions with --text or --prompts (one of them)")
    captions = list(request.text) if request.text else read_prompts(request.prompts)
    settings = momask_settings(request, defaults)
    seconds = request.seconds if request.length_frames is None else None
    if seconds is None and request.length_frames is None:
        seconds = defaults["seconds"]
    frames = frames_from(
        seconds=seconds,
        frames=request.length_frames,
        fps=settings.fps,
        max_frames=MAX_FRAMES["humanml3d"],
    )
    count = request.samples or defaults["samples"]
    out = Path(request.out or defaults["out"])
    folders = sample_folders(captions, count, out)
    sampler, checkpoints = load_momask_sampler(
        request.checkpoint,
        request.residual,
        vq_checkpoint=request.vq_checkpoint,
        **settings.sampler_arguments(),
    )
    device = request.device or ("cuda" if torch.cuda.is_available() else "cpu")
    for net in (sampler.mask_net, sampler.residual_net, sampler.vq, sampler.text.encoder):
        if net is not None:
            net.to(device)
    start = time.perf_counter()
    samples = generate_momask_samples(
        sampler,
        captions,
        frames=frames,
        samples=count,
        seed=defaults["seed"] if request.seed is None else request.seed,
        progress=True,
    )
    renders = [] if request.no_render else list(defaults["renders"])
    text_encoder = sampler.text.encoder.extra_repr()
    layers = "base + residual layers" if sampler.residual_net is not None else "base layer"
    for sample, directory in zip(samples, folders, strict=True):
        paths = write_momask_sample(
            sample,
            directory,
            checkpoints=checkpoints,
            text_encoder=text_encoder,
            settings=settings,
            renders=renders,
        )
        print(
            f"{directory}: MoMask ({layers}), {frames} frames ({frames / settings.fps:.1f} s), "
            f"seed {sample.seed}, {sample.caption!r} -> {', '.join(sorted(paths))}"
        )
    print(f"{len(samples)} sample(s) in {time.perf_counter() - start:.1f} s under {out}")
    return folders
