"""The generate job of an Inter-M run: captions (or a reference or an edited motion) -> two-person
samples at the dataset's rate (30 fps); generated in batches, sample k of caption c from seed
``seed + c * samples + k``."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from intermask.generate.common import (
    MAX_FRAMES,
    Request,
    Sample,
    pick_device,
    refuse_options,
    requested_captions,
    requested_frames,
    sample_folders,
    with_progress,
    write_files,
)
from intermask.interm.decoding import Decoding, Edit, SettingsError
from intermask.interm.load import LoadedGenerator, load_generator
from intermask.interm.sampler import InteractionSampler
from intermask.utils.files import file_hash
from intermask.utils.precision import OPTIONS as PRECISION_OPTIONS
from intermask.utils.precision import resolve_precision
from intermask.utils.staging import staged_outputs
from intermask.vq.model import FRAMES_PER_STEP

# the options of intermask.generate.common.FAMILY_OPTIONS that an Inter-M run takes
OPTIONS = frozenset(
    {"reaction", "edit", "frames_range", "person", "batch_size"}
    | set(Decoding.__dataclass_fields__)
)
# the rules of Decoding that the options can break, in the options' words
OPTION_WORDING = {
    "revisits": "--revisits {revisits} needs --persons in_turn, got {persons!r}",
    "partner_scale": "--partner-scale {partner_scale} needs --persons in_turn or --reaction (one "
    "person decoded beside the other's tokens), got --persons {persons}",
    "remask_noise": "--remask-noise {remask_noise} draws each sample's noise from its own seed; "
    "it needs --noise per_sample, got --noise {noise}",
}


@dataclass(frozen=True)
class Settings:
    """An Inter-M job's settings: the decoding, whole, and how the job runs it. sample.json
    records them flat (:meth:`record`)."""

    decoding: Decoding
    batch_size: int  # (caption, sample) pairs per forward batch
    fps: float
    precision: str  # 32-true | bf16-mixed: the decoding under bf16 autocast

    def record(self) -> dict[str, Any]:
        return {
            **asdict(self.decoding),
            "batch_size": self.batch_size,
            "fps": self.fps,
            "precision": self.precision,
        }


def decoding(request: Request, defaults: dict[str, Any]) -> Decoding:
    """configs/sampler/ (a reaction: ``reaction_iterations``) with the settings given; a rule
    they break is said in the options' words."""
    values = dict(defaults["sampler"])
    if request.reaction:
        values["iterations"] = defaults["reaction_iterations"]
    values |= request.sampler
    try:
        settings = Decoding(**values)
        settings.check_for(modeling=None, reaction=bool(request.reaction))
    except SettingsError as error:
        if error.rule in OPTION_WORDING:
            raise ValueError(OPTION_WORDING[error.rule].format(**values)) from None
        raise
    return settings


def dataset_kind(generator: LoadedGenerator) -> str:
    return str(generator.config.data.dataset)


def normalize(generator: LoadedGenerator, features: torch.Tensor) -> torch.Tensor:
    """De-normalized (..., T, *F) -> the VQ's normalized space (identity without statistics)."""
    view = generator.vq.view
    if hasattr(view, "std"):
        return (features - view.mean) / view.std
    return features


def _raw_interhuman(path: Path, motion: torch.Tensor) -> torch.Tensor:
    """An official ``person1/<id>.npy`` (T, 492) file and its ``person2/<id>.npy`` sibling ->
    (2, T, 262) features."""
    from intermask.motion import interhuman as ih

    partner = path.parent.parent / "person2" / path.name
    if path.parent.name != "person1" or not partner.is_file():
        raise ValueError(
            f"{path}: a raw (T, 492) InterHuman file must be person1/<id>.npy with its "
            f"person2/<id>.npy beside it; {partner} not found"
        )
    other = torch.as_tensor(np.load(partner), dtype=torch.float32)
    return ih.interaction_features(torch.stack([motion, other], dim=1)).transpose(0, 1)


def load_motion_file(path: str | Path, generator: LoadedGenerator) -> torch.Tensor:
    """A motion file -> (P, T, *F) de-normalized features (P = 1 or 2), T a multiple of 4.

    Accepted: ``.npy`` of dataset features, (T, *F) for one person or (2, T, *F) for both;
    for InterHuman also an official ``person1/<id>.npy`` (T, 492) raw file, whose
    ``person2/<id>.npy`` sibling is read too and both are converted to 262-d features.
    """
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
        motion = _raw_interhuman(path, motion)
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


def _fixed_tokens(
    generator: LoadedGenerator, sampler: InteractionSampler, source: torch.Tensor
) -> torch.Tensor:
    """(P, T, *F) de-normalized motion -> (P, rows, T/4) codes of each person."""
    motion = normalize(generator, source.to(sampler.device))
    lengths = torch.full((motion.shape[0],), motion.shape[1])
    return torch.stack([generator.vq.encode(m[None], lengths[:1])[0, 0] for m in motion])


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
        settings=settings.decoding,
        precision=settings.precision,
    )
    jobs = [(c, k) for c in range(len(captions)) for k in range(samples)]
    fixed_tokens = None
    if reaction is not None or edit is not None:
        source = reaction[None] if reaction is not None else edit[0]
        frames = source.shape[1]
        fixed_tokens = _fixed_tokens(generator, sampler, source)
    mode = "reaction" if reaction is not None else "edit" if edit is not None else "interaction"
    results: list[Sample] = []
    chunks = range(0, len(jobs), settings.batch_size)
    for start in with_progress(chunks, enabled=progress, total=len(chunks)):
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
        "settings": settings.record(),
        "generator": {"path": str(generator.checkpoint), "sha256": file_hash(generator.checkpoint)},
        "vq": {"path": str(generator.vq_checkpoint), "sha256": file_hash(generator.vq_checkpoint)},
        "text_encoder": generator.text.encoder.extra_repr(),
    }
    return write_files(sample, directory, record, fps=settings.fps, renders=renders)


def _check_inputs(request: Request, target: str) -> list[str | None]:
    """The request's options, checked before anything is loaded -> the captions ([None]: a
    reaction without text)."""
    refuse_options(
        request,
        OPTIONS,
        lambda option: (
            f"{option} applies to MoMask runs only; --checkpoint {request.checkpoint} "
            f"is not a MoMask masked transformer run (its model is {target or 'not named'})"
        ),
    )
    captions: list[str | None] = list(requested_captions(request, optional=bool(request.reaction)))
    if (request.edit is None) != (request.frames_range is None):
        raise ValueError("--edit FILE needs --frames A:B (and --frames A:B needs --edit)")
    if request.reaction and request.edit:
        raise ValueError("--reaction and --edit are exclusive")
    return captions or [None]


def _load(request: Request, device: str) -> LoadedGenerator:
    generator = load_generator(request.checkpoint, vq_checkpoint=request.vq_checkpoint)
    generator.net.to(device)
    generator.vq.to(device)
    generator.text.encoder.to(device)
    return generator


def _motion_inputs(request: Request, generator: LoadedGenerator):
    """-> (reaction, edit): the reference person (T, *F), or the motion to edit and the region
    to regenerate; both None for an interaction."""
    if request.reaction:
        return load_motion_file(request.reaction, generator)[0], None
    if not request.edit:
        return None, None
    motion = load_motion_file(request.edit, generator)
    if motion.shape[0] != 2:
        raise ValueError(f"{request.edit}: editing needs both persons, (2, T, ...) features")
    steps = motion.shape[1] // FRAMES_PER_STEP
    region = edit_region(steps, request.frames_range, request.person, generator.net.rows)
    return None, (motion, region)


def run(request: Request, defaults: dict[str, Any], target: str) -> list[Path]:
    """The Inter-M job of :func:`intermask.generate.run` (``target``: the run's model)."""
    captions = _check_inputs(request, target)
    settings = decoding(request, defaults)
    count = request.samples or defaults["samples"]
    out = Path(request.out or defaults["out"])
    folders = sample_folders(captions, count, out)
    device = pick_device(request)
    generator = _load(request, device)
    precision = PRECISION_OPTIONS[request.precision or defaults["precision"]]
    job = Settings(
        decoding=settings,
        batch_size=request.batch_size or defaults["batch_size"],
        fps=request.fps or defaults["fps"],
        precision=resolve_precision(precision, torch.device(device).type).precision,
    )
    reaction, edit = _motion_inputs(request, generator)
    frames = 0
    if reaction is None and edit is None:
        kind = dataset_kind(generator)
        frames = requested_frames(request, defaults, fps=job.fps, max_frames=MAX_FRAMES[kind])
    start = time.perf_counter()
    samples = generate_samples(
        generator,
        captions,
        frames=frames,
        samples=count,
        seed=defaults["seed"] if request.seed is None else request.seed,
        settings=job,
        reaction=reaction,
        edit=edit,
        progress=True,
    )
    renders = [] if request.no_render else list(defaults["renders"])
    # the sample folders appear together when all are written, or none does (a full disk)
    with staged_outputs(out, [folder.name for folder in folders]) as staged:
        for sample, directory in zip(samples, folders, strict=True):
            paths = write_sample(
                sample, staged / directory.name, generator=generator, settings=job, renders=renders
            )
            frames_out = sample.features.shape[1]
            print(
                f"{directory}: {sample.mode}, {frames_out} frames ({frames_out / job.fps:.1f} s), "
                f"seed {sample.seed}, {sample.caption or '(no text)'!r} -> "
                f"{', '.join(sorted(paths))}"
            )
        if request.finish is not None:
            request.finish([staged / folder.name for folder in folders], folders)
    print(f"{len(samples)} sample(s) in {time.perf_counter() - start:.1f} s under {out}")
    return folders
