"""MoMask's memorisation check: can the RVQ and both transformers learn a handful of clips?

``python -m intermask.overfit_momask --out outputs/overfit_momask`` (``make overfit-momask``):

1. writes the clip set: the first ``--clips`` (8) synthetic HumanML3D-layout clips, every split
   listing all of them, each clip one item (its time-tagged sub-clip captions removed);
2. trains the residual VQ-VAE on them (``experiment=overfit_momask_rvq``), then the masked
   transformer (``experiment=overfit_momask_mask``) and the residual transformer
   (``experiment=overfit_momask_residual``) on their codes;
3. measures, on the clips' own codes, the masked transformer's accuracy from the caption alone
   (every step [MASK], one pass) and the residual transformer's accuracy on each layer j given the
   true layers below (teacher forcing, no guidance);
4. generates from each clip's caption at its length with MoMask's decoding (CFG, 10 iterations,
   top-k; greedy residual layers) and reports the joint error against the clip, in mm, of the
   base layer alone and of all layers, both on the same generated base codes, beside the same two
   for the clip's own codes (the tokenizer's floor).

A chain that passes this learns; one that passes it and still fails on the full data is short of
training or capacity. The report is printed and written to ``<out>/overfit_momask.json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import shutil
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from intermask.data.humanml3d import HumanML3DDataset, HumanML3DLayout
from intermask.data.synthetic.humanml3d import generate_humanml3d
from intermask.data.synthetic.writers import SPLITS
from intermask.momask.load import load_momask
from intermask.momask.model import MaskedTransformer, ResidualTransformer
from intermask.momask.sampler import MoMaskSampler
from intermask.motion.masks import length_mask
from intermask.overfit import _compose
from intermask.train import train
from intermask.utils.staging import staged_outputs, write_text_atomically
from intermask.utils.write_errors import reported_write_errors
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE

log = logging.getLogger(__name__)

DEFAULT_CLIPS = 8
RESIDUAL_ACCURACY = 0.95  # teacher-forced accuracy every residual layer must reach
MASKED_ACCURACY = 0.95  # the masked transformer's, from the caption alone
GENERATED_BASE_CODES = 0.9  # mean share of the generated base codes equal to the clips'


@dataclass(frozen=True)
class MoMaskClipResult:
    clip: str
    caption: str
    frames: int
    base_codes: float  # share of generated base codes equal to the clip's
    residual_codes: list[float]  # per residual layer 1..Q-1, share equal to the clip's
    base_mm: float  # MPJPE of the generated base layer alone
    full_mm: float  # MPJPE of the generated base and residual layers
    rvq_base_mm: float  # MPJPE of the clip's own base codes alone
    rvq_full_mm: float  # MPJPE of the clip's own codes, every layer


@dataclass(frozen=True)
class MoMaskOverfitReport:
    rvq_mpjpe_mm: float  # the tokenizer's validation MPJPE (windows of the same clips)
    masked_accuracy: float  # from the caption alone, every step masked
    residual_accuracy: list[float]  # teacher-forced, per residual layer 1..Q-1
    clips: list[MoMaskClipResult]
    seconds: dict[str, float]

    def mean(self, field: str) -> float:
        return sum(getattr(c, field) for c in self.clips) / len(self.clips)

    @property
    def residual_helps(self) -> bool:
        """The generated motions closer to their clips, on average, with the residual layers
        than with the same base codes alone."""
        return self.mean("full_mm") < self.mean("base_mm")

    @property
    def passed(self) -> bool:
        return (
            self.masked_accuracy >= MASKED_ACCURACY
            and min(self.residual_accuracy) >= RESIDUAL_ACCURACY
            and self.mean("base_codes") >= GENERATED_BASE_CODES
            and self.residual_helps
        )

    def table(self) -> str:
        layers = ", ".join(f"{a:.3f}" for a in self.residual_accuracy)
        lines = [
            f"RVQ val MPJPE {self.rvq_mpjpe_mm:.1f} mm; masked accuracy {self.masked_accuracy:.3f}; "
            f"residual accuracy per layer 1..{len(self.residual_accuracy)}: {layers}",
            "| clip | frames | base codes | residual codes | MPJPE base (mm) | MPJPE all (mm) | "
            "RVQ base (mm) | RVQ all (mm) | caption |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        lines += [
            f"| {c.clip} | {c.frames} | {c.base_codes:.2f} | "
            f"{'/'.join(f'{a:.2f}' for a in c.residual_codes)} | {c.base_mm:.1f} | "
            f"{c.full_mm:.1f} | {c.rvq_base_mm:.1f} | {c.rvq_full_mm:.1f} | {c.caption} |"
            for c in self.clips
        ]
        means = [self.mean(f) for f in ("base_mm", "full_mm", "rvq_base_mm", "rvq_full_mm")]
        lines.append("| mean | | | | " + " | ".join(f"{m:.1f}" for m in means) + " | |")
        times = ", ".join(f"{k} {v / 60:.1f} min" for k, v in self.seconds.items())
        return "\n".join(lines + [f"time: {times}"])


def write_momask_memorisation_set(out: Path, *, clips: int = DEFAULT_CLIPS, seed: int = 0) -> Path:
    """The first ``clips`` synthetic HumanML3D-layout clips, every split listing all of them.
    Each clip is exactly one item with one crop: time-tagged caption lines are dropped and the
    clip is cut to whole token steps (a multiple of 4 frames), so the reader's crop always starts
    at frame 0 (otherwise it starts anywhere in the 1-3 spare frames and the codes move).
    Written beside ``out`` and moved in when whole (replacing an earlier set)."""
    out = Path(out)
    with staged_outputs(out.parent, [out.name], replace=True) as staged:
        _write_momask_set(staged / out.name, clips=clips, seed=seed)
    return out


def _write_momask_set(out: Path, *, clips: int, seed: int) -> None:
    generate_humanml3d(out, clips=clips, seed=seed)
    layout = HumanML3DLayout(out)
    ids = [f"{index:06d}" for index in range(clips)]
    for split in SPLITS:
        layout.split_file(split).write_text("\n".join(ids) + "\n", encoding="utf-8")
    for clip_id in ids:
        for path in (layout.motion_file(clip_id), layout.joints_file(clip_id)):
            array = np.load(path)
            np.save(path, array[: len(array) - len(array) % FRAMES_PER_STEP])
        path = layout.caption_file(clip_id)
        lines = path.read_text(encoding="utf-8").splitlines()
        whole = [line for line in lines if _is_whole_clip(line)]
        path.write_text("\n".join(whole) + "\n", encoding="utf-8")


def _is_whole_clip(line: str) -> bool:
    """A caption line "text#tokens#start#end" that covers the whole clip (0.0/0.0 tags)."""
    start, end = line.split("#")[2:4]
    return float(start or 0) == 0.0 and float(end or 0) == 0.0


@dataclass(frozen=True)
class ClipBatch:
    ids: list[str]
    captions: list[str]
    motion: torch.Tensor  # (B, T, 263) normalized, zero after each length
    lengths: torch.Tensor  # (B,) frames, multiples of 4
    tokens: torch.Tensor  # (B, Q, T') the clip's codes, -1 beyond each length // 4


def clip_batch(vq: MotionVQVAE, root: Path, max_length: int) -> ClipBatch:
    """Every clip of the test split whole, with the caption its test pass draws, and its codes
    as the transformers' training tokenizes them (the padded batch, encoded at once)."""
    dataset = HumanML3DDataset(
        root=root, split="test", max_length=max_length, length_jitter=False, normalizer=None
    )
    items = [dataset[i] for i in range(len(dataset))]
    motion = torch.stack([item["motion"] for item in items])
    motion = motion[:, : motion.shape[1] - motion.shape[1] % FRAMES_PER_STEP]
    lengths = torch.tensor([int(item["length"]) for item in items])
    lengths = lengths - lengths % FRAMES_PER_STEP
    with torch.no_grad():
        tokens = vq.encode(motion.float(), lengths)[:, :, 0]
    tokens = tokens[..., : int(lengths.max()) // FRAMES_PER_STEP]  # what the sampler's are
    return ClipBatch(
        [str(item["id"]) for item in items],
        [item["caption"] for item in items],
        motion,
        lengths,
        tokens,
    )


def _valid(batch: ClipBatch) -> torch.Tensor:
    return length_mask(batch.lengths // FRAMES_PER_STEP, batch.tokens.shape[-1])  # (B, T')


@torch.no_grad()
def masked_accuracy_from_text(
    net: MaskedTransformer, text: torch.Tensor, batch: ClipBatch
) -> float:
    """Share of the base codes the masked transformer's argmax gets right when every valid step
    is [MASK] (its first decoding pass: the caption and the length alone)."""
    valid = _valid(batch)
    inputs = torch.where(valid, net.vocabulary.mask_id, -1)
    logits = net.eval()(inputs, text, batch.lengths // FRAMES_PER_STEP)  # (B, T', K)
    return float((logits.argmax(-1) == batch.tokens[:, 0])[valid].float().mean())


@torch.no_grad()
def residual_accuracy_per_layer(
    net: ResidualTransformer, text: torch.Tensor, batch: ClipBatch
) -> list[float]:
    """Teacher-forced accuracy of each residual layer j = 1..Q-1: the argmax of layer j's logits
    given the clip's codes of the layers below, the caption, no guidance."""
    valid, steps = _valid(batch), batch.lengths // FRAMES_PER_STEP
    accuracies = []
    for layer in range(1, net.num_quantizers):
        logits = net.eval()(batch.tokens, text, steps, layer=layer)  # (B, T', K)
        hits = logits.argmax(-1) == batch.tokens[:, layer]
        accuracies.append(float(hits[valid].float().mean()))
    return accuracies


def _mpjpe_mm(vq: MotionVQVAE, codes: torch.Tensor, batch: ClipBatch) -> torch.Tensor:
    """(B, Q, T') codes -> (B,) mean joint error (mm) of their decoding against the clips, over
    each clip's frames; both sets of joints are recovered from features in the same way."""
    features = vq.decode_valid(codes[:, :, None])  # (B, 4 T', 263)
    frames = features.shape[1]
    generated = vq.view.geometry(features).positions
    real = vq.view.geometry(batch.motion[:, :frames].float()).positions  # (B, frames, 22, 3)
    valid = length_mask(batch.lengths, frames).to(generated.dtype)  # (B, frames)
    error = (generated - real).norm(dim=-1).mean(dim=-1)  # (B, frames)
    return 1000 * (error * valid).sum(1) / valid.sum(1)


def _base_only(codes: torch.Tensor) -> torch.Tensor:
    """(B, Q, T') -> the same with every layer above the base unused (-1)."""
    base = torch.full_like(codes, -1)
    base[:, 0] = codes[:, 0]
    return base


@torch.no_grad()
def check_generation(
    sampler: MoMaskSampler, batch: ClipBatch, *, seed: int = 0
) -> list[MoMaskClipResult]:
    """Generate every clip from its caption at its length; base-only and all-layer joint errors on
    the same generated base codes, beside those of the clip's own codes."""
    generators = [torch.Generator().manual_seed(seed + i) for i in range(len(batch.ids))]
    codes = sampler.tokens(batch.captions, batch.lengths, generator=generators)[:, :, 0]
    vq, valid = sampler.vq, _valid(batch)
    errors = {
        "base_mm": _mpjpe_mm(vq, _base_only(codes), batch),
        "full_mm": _mpjpe_mm(vq, codes, batch),
        "rvq_base_mm": _mpjpe_mm(vq, _base_only(batch.tokens), batch),
        "rvq_full_mm": _mpjpe_mm(vq, batch.tokens, batch),
    }
    agree = (codes == batch.tokens) & valid[:, None]  # (B, Q, T')
    shares = agree.sum(-1) / valid.sum(-1, keepdim=True)  # (B, Q)
    return [
        MoMaskClipResult(
            clip=clip,
            caption=batch.captions[i],
            frames=int(batch.lengths[i]),
            base_codes=float(shares[i, 0]),
            residual_codes=[float(s) for s in shares[i, 1:]],
            **{name: float(values[i]) for name, values in errors.items()},
        )
        for i, clip in enumerate(batch.ids)
    ]


def _train_stages(
    out: Path, data_root: Path, overrides: dict[str, Sequence[str]]
) -> tuple[dict[str, dict[str, float]], dict[str, float]]:
    """RVQ into ``out/rvq``, then the masked and residual transformers into ``out/mask`` and
    ``out/residual`` -> (final metrics, seconds) per stage."""
    data = f"data.root={data_root}"
    metrics, seconds = {}, {}
    for stage, config in (("rvq", "train_vq"), ("mask", "train_gen"), ("residual", "train_gen")):
        shutil.rmtree(out / stage, ignore_errors=True)  # a re-run trains afresh
        extra = (
            []
            if stage == "rvq"
            else [
                f"text.cache_dir={out / 'text_cache'}",
                f"vq_ckpt={out / 'rvq' / 'checkpoints' / 'last.ckpt'}",
            ]
        )
        start = time.perf_counter()
        cfg = _compose(
            config,
            out / stage,
            [f"experiment=overfit_momask_{stage}", data, *extra, *overrides[stage]],
        )
        metrics[stage] = train(cfg)
        seconds[stage] = time.perf_counter() - start
    return metrics, seconds


def run(
    out: Path,
    *,
    clips: int = DEFAULT_CLIPS,
    seed: int = 0,
    rvq_overrides: Sequence[str] = (),
    mask_overrides: Sequence[str] = (),
    residual_overrides: Sequence[str] = (),
) -> MoMaskOverfitReport:
    """The whole check into ``out``: data (``data/``), RVQ (``rvq/``), transformers (``mask/``,
    ``residual/``), measurements (``overfit_momask.json``)."""
    out = Path(out)
    data_root = write_momask_memorisation_set(out / "data", clips=clips, seed=seed)
    overrides = {"rvq": rvq_overrides, "mask": mask_overrides, "residual": residual_overrides}
    metrics, seconds = _train_stages(out, data_root, overrides)
    start = time.perf_counter()
    mask = load_momask(out / "mask")
    residual = load_momask(out / "residual", vq=mask.vq)
    batch = clip_batch(mask.vq, data_root, int(mask.config.data.max_length))
    sampler = MoMaskSampler(
        mask_net=mask.net, residual_net=residual.net, vq=mask.vq, text=mask.text
    )
    text = sampler.sentence(batch.captions)
    report = MoMaskOverfitReport(
        rvq_mpjpe_mm=float(metrics["rvq"].get("val/mpjpe_mm", float("nan"))),
        masked_accuracy=masked_accuracy_from_text(mask.net, text, batch),
        residual_accuracy=residual_accuracy_per_layer(residual.net, text, batch),
        clips=check_generation(sampler, batch, seed=seed),
        seconds=seconds | {"measurements": time.perf_counter() - start},
    )
    summary = {
        "passed": report.passed,
        "residual_helps": report.residual_helps,
        **{
            f"mean_{f}": report.mean(f)
            for f in ("base_mm", "full_mm", "rvq_base_mm", "rvq_full_mm")
        },
    }
    write_text_atomically(
        out / "overfit_momask.json", json.dumps(asdict(report) | summary, indent=2)
    )
    return report


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", type=Path, default=Path("outputs/overfit_momask"))
    parser.add_argument("--clips", type=int, default=DEFAULT_CLIPS, help="clips to memorise")
    parser.add_argument("--seed", type=int, default=0, help="synthetic dataset seed")
    for stage, config in (("rvq", "train_vq"), ("mask", "train_gen"), ("residual", "train_gen")):
        parser.add_argument(
            f"--{stage}",
            nargs="*",
            default=[],
            help=f"extra Hydra overrides of the {stage} {config}",
        )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="[%(asctime)s] %(message)s")
    with reported_write_errors(
        "python -m intermask.overfit_momask", fallback=args.out, elsewhere="choose another --out"
    ):
        report = run(
            args.out,
            clips=args.clips,
            seed=args.seed,
            rvq_overrides=args.rvq,
            mask_overrides=args.mask,
            residual_overrides=args.residual,
        )
    print(report.table())
    return 0 if report.passed else 1


if __name__ == "__main__":
    raise SystemExit(main())
