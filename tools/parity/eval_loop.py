"""The authors' evaluation loop (gohar-malik/InterMask ``eval.py``) beside ours, on the same data
and the same random-weight models: every metric of every replication, and the CPU time of both.

    python tools/parity/eval_loop.py --reference PATH [--clips N] [--replications R]

In a work folder laid out as the authors' code expects its working directory (``data/InterHuman``,
``data/stats``, ``checkpoints/``), this script

1. writes the embedded InterHuman data (``intermask data synth``; every clip in the test split);
2. writes a random-weight release: the InterHuman tokenizer, the generator (``opt.txt`` +
   ``model/*.tar``), InterGen's ``interclip.ckpt`` with an ``eval_model.yaml``, and
   ``global_mean.npy``/``global_std.npy``, all at reduced widths;
3. converts it with ``intermask convert-reference`` (the console script, in a subprocess);
4. runs ``eval.py`` itself (its ``__main__``, imported from ``--reference``) with ``--gpu_id -1``;
5. runs ``python -m intermask.evaluate``'s ``evaluate`` twice in this process: in the reference
   order (``experiment=eval_reference_loop``) from the generator states eval.py had when its first
   replication began, and in the default batched order;
6. prints per metric both runs' values per replication (and mean +- CI95) and the CPU seconds per
   generated interaction of the three runs.

What is patched for the authors' code, in memory only: OpenAI's ``clip`` package (a stand-in that
returns our random text tower: no download), ``torch.cuda.set_device`` and ``Tensor.cuda`` (CPU),
and ``numpy.core.umath_tests`` (removed in numpy 2; imported by their visualization code, which
``--save_vis False`` never runs). Their metric functions, generator and tokenizer are wrapped to
record what they return and the CPU time they take; nothing they compute is changed.

Both sides' text towers are one random CLIP-shaped tower (width 768, ``--text-layers`` layers;
ViT-L/14@336px has 12, about 1 CPU second per caption here). The stand-in rounds the tower's output
to fp16, as our text cache stores it, so both generators see the same bits.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import runpy
import subprocess
import sys
import tempfile
import time
import types
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
from intermask_release import write_release  # noqa: E402

SEED = 20260512
MARKER = "eval.py"
EVAL_MODEL = {"NAME": "InterCLIP", "INPUT_DIM": 258, "LATENT_DIM": 128, "FF_SIZE": 256,
              "NUM_LAYERS": 2, "NUM_HEADS": 8, "DROPOUT": 0.1, "ACTIVATION": "gelu"}  # fmt: skip
OURS_INTERCLIP = {"width": 128, "layers": 2, "heads": 8, "ff": 256, "text_ff": 256}
TEXT_WIDTH, TEXT_HEADS = 768, 12
METRICS = ("top1", "top2", "top3", "fid", "mm_dist", "diversity", "multimodality")


def _release_options(**options: Any) -> dict[str, str]:
    base = {"checkpoints_dir": "./checkpoints", "gpu_id": 0, "is_train": True,
            "is_continue": False, "cache": True, "batch_size": 8}  # fmt: skip
    return {k: str(v) for k, v in {**base, **options}.items()}


VQ_OPTIONS = _release_options(dataset_name="interhuman", name="vq_parity", motion_rep="global",
                              nb_code=32, code_dim=32, output_emb_width=32, width=32, depth=2,
                              dilation_growth_rate=3, down_t=2, stride_t=2, vq_act="relu",
                              vq_norm=None, num_quantizers=1, shared_codebook=False,
                              quantize_dropout_prob=0.2, mu=0.99, window_size=16)  # fmt: skip
GENERATOR_OPTIONS = _release_options(dataset_name="interhuman", name="trans_parity",
                                     vq_name="vq_parity", motion_rep="global", latent_dim=96,
                                     n_heads=6, n_layers=2, ff_size=128, dropout=0.2,
                                     force_mask=False, cond_drop_prob=0.1, step_unroll=1.0,
                                     interaction_mask_prob=0.2, seed=3407,
                                     gumbel_sample=False)  # fmt: skip


# ---------------------------------------------------------------------- the shared text tower
def text_config(folder: Path, layers: int) -> str:
    """Register a CLIP-shaped text tower (width 768, ``layers`` layers) with open_clip."""
    import open_clip

    name = f"intermask-parity-text-{layers}"
    folder.mkdir(parents=True, exist_ok=True)
    config = {"embed_dim": TEXT_WIDTH,
              "vision_cfg": {"image_size": 32, "layers": 1, "width": 64, "head_width": 32,
                             "patch_size": 16},
              "text_cfg": {"context_length": 77, "vocab_size": 49408, "width": TEXT_WIDTH,
                           "heads": TEXT_HEADS, "layers": layers}}  # fmt: skip
    (folder / f"{name}.json").write_text(json.dumps(config))
    open_clip.add_model_config(folder)
    return name


def text_encoder(name: str):
    from intermask.text.clip_encoder import FrozenCLIPTextEncoder

    return FrozenCLIPTextEncoder(model_name=name, pretrained=None, quick_gelu=True, seed=0)


class _SequenceFirst(nn.Module):
    """OpenAI CLIP's transformer call: (L, N, D) in and out, the causal mask inside."""

    def __init__(self, transformer: nn.Module, mask: torch.Tensor) -> None:
        super().__init__()
        self.inner = transformer
        self.register_buffer("attn_mask", mask, persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.inner(x.permute(1, 0, 2), attn_mask=self.attn_mask).permute(1, 0, 2)


class _Fp16Rounded(nn.Module):
    """The final LayerNorm, its output rounded to fp16 as our text cache stores features."""

    def __init__(self, norm: nn.Module) -> None:
        super().__init__()
        self.inner = norm

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.inner(x).half().float()


class _ClipStandIn(nn.Module):
    """What ``clip.load`` gives the authors' modules: the pieces of our random tower."""

    def __init__(self, encoder) -> None:
        super().__init__()
        self.token_embedding = encoder.token_embedding
        self.positional_embedding = encoder.positional_embedding
        self.transformer = _SequenceFirst(encoder.transformer, encoder.attn_mask)
        self.ln_final = _Fp16Rounded(encoder.ln_final)
        self.dtype = torch.float32


def patch_for_cpu(encoder) -> None:
    common.clip_stub(
        _ClipStandIn(encoder), lambda texts, truncate=True: encoder.tokenize(list(texts))
    )
    torch.Tensor.cuda = lambda self, *args, **kwargs: self  # type: ignore[method-assign]
    torch.cuda.set_device = lambda *args, **kwargs: None
    shim = types.ModuleType("numpy.core.umath_tests")
    shim.matrix_multiply = np.matmul
    sys.modules["numpy.core.umath_tests"] = shim


# ---------------------------------------------------------------------- data and release
def write_data(work: Path, clips: int) -> Path:
    root = work / "data" / "InterHuman"
    intermask = Path(sys.executable).parent / "intermask"
    subprocess.run([str(intermask), "data", "synth", "--out", str(root), "--format",
                    "interhuman", "--clips", str(clips), "--seed", "1"],
                   check=True, capture_output=True)  # fmt: skip
    ids = [i for split in ("train", "val", "test")
           for i in (root / "split" / f"{split}.txt").read_text().split()]  # fmt: skip
    (root / "split" / "test.txt").write_text("".join(f"{i}\n" for i in ids))
    (root / "interaction_meta.json").unlink()  # the reference has no labels: no success column
    return root


def write_statistics(root: Path, work: Path) -> tuple[Path, Path]:
    """The release's global_mean.npy / global_std.npy: our features' statistics (train split)."""
    from intermask.data.interhuman import InterHumanDataset

    reader = InterHumanDataset.for_statistics(root, "train")
    features = torch.cat([f.reshape(-1, 262) for f in reader.stats_sequences()]).double()
    mean, std = features.mean(0).numpy(), features.std(0).clamp_min(1e-3).numpy()
    paths = (
        work / "data" / "stats" / "global_mean.npy",
        work / "data" / "stats" / "global_std.npy",
    )
    paths[0].parent.mkdir(parents=True, exist_ok=True)
    for path, values in zip(paths, (mean, std), strict=True):
        np.save(path, values.astype(np.float32))
    return paths


def write_release_files(work: Path) -> dict[str, Path]:
    """Random weights in the release layout, from the authors' own module trees."""
    from argparse import Namespace

    from models.evaluator.evaluator_models import InterCLIP
    from models.mask_transformer.transformer import MaskTransformer
    from models.vq.model import RVQVAE
    from utils.get_opt import get_opt

    checkpoints = work / "checkpoints"
    paths = {}
    folder = checkpoints / "interhuman"
    vq_opt = _their_opt(VQ_OPTIONS, folder / "options_vq.txt", get_opt)
    vq_opt.joints_num = 22
    vq = RVQVAE(vq_opt, 12, vq_opt.nb_code, vq_opt.code_dim, vq_opt.code_dim, vq_opt.down_t,
                vq_opt.stride_t, vq_opt.width, vq_opt.depth, vq_opt.dilation_growth_rate,
                vq_opt.vq_act, None)  # fmt: skip
    state = common.build_state(common.weight_recipe(vq.state_dict()), seed=SEED)
    written = write_release(folder / "vq_parity", "vq_model", state, VQ_OPTIONS)
    paths["vq"] = written.rename(written.parent / "best_fid.tar")  # what eval.py loads
    opt = _their_opt(GENERATOR_OPTIONS, folder / "options_trans.txt", get_opt)
    opt.num_tokens, opt.code_dim = vq_opt.nb_code, vq_opt.code_dim
    trans = MaskTransformer(code_dim=opt.code_dim, cond_mode="text", latent_dim=opt.latent_dim,
                            ff_size=opt.ff_size, num_layers=opt.n_layers, num_heads=opt.n_heads,
                            dropout=opt.dropout, clip_dim=768, cond_drop_prob=opt.cond_drop_prob,
                            clip_version="ViT-L/14@336px", opt=opt)  # fmt: skip
    release = {k: v for k, v in trans.state_dict().items() if not k.startswith("clip_")}
    state = common.build_state(common.weight_recipe(release, keep=("position_enc.",)), seed=SEED)
    paths["generator"] = write_release(
        folder / "trans_parity", "t2m_transformer", state, GENERATOR_OPTIONS
    )
    evaluator = InterCLIP(Namespace(**EVAL_MODEL))
    recipe = common.weight_recipe(evaluator.state_dict(), keep=("motion_encoder.sequence_pos",))
    state = common.build_state(recipe, seed=SEED)
    state["latent_scale"] = torch.ones(1)
    (checkpoints / "eval_model").mkdir(parents=True, exist_ok=True)
    paths["evaluator"] = checkpoints / "eval_model" / "interclip.ckpt"
    torch.save({"state_dict": {f"model.{k}": v for k, v in state.items()}}, paths["evaluator"])
    (checkpoints / "eval_model" / "eval_model.yaml").write_text(
        "".join(f"{k}: {v}\n" for k, v in EVAL_MODEL.items())
    )
    return paths


def _their_opt(options: dict[str, str], path: Path, get_opt: Callable) -> Any:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("".join(f"{k}: {v}\n" for k, v in options.items()))
    opt = get_opt(str(path), "cpu", complete=False)
    path.unlink()
    return opt


def convert(work: Path, paths: dict[str, Path], statistics, text_name: str) -> Path:
    """``intermask convert-reference`` as a user runs it; the run's text tower set to ours."""
    from omegaconf import OmegaConf

    out = work / "converted"
    intermask = Path(sys.executable).parent / "intermask"
    subprocess.run([str(intermask), "convert-reference", "--vq", str(paths["vq"]), "--generator",
                    str(paths["generator"]), "--out", str(out), "--mean", str(statistics[0]),
                    "--std", str(statistics[1])], check=True, capture_output=True)  # fmt: skip
    config_path = out / "gen" / "config.yaml"
    config = OmegaConf.load(config_path)
    config.text.encoder.model_name = text_name
    config.text.encoder.pretrained = None  # offline: the random tower both sides share
    config.text.encoder.quick_gelu = True
    config.text.encoder.seed = 0
    config.text.cache_dir = str(work / "text_cache")
    OmegaConf.save(config, config_path)
    return out / "gen"


# ---------------------------------------------------------------------- the authors' loop
class _Recorder:
    """What the authors' metric functions return, per replication, and CPU times."""

    def __init__(self) -> None:
        self.replications: list[dict[str, list]] = []
        self.start: float | None = None
        self.generation_cpu_s = 0.0
        self.generations = 0
        self.total_cpu_s = 0.0

    def event(self, kind: str, value: Any) -> None:
        self.replications[-1].setdefault(kind, []).append(value)

    def metrics(self) -> list[dict[str, dict[str, float]]]:
        """Per replication: {row: {metric: value}} as eval.py computes them (same arithmetic)."""
        out = []
        for events in self.replications:
            half = len(events["dist"]) // 2
            rows = {}
            for name, part in (("gt", slice(0, half)), ("gen", slice(half, None))):
                dist_sum, hits, size = 0, 0, 0
                for trace, count in events["dist"][part]:
                    dist_sum, size = dist_sum + trace, size + count
                for top_k in events["top_k"][part]:
                    hits = hits + top_k.sum(axis=0)
                rows[name] = {f"top{k + 1}": float(hits[k] / size) for k in range(3)}
                rows[name]["mm_dist"] = float(dist_sum / size)
            for name, fid, diversity in zip(("gt", "gen"), events["fid"], events["diversity"],
                                            strict=True):  # fmt: skip
                rows[name] |= {"fid": float(fid), "diversity": float(diversity)}
            rows["gen"]["multimodality"] = float(events["multimodality"][0])
            out.append(rows)
        return out


def _timed(recorder: _Recorder, function: Callable, *, count: bool = False) -> Callable:
    def wrapper(*args, **kwargs):
        start = time.process_time()
        try:
            return function(*args, **kwargs)
        finally:
            recorder.generation_cpu_s += time.process_time() - start
            recorder.generations += int(count)

    return wrapper


def run_reference(checkout: Path, work: Path, args, recorder: _Recorder, state_path: Path) -> None:
    """eval.py's ``__main__`` with ``work`` as its working directory (its paths are relative)."""
    previous = (sys.argv, os.getcwd())
    os.chdir(work)
    try:
        _run_reference(checkout, work, args, recorder, state_path)
    finally:
        sys.argv = previous[0]
        os.chdir(previous[1])
    recorder.total_cpu_s = time.process_time() - recorder.start


def _run_reference(checkout: Path, work: Path, args, recorder: _Recorder, state_path: Path) -> None:
    import models.evaluator.evaluator as evaluator_module
    import utils.metrics as metrics
    from models.mask_transformer.transformer import MaskTransformer
    from models.vq.model import RVQVAE

    def record(kind: str, function: Callable, convert_result: Callable = lambda r: r) -> Callable:
        def wrapper(*a, **k):
            result = function(*a, **k)
            recorder.event(kind, convert_result(result))
            return result

        return wrapper

    metrics.euclidean_distance_matrix = record(
        "dist", metrics.euclidean_distance_matrix, lambda d: (d.trace(), d.shape[0])
    )
    metrics.calculate_top_k = record("top_k", metrics.calculate_top_k)
    metrics.calculate_frechet_distance = record("fid", metrics.calculate_frechet_distance)
    metrics.calculate_diversity = record("diversity", metrics.calculate_diversity)
    metrics.calculate_multimodality = record("multimodality", metrics.calculate_multimodality)
    original_loader = evaluator_module.get_motion_loader

    def get_motion_loader(*a, **k):  # called first in every replication
        if recorder.start is None:
            recorder.start = time.process_time()
            common_streams().save(state_path)
        recorder.replications.append({})
        return original_loader(*a, **k)

    evaluator_module.get_motion_loader = get_motion_loader
    MaskTransformer.generate = _timed(recorder, MaskTransformer.generate, count=True)
    RVQVAE.forward_decoder = _timed(recorder, RVQVAE.forward_decoder)
    argv = ["eval.py", "--gpu_id", "-1", "--name", "trans_parity", "--dataset_name", "interhuman",
            "--mm_num_samples", str(args.mm_texts), "--mm_num_repeats", str(args.mm_generations),
            "--mm_num_times", str(args.mm_pairs), "--diversity_times", str(args.diversity_pairs),
            "--replication_times", str(args.replications),
            "--time_steps", str(args.time_steps)]  # fmt: skip
    sys.argv = argv
    with open(work / "reference_eval.log", "w", buffering=1) as sink:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            runpy.run_path(str(checkout / "eval.py"), run_name="__main__")


def common_streams():
    from intermask.evaluation.reference_order import Streams

    return Streams.from_globals()


# ---------------------------------------------------------------------- ours
def run_ours(work: Path, gen: Path, args, order: str, state: Path | None, timer: dict) -> dict:
    from hydra import compose, initialize_config_dir

    from intermask.evaluate import evaluate
    from intermask.interm.sampler import InteractionSampler

    overrides = [
        "data=interhuman", f"data.root={work / 'data' / 'InterHuman'}", "data.num_workers=0",
        f"paths.data_dir={work}", f"paths.output_dir={work / ('ours_' + order)}",
        f"gen_ckpt={gen}", f"eval_ckpt={work / 'checkpoints' / 'eval_model' / 'interclip.ckpt'}",
        "device=cpu", "penetration.modes=[]", "protocol.eval_batch_size=96",
        f"protocol.replications={args.replications}",
        f"protocol.mm_replications={args.replications}",
        f"protocol.diversity_pairs={args.diversity_pairs}", f"protocol.mm_texts={args.mm_texts}",
        f"protocol.mm_generations={args.mm_generations}", f"protocol.mm_pairs={args.mm_pairs}",
        "protocol.seed=3407",
        "released_evaluator.interclip={" + ",".join(f"{k}:{v}" for k, v in OURS_INTERCLIP.items())
        + "}",
    ]  # fmt: skip
    if order == "reference":
        overrides += ["experiment=eval_reference_loop", f"reference_state={state}"]
    overrides.append(f"sampler.iterations={args.time_steps}")
    original = InteractionSampler.__call__

    def timed(self, captions, lengths, **kwargs):
        start = time.process_time()
        try:
            return original(self, captions, lengths, **kwargs)
        finally:
            timer["generation_cpu_s"] = timer.get("generation_cpu_s", 0.0) + (
                time.process_time() - start
            )
            timer["generated"] = timer.get("generated", 0) + len(lengths)

    InteractionSampler.__call__ = timed
    config_dir = str(common.REPO / "configs")
    try:
        with initialize_config_dir(config_dir=config_dir, version_base="1.3"):
            cfg = compose("eval", overrides=overrides)
        with contextlib.redirect_stdout(io.StringIO()):
            return evaluate(cfg)
    finally:
        InteractionSampler.__call__ = original


# ---------------------------------------------------------------------- the table
def _equal4(a: float, b: float) -> bool:
    return f"{a:.4g}" == f"{b:.4g}" or math.isclose(a, b, rel_tol=5e-5, abs_tol=1e-12)


def _summary(values: list[float]) -> str:
    data = np.asarray(values, dtype=np.float64)
    return f"{data.mean():.5g} ± {1.96 * data.std() / math.sqrt(len(data)):.3g}"


def print_table(reference: list[dict], ours: dict, default: dict, replications: int) -> bool:
    rows = {"gt": "Ground Truth", "gen": "InterMask"}
    equal_all = True
    print(
        "\n| row | metric | rep | eval.py | ours (reference order) | equal (4 s.d.) | ours (batched) |"
    )
    print("|---|---|---|---|---|---|---|")
    for key, row in rows.items():
        for metric in METRICS:
            if metric not in ours["rows"][row]:
                continue
            mine = ours["rows"][row][metric]["values"]
            batched = default["rows"][row].get(metric, {}).get("values", [])
            theirs = [r[key][metric] for r in reference]
            for rep in range(replications):
                equal = _equal4(theirs[rep], mine[rep])
                equal_all &= equal
                other = f"{batched[rep]:.6g}" if rep < len(batched) else "-"
                print(f"| {row} | {metric} | {rep} | {theirs[rep]:.6g} | {mine[rep]:.6g} | "
                      f"{'yes' if equal else 'NO'} | {other} |")  # fmt: skip
            other = _summary(batched) if batched else "-"
            print(f"| {row} | {metric} | mean ± CI95 | {_summary(theirs)} | {_summary(mine)} | "
                  f"| {other} |")  # fmt: skip
    return equal_all


def main() -> int:
    cli = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    cli.add_argument("--reference", required=True, type=Path, help="the authors' checkout")
    cli.add_argument(
        "--clips", type=int, default=100, help="test clips (>= 97: eval.py batches 96)"
    )
    cli.add_argument("--replications", type=int, default=2)
    cli.add_argument(
        "--time-steps", type=int, default=10, help="eval.py --time_steps (its default: 20)"
    )
    cli.add_argument("--mm-texts", type=int, default=3, help="eval.py --mm_num_samples")
    cli.add_argument("--mm-generations", type=int, default=6, help="--mm_num_repeats")
    cli.add_argument("--mm-pairs", type=int, default=5, help="--mm_num_times")
    cli.add_argument("--diversity-pairs", type=int, default=50, help="--diversity_times")
    cli.add_argument("--text-layers", type=int, default=1,
                     help="layers of the shared random CLIP-shaped text tower (ViT-L/14: 12)")  # fmt: skip
    cli.add_argument("--work", type=Path, help="work folder (default: a temporary one)")
    args = cli.parse_args()
    if args.clips < 97 or args.diversity_pairs >= 96:
        cli.error("eval.py batches 96 test items (drop_last) and needs diversity pairs < 96")
    with contextlib.ExitStack() as stack:
        work = args.work or Path(stack.enter_context(tempfile.TemporaryDirectory()))
        work = work.resolve()
        work.mkdir(parents=True, exist_ok=True)
        (work / "visualization").symlink_to(args.reference.resolve() / "visualization")
        text_name = text_config(work / "clip_configs", args.text_layers)
        encoder = text_encoder(text_name)
        patch_for_cpu(encoder)
        print(f"work folder {work}; text tower {text_name} (random, width {TEXT_WIDTH})")
        root = write_data(work, args.clips)
        statistics = write_statistics(root, work)
        recorder, state = _Recorder(), work / "reference_streams.pt"
        with common.reference_modules(args.reference, MARKER):
            paths = write_release_files(work)
            gen = convert(work, paths, statistics, text_name)
            run_reference(args.reference.resolve(), work, args, recorder, state)
        cache_start = time.process_time()
        captions = _test_captions(root)
        _fill_text_cache(gen, captions)
        cache_cpu = time.process_time() - cache_start
        timers = {"reference": {}, "batched": {}}
        ours = run_ours(work, gen, args, "reference", state, timers["reference"])
        default = run_ours(work, gen, args, "batched", None, timers["batched"])
        equal = print_table(recorder.metrics(), ours, default, args.replications)
        _print_timing(recorder, ours, default, timers, cache_cpu, len(captions))
        print(f"\nevery metric of every replication equal to 4 significant digits: {equal}")
    return 0


def _test_captions(root: Path) -> list[str]:
    from intermask.evaluation.reference_order import caption_lines

    ids = (root / "split" / "test.txt").read_text().split()
    return sorted({c.strip() for i in ids for c in caption_lines(root / "annots" / f"{i}.txt")})


def _fill_text_cache(gen: Path, captions: list[str]) -> None:
    from hydra.utils import instantiate
    from omegaconf import OmegaConf

    instantiate(OmegaConf.load(gen / "config.yaml").text).precompute(captions)


def _print_timing(recorder, ours, default, timers, cache_cpu, captions) -> None:
    lines = [("eval.py (batch 1, CLIP per call)", recorder.total_cpu_s,
              recorder.generation_cpu_s, recorder.generations)]  # fmt: skip
    for name, result in (("ours, reference order", ours), ("ours, batched (default)", default)):
        key = "reference" if "reference" in name else "batched"
        lines.append((name, result["header"]["protocol_cpu_s"],
                      timers[key]["generation_cpu_s"], timers[key]["generated"]))  # fmt: skip
    print(
        "\n| run | loop CPU s | generated | CPU s / interaction (loop) | "
        "CPU s / interaction (generation only) |"
    )
    print("|---|---|---|---|---|")
    for name, total, generation, count in lines:
        print(
            f"| {name} | {total:.1f} | {count} | {total / count:.4f} | {generation / count:.4f} |"
        )
    base = lines[0]
    for name, total, generation, count in lines[1:]:
        print(f"speed-up of {name} over eval.py: {base[1] / base[3] / (total / count):.1f}x "
              f"(loop), {base[2] / base[3] / (generation / count):.1f}x (generation)")  # fmt: skip
    print(
        f"text cache fill before our runs (once per caption set, not in the loops above): "
        f"{cache_cpu:.1f} CPU s for {captions} captions; CPU seconds are process CPU time "
        f"(all threads, torch {torch.get_num_threads()} threads), on a shared machine"
    )


if __name__ == "__main__":
    raise SystemExit(main())
