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
from intermask.utils.staging import write_text_atomically
from intermask.utils.write_errors import reported_write_errors
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
    run = _Run(report, dev, log, repeats)
    vq, module = build_models(size, dev)
    net = module.net.eval()
    steps = frames // FRAMES_PER_STEP
    run.add(_forward_row(run, net, steps))
    best = _interaction_rows(run, net, vq, steps, batches, cuda_graphs)
    run.add(_interm_train_row(run, module, vq, frames, train_batch))
    _vq_rows(run, vq, vq_batch)
    run.add(_protocol_row(run, best, frames, test_split))


@dataclass
class _Run:
    """What the rows of one bench run share: the report they go to, the log, the device and
    how often a call is timed."""

    report: Report
    dev: torch.device
    log: Callable[[str], None]
    repeats: int
    threads: int = field(default_factory=torch.get_num_threads)

    def add(self, row: Row) -> None:
        """Derive the rate columns from the report's peak, record the row and log it."""
        if row.flops is not None:
            row.gflops_per_s = row.flops / row.seconds / 1e9
            row.pct_peak = 100 * row.gflops_per_s / self.report.peak_gflops
        self.report.rows.append(row)
        self.log(format_row(row))

    def row(self, name: str, batch: int, wall: float, cpu: float, **columns: Any) -> Row:
        """A row of ``batch`` samples measured in ``wall`` and ``cpu`` seconds per call."""
        return Row(name, str(self.dev), self.threads, batch, wall, cpu, wall / batch, **columns)

    def counted(self, name: str, fn: Callable[[], None], repeats: int) -> Row:
        """A no-grad call at batch 1: its FLOPs counted once, then timed over ``repeats``."""
        with torch.no_grad():
            with FlopCounterMode(display=False) as counter:
                fn()
            wall, cpu = _timed(fn, self.dev, repeats)
        return self.row(name, 1, wall, cpu, flops=counter.get_total_flops())

    def training(self, name: str, step: Callable[[], None], batch: int, note: str = "") -> Row:
        """An optimizer step: run once (the optimizer's state exists before memory is
        measured), then timed and its peak memory taken."""
        step()
        with PeakMemory(self.dev) as memory:
            wall, cpu = _timed(step, self.dev, self.repeats, warm=True)
        return self.row(
            name, batch, wall, cpu, samples_per_s=batch / wall, peak_memory_mb=memory.mb, note=note
        )


def _forward_row(run: _Run, net: InterMTransformer, steps: int) -> Row:
    """One Inter-M forward at batch 1 on ``steps`` token steps."""
    tokens = torch.randint(0, net.codebook_size, (1, net.rows, steps), device=run.dev)
    lengths = torch.tensor([steps], device=run.dev)
    text = _text(net, 1, run.dev)

    def forward() -> None:
        net(tokens, tokens, text, lengths)

    return run.counted("interm_forward", forward, run.repeats)


def _interaction_rows(
    run: _Run,
    net: InterMTransformer,
    vq: MotionVQVAE,
    steps: int,
    batches: tuple[int, ...],
    cuda_graphs: bool,
) -> Row:
    """Whole interactions (generation and VQ decoding) per batch size, recorded with the best
    per-sample time marked; returns that best row. The graphs outlive a call, as in the
    protocol."""
    graphed = GraphedForward(net, enabled=cuda_graphs)
    rows = []
    for batch in batches:
        text = _text(net, batch, run.dev)
        lengths = torch.full((batch,), steps, device=run.dev)

        @torch.no_grad()
        def interaction(text=text, lengths=lengths, batch=batch, forward=graphed) -> None:
            codes = generate(net, text, lengths, seeds=list(range(batch)), forward=forward)
            decode_tokens(vq, codes)

        with FlopCounterMode(display=False) as counter:
            interaction(forward=None)  # eager: a replayed graph runs no countable operator
        wall, cpu = _timed(interaction, run.dev, max(1, run.repeats // 2))  # its warm-up captures
        rows.append(run.row("interaction", batch, wall, cpu, flops=counter.get_total_flops()))
    best = min(rows, key=lambda r: r.per_sample_seconds)
    best.best = True
    for row in rows:
        run.add(row)
    return best


def _interm_train_row(
    run: _Run, module: InterMModule, vq: MotionVQVAE, frames: int, train_batch: int
) -> Row:
    """An Inter-M optimizer step on ``train_batch`` random crops of ``frames`` frames."""
    module.train()
    optimizer = module.optimizer_factory(module.net.parameters())
    batch = {
        "motion": torch.randn(train_batch, 2, frames, *vq.view.feature_shape, device=run.dev),
        "length": torch.full((train_batch,), frames, device=run.dev),
        "caption": [CAPTIONS[i % len(CAPTIONS)] for i in range(train_batch)],
    }
    generator = torch.Generator(device=run.dev).manual_seed(0)

    def train_step() -> None:
        losses = module.compute_losses(batch, condition_drop=0.1, generator=generator)
        optimizer.zero_grad(set_to_none=True)
        losses.total.backward()
        optimizer.step()

    unroll = "on" if module.hparams.step_unroll else "off"
    return run.training("interm_train_step", train_step, train_batch, f"step unroll {unroll}")


def _vq_rows(run: _Run, vq: MotionVQVAE, vq_batch: int) -> None:
    """Record a VQ-VAE optimizer step on ``vq_batch`` 64-frame windows, then the encode + decode
    round trip of one window."""
    vq_module = VQVAEModule(net=vq, optimizer=torch.optim.AdamW).to(run.dev).train()
    vq_optimizer = torch.optim.AdamW(vq.parameters(), lr=2e-4)
    windows = torch.randn(vq_batch, 64, *vq.view.feature_shape, device=run.dev)

    def vq_step() -> None:
        losses = vq_module.compute_losses({"motion": windows})
        vq_optimizer.zero_grad(set_to_none=True)
        losses.total.backward()
        vq_optimizer.step()

    vq.requires_grad_(True)
    run.add(run.training("vq_train_step", vq_step, vq_batch))
    vq.eval()
    window = windows[:1]

    def roundtrip() -> None:
        vq.decode(vq.encode(window))

    run.add(run.counted("vq_roundtrip", roundtrip, run.repeats * 3))


def _protocol_row(run: _Run, best: Row, frames: int, test_split: Path | None) -> Row:
    """The protocol's generations (replications x test items + MultiModality) at ``best``'s
    per-sample time."""
    constants: ProtocolConstants = instantiate(
        OmegaConf.load(config_dir() / "protocol/interhuman.yaml")
    )
    clips, source = _test_clips(test_split)
    items = clips // constants.eval_batch_size * constants.eval_batch_size  # drop_last
    multimodality = constants.mm_replications * constants.mm_texts * constants.mm_generations
    count = constants.replications * items + multimodality
    seconds = count * best.per_sample_seconds
    return Row(
        "protocol", str(run.dev), run.threads, best.batch, seconds,
        count * best.cpu_seconds / best.batch, best.per_sample_seconds,
        note=(
            f"{count} generations at {frames} frames: {constants.replications} x {items} test "
            f"items ({source}) + {constants.mm_replications} x {constants.mm_texts} x "
            f"{constants.mm_generations} MultiModality = {seconds / 3600:.1f} h"
        ),
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
    name = f"bench_{args.size}_{report.machine['device'].replace(':', '')}_{report.machine['threads']}t.json"
    path = args.out / name
    with reported_write_errors(
        "python -m intermask.bench", fallback=path, elsewhere="choose another --out"
    ):
        write_text_atomically(path, json.dumps(asdict(report), indent=2) + "\n")
    print(f"written {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
