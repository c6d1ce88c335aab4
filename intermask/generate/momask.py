"""The generate job of a MoMask run: a masked transformer run (``MaskTransformerModule``),
optionally with its residual transformer run (``--residual RUN``; without it the base layer alone
is decoded) -> one HumanML3D person (P = 1, F = 263) at 20 fps, at most 196 frames. Each sample
is generated on its own from its own seeded generator, so its recorded seed reproduces it
whatever else was generated with it."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch

from intermask.generate.common import (
    MAX_FRAMES,
    Request,
    Sample,
    pick_device,
    refuse_options,
    requested_captions,
    requested_frames,
    run_target,
    sample_folders,
    with_progress,
    write_files,
)
from intermask.momask.load import load_momask_sampler
from intermask.momask.sampler import MoMaskDecoding, MoMaskSampler
from intermask.motion import humanml3d as hml
from intermask.utils.files import file_hash
from intermask.utils.staging import staged_outputs

# model._target_ of a MoMask train_gen run -> its role
MASK_MODULE = "intermask.momask.module.MaskTransformerModule"
RESIDUAL_MODULE = "intermask.momask.module.ResidualTransformerModule"
MOMASK_MODULES = {MASK_MODULE: "mask", RESIDUAL_MODULE: "residual"}
# the options of intermask.generate.common.FAMILY_OPTIONS that a MoMask run takes
OPTIONS = frozenset({"residual", "residual_cfg_scale", "residual_temperature"})
# the decoding options named otherwise in configs/sampler/momask.yaml
SAMPLER_KEYS = {"cfg_scale": "mask_cfg_scale"}


@dataclass(frozen=True)
class Settings:
    """A MoMask job's settings: the decoding, whole (MoMask section 4), and the frame rate of
    the data (HumanML3D)."""

    decoding: MoMaskDecoding
    fps: float


def settings(request: Request, defaults: dict[str, Any]) -> Settings:
    """configs/sampler/momask.yaml with the decoding settings given, and the frame rate."""
    given = {SAMPLER_KEYS.get(key, key): value for key, value in request.sampler.items()}
    return Settings(
        decoding=MoMaskDecoding(**{**defaults["momask"], **given}),
        fps=request.fps or defaults["momask_fps"],
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
    for c, k in with_progress(jobs, enabled=progress, total=len(jobs)):
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


def write_momask_sample(
    sample: Sample,
    directory: Path,
    *,
    checkpoints: dict[str, Path],
    text_encoder: str,
    settings: Settings,
    renders: Sequence[str],
) -> dict[str, Path]:
    """The MoMask counterpart of :func:`intermask.generate.interm.write_sample`: the record
    names the masked transformer, the residual one (null for the base layer alone) and the
    tokenizer by path and hash, and its ``settings`` are the decoding settings."""

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
        "settings": asdict(settings.decoding),
        "mask": named("mask"),
        "residual": named("residual"),
        "vq": named("vq"),
        "text_encoder": text_encoder,
    }
    return write_files(sample, directory, record, fps=settings.fps, renders=renders)


def _check_request(request: Request, target: str) -> None:
    """The run kinds and the options, checked before anything is loaded."""
    if MOMASK_MODULES[target] != "mask":
        raise ValueError(
            f"--checkpoint {request.checkpoint}: a MoMask residual transformer run; pass the "
            "masked transformer run as --checkpoint and this one as --residual"
        )
    if request.precision not in (None, "32"):
        raise ValueError(
            f"--precision {request.precision}: MoMask runs decode in fp32 only (--checkpoint "
            f"{request.checkpoint})"
        )
    refuse_options(
        request,
        OPTIONS,
        lambda option: (
            f"{option} does not apply to a MoMask run: --checkpoint "
            f"{request.checkpoint} generates one person from text, each sample on its own"
        ),
    )
    if request.residual is not None:
        residual = run_target(request.residual)
        if MOMASK_MODULES.get(residual) != "residual":
            raise ValueError(
                f"--residual {request.residual}: not a MoMask residual transformer run (its "
                f"model is {residual or 'not named'}, not {RESIDUAL_MODULE})"
            )


def _load(request: Request, job: Settings) -> tuple[MoMaskSampler, dict[str, Path]]:
    sampler, checkpoints = load_momask_sampler(
        request.checkpoint,
        request.residual,
        vq_checkpoint=request.vq_checkpoint,
        settings=job.decoding,
    )
    device = pick_device(request)
    for net in (sampler.mask_net, sampler.residual_net, sampler.vq, sampler.text.encoder):
        if net is not None:
            net.to(device)
    return sampler, checkpoints


def run(request: Request, defaults: dict[str, Any], target: str) -> list[Path]:
    """The MoMask job of :func:`intermask.generate.run` (``target``: the run's model, a
    :data:`MOMASK_MODULES` key): captions -> single-person sample folders."""
    _check_request(request, target)
    captions = requested_captions(request)
    job = settings(request, defaults)
    frames = requested_frames(request, defaults, fps=job.fps, max_frames=MAX_FRAMES["humanml3d"])
    count = request.samples or defaults["samples"]
    out = Path(request.out or defaults["out"])
    folders = sample_folders(captions, count, out)
    sampler, checkpoints = _load(request, job)
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
    # the sample folders appear together when all are written, or none does (a full disk)
    with staged_outputs(out, [folder.name for folder in folders]) as staged:
        for sample, directory in zip(samples, folders, strict=True):
            paths = write_momask_sample(
                sample,
                staged / directory.name,
                checkpoints=checkpoints,
                text_encoder=text_encoder,
                settings=job,
                renders=renders,
            )
            print(
                f"{directory}: MoMask ({layers}), {frames} frames ({frames / job.fps:.1f} s), "
                f"seed {sample.seed}, {sample.caption!r} -> {', '.join(sorted(paths))}"
            )
        if request.finish is not None:
            request.finish([staged / folder.name for folder in folders], folders)
    print(f"{len(samples)} sample(s) in {time.perf_counter() - start:.1f} s under {out}")
    return folders
