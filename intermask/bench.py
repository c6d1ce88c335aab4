"""``make bench``: the hot paths' speed on this machine, each against the machine's own peak.

Every row runs the framework's own code on random weights (speed does not depend on what the
weights learned) at one model size, ``paper`` (Table 4: the 41M-weight VQ-VAE, the 54M-weight
Inter-M, CLIP ViT-L/14@336px's text tower) or ``demo`` (the CPU demo's experiments):

========================  ======================================================================
row                       what is timed
========================  ======================================================================
``peak``                  a dense matmul (2048^3, fp32 on CPU, bf16 on CUDA): the yardstick of
                          every ``% peak`` column, measured in the same run
``interm_forward``        one Inter-M forward at batch 1, 300 frames (751 tokens at the paper
                          size), counted FLOPs (``torch.utils.flop_counter``)
``interaction``           one whole interaction per batch size (20 iterations, CFG 2 in one
                          doubled forward, top-k, VQ decode of both persons): per-sample time;
                          the best batch is marked. On CUDA the passes replay CUDA graphs
                          (``--no-cuda-graphs``: eager); FLOPs are counted on an eager run
``interm_train_step``     an Inter-M optimizer step (masking, BERT corruption, step unroll,
                          AdamW) at batch 4 on 300-frame crops, VQ encoding included (no token
                          cache): samples/s and the step's peak memory
``vq_train_step``         a VQ-VAE optimizer step on 64-frame windows
``vq_roundtrip``          encode + decode of one 64-frame window
``protocol``              the protocol's generations (replications x test items + MultiModality),
                          extrapolated from the best per-sample time
========================  ======================================================================

Times are medians of ``repeats`` runs after a warm-up run, as wall and process CPU seconds.
Peak memory is the process's resident-set high-water mark during the row (Linux, reset through
``/proc/self/clear_refs``; CUDA: ``max_memory_allocated``). The JSON schema is in
``docs/performance.md``.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf
from torch.utils.flop_counter import FlopCounterMode

from intermask.config_files import config_dir
from intermask.data.common import read_id_list
from intermask.evaluation.protocol import ProtocolConstants
from intermask.interm.decoding import generate
from intermask.interm.graphs import GraphedForward
from intermask.interm.model import InterMTransformer, TextFeatures
from intermask.interm.module import InterMModule
from intermask.interm.sampler import decode_tokens
from intermask.text.cache import TextFeatureCache
from intermask.text.clip_encoder import padding_mask_from_eot
from intermask.utils.precision import BF16, OPTIONS, PrecisionChoice, resolve_precision
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE
from intermask.vq.module import VQVAEModule

SCHEMA = 1
SIZES = {  # experiment overrides of (train_vq, train_gen) per model size
    "paper": ((), ()),
    "demo": (("experiment=vq_demo",), ("experiment=gen_demo",)),
}
CAPTIONS = (
    "two people shake hands.",
    "one person pushes the other, who steps back.",
    "the two people hug each other.",
    "one person waves and the other walks over.",
)


@dataclass
class Row:
    """One measurement; fields a row does not measure stay None."""

    name: str
    device: str
    threads: int
    batch: int
    seconds: float  # wall, per call (median)
    cpu_seconds: float  # process CPU time per call (median), all threads together
    per_sample_seconds: float
    flops: float | None = None  # counted per call
    gflops_per_s: float | None = None
    pct_peak: float | None = None
    samples_per_s: float | None = None
    peak_memory_mb: float | None = None
    best: bool = False
    note: str = ""


@dataclass
class Report:
    schema: int
    size: str
    machine: dict[str, Any]
    peak_gflops: float
    rows: list[Row] = field(default_factory=list)


# ---------------------------------------------------------------------------------- measuring


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _timed(
    fn: Callable[[], Any], device: torch.device, repeats: int, *, warm: bool = False
) -> tuple[float, float]:
    """(wall, CPU) seconds per call: medians of ``repeats`` calls after one warm-up call
    (none when ``warm``: the caller has just run ``fn``)."""
    if not warm:
        fn()
        _sync(device)
    walls, cpus = [], []
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        fn()
        _sync(device)
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return statistics.median(walls), statistics.median(cpus)


class PeakMemory:
    """Peak memory during a block, in MB: the process's resident set on CPU (weights, optimizer
    state and whatever the allocator keeps included), allocated memory on CUDA; None where the
    platform cannot reset its high-water mark."""

    def __init__(self, device: torch.device) -> None:
        self.device, self.mb = device, None

    def __enter__(self) -> PeakMemory:
        if self.device.type == "cuda":
            torch.cuda.reset_peak_memory_stats(self.device)
            self.reset = True
        else:
            self.reset = _reset_rss_peak()
        return self

    def __exit__(self, *exc: object) -> None:
        if self.device.type == "cuda":
            self.mb = torch.cuda.max_memory_allocated(self.device) / 2**20
        elif self.reset:
            self.mb = _status_kb("VmHWM") / 1024


def _status_kb(key: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(f"{key}:"):
            return int(line.split()[1])
    raise KeyError(key)


def _reset_rss_peak() -> bool:
    """Reset the resident-set high-water mark to the current resident set (Linux); False where
    that is not possible."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return _status_kb("VmHWM") > 0
    except (OSError, KeyError):
        return False


def matmul_peak(
    device: torch.device,
    size: int = 2048,
    repeats: int = 10,
    dtype: torch.dtype | None = None,
) -> float:
    """GFLOP/s of a dense ``size``^3 matmul in ``dtype`` (default: fp32 on CPU, bf16 on CUDA)."""
    if dtype is None:
        dtype = torch.bfloat16 if device.type == "cuda" else torch.float32
    a = torch.randn(size, size, device=device, dtype=dtype)
    b = torch.randn(size, size, device=device, dtype=dtype)
    wall, _ = _timed(lambda: a @ b, device, repeats)
    return 2 * size**3 / wall / 1e9


def machine_record(device: torch.device) -> dict[str, Any]:
    record = {
        "cpu": _cpu_model(),
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "python": platform.python_version(),
        "device": str(device),
    }
    if device.type == "cuda":
        record["gpu"] = torch.cuda.get_device_name(device)
    return record


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


# ---------------------------------------------------------------------------------- models


def build_models(size: str, device: torch.device) -> tuple[MotionVQVAE, InterMModule]:
    """The VQ-VAE and the Inter-M module of a model size, random weights, on ``device``."""
    vq_overrides, gen_overrides = SIZES[size]
    with initialize_config_dir(config_dir=str(config_dir()), version_base="1.3"):
        vq_cfg = compose("train_vq", overrides=list(vq_overrides))
        gen_cfg = compose(
            "train_gen",
            overrides=[*gen_overrides, "vq_ckpt=unused", "text.cache_dir=null"]
            + (["text.encoder.pretrained=null"] if size == "paper" else []),
        )
    torch.manual_seed(0)
    vq = instantiate(vq_cfg.model.net).to(device)
    text: TextFeatureCache = instantiate(gen_cfg.text)
    module = InterMModule(
        net=instantiate(gen_cfg.model.net),
        vq=vq,
        text=text,
        optimizer=instantiate(gen_cfg.model.optimizer),
        warmup_fraction=0.0,
        step_unroll=bool(gen_cfg.model.step_unroll) or size == "paper",
        token_cache=False,  # every step encodes its crops, as the reference does
        validation_samples=0,
    ).to(device)
    return vq, module


def _text(net: InterMTransformer, batch: int, device: torch.device) -> TextFeatures:
    """Random per-token text features with CLIP's layout (77 tokens, end-of-text at 12)."""
    generator = torch.Generator().manual_seed(0)
    features = torch.randn(batch, 77, net.text_dim, generator=generator).to(device)
    eot = torch.full((batch,), 12, dtype=torch.long, device=device)
    return TextFeatures(features, eot, padding_mask_from_eot(eot, 77))


# ---------------------------------------------------------------------------------- rows


def bench(
    size: str = "paper",
    *,
    device: str = "cpu",
    frames: int = 300,
    batches: tuple[int, ...] = (1, 2, 4),
    repeats: int = 2,
    train_batch: int = 4,
    vq_batch: int = 32,
    test_split: Path | None = Path("data/InterHuman/split/test.txt"),
    precision: str = "auto",
    cuda_graphs: bool = True,
    log: Callable[[str], None] = print,
) -> Report:
    dev = torch.device(device)
    threads = torch.get_num_threads()
    choice = bench_precision(precision, dev)
    bf16 = choice.precision == BF16
    peak = matmul_peak(dev, dtype=torch.bfloat16 if bf16 else torch.float32)
    graphs = cuda_graphs and dev.type == "cuda"
    machine = {
        **machine_record(dev),
        "precision": choice.precision,
        "cuda_graphs": graphs,
    }
    report = Report(SCHEMA, size, machine, peak)
    log(
        f"peak: {peak:.1f} GFLOP/s ({report.machine['cpu']}, {threads} threads); "
        f"precision {choice.precision} ({choice.reason})"
    )
    # every row runs under the precision the trainer would pick (bf16 autocast or none)
    with torch.autocast(dev.type, dtype=torch.bfloat16, enabled=bf16):
        _rows(
            report, size, dev, log,
            frames=frames, batches=batches, repeats=repeats, train_batch=train_batch,
            vq_batch=vq_batch, test_split=test_split, cuda_graphs=graphs,
        )  # fmt: skip
    return report


def bench_precision(requested: str, device: torch.device) -> PrecisionChoice:
    """``auto`` (the trainer's choice for this device: bf16 autocast on CUDA with bf16 and on
    CPUs with native bf16, fp32 elsewhere), ``32`` or ``bf16``."""
    if requested not in OPTIONS:
        raise ValueError(f"bench precision must be one of {sorted(OPTIONS)}, got {requested!r}")
    return resolve_precision(OPTIONS[requested], device.type)


def _rows(
    report: Report,
    size: str,
    dev: torch.device,
    log: Callable[[str], None],
    *,
    frames: int,
    batches: tuple[int, ...],
    repeats: int,
    train_batch: int,
    vq_batch: int,
    test_split: Path | None,
    cuda_graphs: bool = False,
) -> None:
    """Measure every row into ``report`` (its peak is the yardstick of ``% peak``)."""
    threads, peak = torch.get_num_threads(), report.peak_gflops
    vq, module = build_models(size, dev)
    net = module.net.eval()
    steps = frames // FRAMES_PER_STEP

    def add(row: Row) -> None:
        if row.flops is not None:
            row.gflops_per_s = row.flops / row.seconds / 1e9
            row.pct_peak = 100 * row.gflops_per_s / peak
        report.rows.append(row)
        log(format_row(row))

    # one Inter-M forward
    tokens = torch.randint(0, net.codebook_size, (1, net.rows, steps), device=dev)
    lengths = torch.tensor([steps], device=dev)
    text = _text(net, 1, dev)
    with torch.no_grad():

        def forward() -> None:
            net(tokens, tokens, text, lengths)

        with FlopCounterMode(display=False) as counter:
            forward()
        wall, cpu = _timed(forward, dev, repeats)
    add(
        Row(
            "interm_forward", str(dev), threads, 1, wall, cpu, wall, flops=counter.get_total_flops()
        )
    )

    # whole interactions per batch size; the graphs outlive a call, as in the protocol
    graphed = GraphedForward(net, enabled=cuda_graphs)
    rows = []
    for batch in batches:
        text = _text(net, batch, dev)
        lengths = torch.full((batch,), steps, device=dev)

        @torch.no_grad()
        def interaction(text=text, lengths=lengths, batch=batch, forward=graphed) -> None:
            codes = generate(net, text, lengths, seeds=list(range(batch)), forward=forward)
            decode_tokens(vq, codes)

        with FlopCounterMode(display=False) as counter:
            interaction(forward=None)  # eager: a replayed graph runs no countable operator
        wall, cpu = _timed(interaction, dev, max(1, repeats // 2))  # its warm-up captures
        rows.append(
            Row(
                "interaction",
                str(dev),
                threads,
                batch,
                wall,
                cpu,
                wall / batch,
                flops=counter.get_total_flops(),
            )
        )
    best = min(rows, key=lambda r: r.per_sample_seconds)
    best.best = True
    for row in rows:
        add(row)

    # Inter-M training step
    module.train()
    optimizer = module.optimizer_factory(module.net.parameters())
    features = vq.view.feature_shape
    batch = {
        "motion": torch.randn(train_batch, 2, frames, *features, device=dev),
        "length": torch.full((train_batch,), frames, device=dev),
        "caption": [CAPTIONS[i % len(CAPTIONS)] for i in range(train_batch)],
    }
    generator = torch.Generator(device=dev).manual_seed(0)

    def train_step() -> None:
        losses = module.compute_losses(batch, condition_drop=0.1, generator=generator)
        optimizer.zero_grad(set_to_none=True)
        losses.total.backward()
        optimizer.step()

    def training_row(name: str, step: Callable[[], None], batch: int, note: str = "") -> Row:
        step()  # the optimizer's state exists before memory is measured
        with PeakMemory(dev) as memory:
            wall, cpu = _timed(step, dev, repeats, warm=True)
        return Row(
            name, str(dev), threads, batch, wall, cpu, wall / batch,
            samples_per_s=batch / wall, peak_memory_mb=memory.mb, note=note,
        )  # fmt: skip

    unroll = "on" if module.hparams.step_unroll else "off"
    add(training_row("interm_train_step", train_step, train_batch, f"step unroll {unroll}"))

    # VQ-VAE training step and round trip
    vq_module = VQVAEModule(net=vq, optimizer=torch.optim.AdamW).to(dev).train()
    vq_optimizer = torch.optim.AdamW(vq.parameters(), lr=2e-4)
    windows = torch.randn(vq_batch, 64, *features, device=dev)

    def vq_step() -> None:
        losses = vq_module.compute_losses({"motion": windows})
        vq_optimizer.zero_grad(set_to_none=True)
        losses.total.backward()
        vq_optimizer.step()

    vq.requires_grad_(True)
    add(training_row("vq_train_step", vq_step, vq_batch))
    vq.eval()
    window = windows[:1]
    with torch.no_grad():

        def roundtrip() -> None:
            vq.decode(vq.encode(window))

        with FlopCounterMode(display=False) as counter:
            roundtrip()
        wall, cpu = _timed(roundtrip, dev, repeats * 3)
    add(Row("vq_roundtrip", str(dev), threads, 1, wall, cpu, wall, flops=counter.get_total_flops()))

    # the protocol, extrapolated
    constants: ProtocolConstants = instantiate(
        OmegaConf.load(config_dir() / "protocol/interhuman.yaml")
    )
    clips, source = _test_clips(test_split)
    items = clips // constants.eval_batch_size * constants.eval_batch_size  # drop_last
    multimodality = constants.mm_replications * constants.mm_texts * constants.mm_generations
    count = constants.replications * items + multimodality
    seconds = count * best.per_sample_seconds
    add(
        Row(
            "protocol", str(dev), threads, best.batch, seconds, count * best.cpu_seconds / best.batch,
            best.per_sample_seconds,
            note=(
                f"{count} generations at {frames} frames: {constants.replications} x {items} test "
                f"items ({source}) + {constants.mm_replications} x {constants.mm_texts} x "
                f"{constants.mm_generations} MultiModality = {seconds / 3600:.1f} h"
            ),
        )
    )  # fmt: skip


def _test_clips(split: Path | None) -> tuple[int, str]:
    """InterHuman's test clips from its split file, or 1,000 when the release is not here."""
    if split is not None and split.is_file():
        return len(read_id_list(split, what="test split")), f"{split}"
    return 1000, "per 1,000 clips: no InterHuman test split here"


def format_row(row: Row) -> str:
    parts = [
        f"{row.name:<18} batch {row.batch:<3}",
        f"{row.seconds:9.3f} s",
        f"{row.cpu_seconds:9.3f} CPU s",
        f"{row.per_sample_seconds:8.3f} s/sample",
    ]
    if row.pct_peak is not None:
        parts.append(f"{row.gflops_per_s:7.1f} GFLOP/s = {row.pct_peak:5.1f}% peak")
    if row.samples_per_s is not None:
        parts.append(f"{row.samples_per_s:6.2f} samples/s")
    if row.peak_memory_mb is not None:
        parts.append(f"peak {row.peak_memory_mb:,.0f} MB")
    if row.best:
        parts.append("best batch")
    if row.note:
        parts.append(row.note)
    return "  ".join(parts)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m intermask.bench", description=__doc__.split("\n")[0]
    )
    parser.add_argument("--size", choices=sorted(SIZES), default="paper")
    parser.add_argument("--device", default="cpu", help="cpu or cuda (default cpu)")
    parser.add_argument("--threads", type=int, default=None, help="torch intra-op threads")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--batches", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--repeats", type=int, default=2)
    parser.add_argument("--train-batch", type=int, default=4, help="Inter-M training batch")
    parser.add_argument("--vq-batch", type=int, default=32, help="VQ-VAE training windows")
    parser.add_argument(
        "--test-split",
        type=Path,
        default=Path("data/InterHuman/split/test.txt"),
        help="InterHuman's test split, for the protocol's extrapolation",
    )
    parser.add_argument(
        "--precision",
        choices=sorted(OPTIONS),
        default="auto",
        help="auto: the trainer's choice for the device (bf16 autocast on CUDA and on CPUs with "
        "native bf16, fp32 elsewhere)",
    )
    parser.add_argument(
        "--cuda-graphs",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="CUDA: replay the decoding passes as CUDA graphs (the protocol's default)",
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/bench"))
    args = parser.parse_args(argv)
    if args.threads is not None:
        torch.set_num_threads(args.threads)
    report = bench(
        args.size,
        device=args.device,
        frames=args.frames,
        batches=tuple(args.batches),
        repeats=args.repeats,
        train_batch=args.train_batch,
        vq_batch=args.vq_batch,
        test_split=args.test_split,
        precision=args.precision,
        cuda_graphs=args.cuda_graphs,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    name = f"bench_{args.size}_{report.machine['device'].replace(':', '')}_{report.machine['threads']}t.json"
    path = args.out / name
    path.write_text(json.dumps(asdict(report), indent=2) + "\n")
    print(f"written {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
