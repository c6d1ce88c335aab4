"""Run the evaluation protocol: ``python -m intermask.evaluate [mode=...] gen_ckpt=... eval_ckpt=...``.

Thin by design: build the rows of the table for the chosen mode, run
:class:`~intermask.evaluation.protocol.ProtocolRunner`, write JSON + Markdown, log to TensorBoard and
print the table. ``make eval`` wraps it.
"""

from __future__ import annotations

import functools
import logging
import time
from collections.abc import Iterator
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import hydra
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig, OmegaConf

from intermask.evaluation.protocol import MotionSource, ProtocolConstants, ProtocolRunner
from intermask.evaluation.reference_order import ReferenceOrderLoop
from intermask.evaluation.report import markdown_table, write_results
from intermask.evaluation.sources import (
    ARFlowReaction,
    GroundTruth,
    InterMaskGeneration,
    InterMaskReaction,
    Measured,
    VQReconstruction,
    motion_joints,
)
from intermask.evaluation.text_motion import SoloReconstruction, TextToMotion
from intermask.train import CONFIG_DIR
from intermask.utils.files import file_hash, resolve_checkpoint
from intermask.utils.precision import resolve_precision
from intermask.utils.run_record import write_run_record

log = logging.getLogger(__name__)
MODES = ("interaction", "reaction", "reconstruction", "text_to_motion")
ORDERS = ("batched", "reference")  # batched: keyed draws (the default); reference: eval.py's order
SINGLE_PERSON = ("humanml3d",)  # dataset kinds of the text-to-motion table


def pick_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    return torch.device(name)


def _on(batch: dict[str, Any], device: torch.device) -> dict[str, Any]:
    return {k: v.to(device) if isinstance(v, torch.Tensor) else v for k, v in batch.items()}


def build_sources(
    cfg: DictConfig, normalizer, device: torch.device
) -> tuple[list[MotionSource], dict[str, Any]]:
    """The rows after the GT row for ``cfg.mode`` -> (sources, {checkpoint role: 'path (hash)'}).

    interaction: InterMask from ``gen_ckpt`` (after its VQ-VAE's reconstruction row when
    ``reconstruction_row``); reaction: InterMask's reaction mode from
    ``gen_ckpt`` and / or ARFlow from ``arflow_ckpt`` (its steps, guidance and step-ablation
    rows); reconstruction: the VQ-VAE of ``vq_ckpt``. Then the rows of ``rows`` (:func:`user_rows`).
    """
    checkpoints: dict[str, Any] = {}
    sources = _builtin_sources(cfg, normalizer, device, checkpoints)
    sources += user_rows(cfg, normalizer, device, checkpoints)
    names = [source.name for source in sources]
    repeated = sorted(
        {name for name in names if names.count(name) > 1} | {"Ground Truth"} & set(names)
    )
    if repeated:
        raise ValueError(f"two rows of the table would be named {repeated}: name each row apart")
    return sources, checkpoints


def own_row_keys(cfg: DictConfig) -> list[str]:
    """The keys of ``rows`` that are switched on (``rows.<key>=null`` leaves one out)."""
    return [key for key, spec in (cfg.get("rows") or {}).items() if spec is not None]


def user_rows(cfg: DictConfig, normalizer, device: torch.device, checkpoints) -> list[MotionSource]:
    """``rows``: rows of your own (docs/extending.md), each built by its config's ``_target_``
    with ``device`` (the evaluation's) and ``normalizer`` (the dataset's, or None); its
    resolved config goes into the results' header as ``rows.<key>``."""
    rows: list[MotionSource] = []
    for key in own_row_keys(cfg):
        spec = cfg.rows[key]
        if not isinstance(spec, DictConfig) or "_target_" not in spec:
            raise ValueError(
                f"rows.{key}: expected a config with a _target_ (the function or class that "
                f"builds the row), got {OmegaConf.to_container(spec) if isinstance(spec, DictConfig) else spec!r}"
            )
        row = instantiate(spec, device=device, normalizer=normalizer)
        if not isinstance(row, MotionSource):
            raise TypeError(
                f"rows.{key}: {spec._target_} returned a {type(row).__name__}, not a MotionSource "
                "(intermask.evaluation.protocol)"
            )
        checkpoints[f"rows.{key}"] = OmegaConf.to_container(spec, resolve=True)
        rows.append(row)
    return rows


def _builtin_sources(
    cfg: DictConfig, normalizer, device: torch.device, checkpoints: dict[str, Any]
) -> list[MotionSource]:
    """The rows the framework builds for ``cfg.mode`` (see :func:`build_sources`); none when
    only ``rows`` of your own are given."""
    from intermask.vq.load import load_vq

    own_rows = bool(own_row_keys(cfg))
    single_person = cfg.data.dataset in SINGLE_PERSON
    if single_person and cfg.mode not in ("text_to_motion", "reconstruction"):
        raise ValueError(
            f"mode={cfg.mode} does not apply to {cfg.data.dataset}: single-person data takes "
            "mode=text_to_motion or reconstruction"
        )
    if cfg.mode == "text_to_motion" and not single_person:
        raise ValueError(
            f"mode=text_to_motion needs single-person data (data=humanml3d), got {cfg.data.dataset}"
        )
    if cfg.mode == "reconstruction":
        if not cfg.vq_ckpt and own_rows:
            return []
        if not cfg.vq_ckpt:
            raise ValueError(
                "mode=reconstruction needs vq_ckpt=<train_vq run or its checkpoints/*.ckpt>"
            )
        vq_path = resolve_checkpoint(cfg.vq_ckpt, kind="VQ")  # a run folder: its last.ckpt
        checkpoints["vq"] = f"{vq_path} ({file_hash(vq_path)})"
        vq = load_vq(vq_path).to(device)
        row = SoloReconstruction(vq=vq) if single_person else VQReconstruction(vq=vq)
        return [row]
    if cfg.mode == "text_to_motion":
        if not cfg.mask_ckpt and own_rows:
            return []
        return _momask_rows(cfg, device, checkpoints)
    arflow_ckpt = cfg.get("arflow_ckpt") if cfg.mode == "reaction" else None
    if not cfg.gen_ckpt and not arflow_ckpt and own_rows:
        return []
    if not cfg.gen_ckpt and not arflow_ckpt:
        wanted = "gen_ckpt=<train_gen run or .ckpt>"
        if cfg.mode == "reaction":
            wanted += " and / or arflow_ckpt=<train_arflow run or .ckpt>"
        raise ValueError(f"mode={cfg.mode} needs {wanted}")
    sources: list[MotionSource] = []
    if cfg.gen_ckpt:
        sources += _intermask_rows(cfg, normalizer, device, checkpoints)
    if arflow_ckpt:
        sources += _arflow_rows(cfg, normalizer, device, checkpoints)
    return sources


def _momask_rows(cfg: DictConfig, device, checkpoints) -> list[MotionSource]:
    """MoMask's rows of its Table 1: the tokenizer's reconstruction (``reconstruction_row``),
    the base layer alone ("MoMask (base)"), and base + residual layers ("MoMask") when
    ``residual_ckpt`` is given. Both generated rows draw the same base tokens per batch."""
    from intermask.momask.load import load_momask_sampler
    from intermask.momask.sampler import MoMaskDecoding, MoMaskSampler

    if not cfg.mask_ckpt:
        raise ValueError(
            "mode=text_to_motion needs mask_ckpt=<masked transformer run> (and residual_ckpt=<"
            "residual transformer run> for the full MoMask row)"
        )
    settings = MoMaskDecoding(**OmegaConf.to_container(cfg.momask))
    full, paths = load_momask_sampler(
        cfg.mask_ckpt,
        cfg.residual_ckpt or None,
        vq_checkpoint=cfg.vq_ckpt or None,
        settings=settings,
    )
    for role, path in paths.items():
        checkpoints[role] = f"{path} ({file_hash(path)})"
    checkpoints["text_encoder"] = full.text.encoder.extra_repr()
    full.mask_net.to(device)
    full.text.encoder.to(device)
    if full.residual_net is not None:
        full.residual_net.to(device)
    base = MoMaskSampler(
        mask_net=full.mask_net,
        residual_net=None,
        vq=full.vq.to(device),
        text=full.text,
        settings=settings,
    )

    def rows_of(sampler: MoMaskSampler):
        def generate(captions, lengths, seeds):
            # one generator per sample, seeded by its protocol seed: a sample does not depend on
            # its batch, and both rows draw the same base tokens
            generators = [torch.Generator(device=device).manual_seed(int(s)) for s in seeds]
            out = sampler(captions, lengths.to(device), generator=generators)
            return sampler.vq.view.denormalize(out.features)

        return generate

    rows: list[MotionSource] = [TextToMotion(generate=rows_of(base), name="MoMask (base)")]
    if full.residual_net is not None:
        rows.append(TextToMotion(generate=rows_of(full), name="MoMask"))
    if cfg.reconstruction_row:
        rows.insert(0, SoloReconstruction(vq=full.vq))
    return rows


def _intermask_rows(cfg: DictConfig, normalizer, device, checkpoints) -> list[MotionSource]:
    from intermask.interm.decoding import Decoding
    from intermask.interm.load import load_generator
    from intermask.interm.sampler import InteractionSampler

    generator = load_generator(cfg.gen_ckpt, vq_checkpoint=cfg.vq_ckpt or None)
    checkpoints["generator"] = f"{generator.checkpoint} ({file_hash(generator.checkpoint)})"
    checkpoints["vq"] = f"{generator.vq_checkpoint} ({file_hash(generator.vq_checkpoint)})"
    checkpoints["text_encoder"] = generator.text.encoder.extra_repr()
    precision = resolve_precision(cfg.precision, device.type)
    checkpoints["generation_precision"] = f"{precision.precision} ({precision.reason})"
    sampler = InteractionSampler(
        net=generator.net.to(device),
        vq=generator.vq.to(device),
        text=generator.text,
        settings=Decoding(**OmegaConf.to_container(cfg.sampler)),
        cuda_graphs=cfg.cuda_graphs,
        precision=precision.precision,
    )
    generator.text.encoder.to(device)
    if cfg.mode == "interaction":
        rows: list[MotionSource] = [InterMaskGeneration(sampler=sampler)]
        if cfg.reconstruction_row:
            # the tokenizer's share of the gap: test motion through the generator's own VQ-VAE
            rows.insert(0, VQReconstruction(vq=generator.vq.to(device)))
        return rows
    return [
        InterMaskReaction(
            sampler=sampler,
            normalizer=normalizer,
            iterations=cfg.reaction.iterations,
            use_text=cfg.reaction.use_text,
        )
    ]


def _arflow_rows(cfg: DictConfig, normalizer, device, checkpoints) -> list[MotionSource]:
    """ARFlow at ``arflow.steps`` with guidance (and without, and with each mode of
    ``arflow.compare_guidance``, for comparison), then the guided sampling-step ablation rows."""
    from intermask.reaction.guidance import Guidance
    from intermask.reaction.load import load_arflow
    from intermask.utils.files import resolve_checkpoint

    settings = cfg.arflow
    checkpoint = resolve_checkpoint(cfg.arflow_ckpt, kind="ARFlow")
    checkpoints["arflow"] = f"{checkpoint} ({file_hash(checkpoint)})"
    model = load_arflow(checkpoint).to(device)
    guided = Guidance(**OmegaConf.to_container(settings.guidance))
    plans = [(settings.steps, guided)]
    if settings.compare_unguided and guided.mode != "none":
        plans.insert(0, (settings.steps, Guidance.off(beta=guided.beta)))
    for mode in dict.fromkeys(settings.compare_guidance):  # ordered, unique
        if mode != guided.mode:
            plans.append((settings.steps, replace(guided, mode=mode, beta=0.0)))
    ablation = dict.fromkeys(int(steps) for steps in settings.step_ablation)  # ordered, unique
    plans += [(steps, guided) for steps in ablation if steps != settings.steps]
    return [
        ARFlowReaction(
            model=model,
            normalizer=normalizer,
            steps=int(steps),
            guidance=guidance,
            use_text=settings.use_text,
        )
        for steps, guidance in plans
    ]


def measured(cfg: DictConfig, source: MotionSource, *, latency: bool = True) -> MotionSource:
    """``source`` with the penetration (``cfg.penetration``) and latency columns; with
    ``penetration.body_model``, the mesh penetration columns too (docs/bodies.md)."""
    settings = cfg.penetration
    penetration = cfg.mode in settings.modes
    mesh = None
    if penetration and settings.get("body_model"):
        from intermask.body.penetration import MeshPenetration

        mesh = MeshPenetration(
            _body_model(str(settings.body_model), settings.get("body_gender")),
            pitch=settings.pitch,
            tolerance=settings.tolerance,
        )
    return Measured(
        source,
        penetration=penetration,
        latency=latency,
        pitch=settings.pitch,
        tolerance=settings.tolerance,
        mesh=mesh,
    )


@functools.cache
def _body_model(path: str, gender: str | None):
    """The configured body model, read once for every row (fitted on the CPU in float64)."""
    from intermask.body.model import load_body_model

    return load_body_model(path, gender=gender, dtype=torch.float64)


def _check_config(cfg: DictConfig) -> str:
    """The mode, order and penetration modes of ``cfg``, checked -> the order."""
    if cfg.mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {cfg.mode!r}")
    order = cfg.get("order", "batched")
    if order not in ORDERS:
        raise ValueError(f"order must be one of {ORDERS}, got {order!r}")
    own_rows = own_row_keys(cfg)
    if order == "reference" and (cfg.mode != "interaction" or cfg.reconstruction_row or own_rows):
        raise ValueError(
            "order=reference replays the authors' eval.py loop: mode=interaction without "
            f"reconstruction_row or rows of your own, got mode={cfg.mode}, reconstruction_row="
            f"{cfg.reconstruction_row}, rows={own_rows}"
        )
    unknown = sorted(set(cfg.penetration.modes) - set(MODES))
    if unknown:
        raise ValueError(f"penetration.modes: unknown mode(s) {unknown}; expected some of {MODES}")
    return order


def _header(cfg: DictConfig, order: str, replications: int, evaluator, checkpoints, success):
    """What the results record besides the rows: the data, the checkpoints and the settings."""
    sampler = cfg.momask if cfg.mode == "text_to_motion" else cfg.sampler
    arflow = "arflow" in checkpoints
    return {
        "mode": cfg.mode,
        "order": order,
        "dataset": f"{cfg.data.dataset} ({cfg.data.root})",
        "split": cfg.split,
        "replications": replications,
        "fast": bool(cfg.fast),
        "evaluator": f"{evaluator.name} ({cfg.eval_ckpt}, sha256 {evaluator.file_hash})",
        **checkpoints,
        "sampler": dict(OmegaConf.to_container(sampler)),
        **({"arflow_sampling": dict(OmegaConf.to_container(cfg.arflow))} if arflow else {}),
        "penetration": dict(OmegaConf.to_container(cfg.penetration)),
        "success_thresholds": asdict(success),
    }


def _load_evaluator(cfg: DictConfig, device: torch.device):
    from intermask.evaluator import load_evaluator

    released = cfg.get("released_evaluator") or {}
    return load_evaluator(
        cfg.eval_ckpt,
        glove_dir=released.get("glove_dir"),
        meta_dir=released.get("meta_dir"),
        net=_released_interclip(released.get("interclip")),
    ).to(device)


def evaluate(cfg: DictConfig) -> dict[str, Any]:
    """Run the protocol of ``cfg`` -> the result dictionary (also written to the run folder)."""
    order = _check_config(cfg)
    output_dir = Path(cfg.paths.output_dir)
    write_run_record(output_dir, cfg, extra={"job": cfg.task_name})
    constants: ProtocolConstants = instantiate(cfg.protocol)
    success_thresholds = instantiate(cfg.success)
    replications = cfg.fast_replications if cfg.fast else constants.replications
    constants = ProtocolConstants(**{**vars(constants), "replications": replications})
    device = pick_device(cfg.device)
    # the data config's own batch mode: interactions (two-person kinds) or text-motion items
    datamodule = instantiate(cfg.data, eval_batch_size=constants.eval_batch_size)
    datamodule.prepare_data()
    datamodule.setup("test" if cfg.split == "test" else "validate")
    evaluator = _load_evaluator(cfg, device)
    sources, checkpoints = build_sources(cfg, datamodule.normalizer, device)

    def loader(epoch: int) -> Iterator[dict[str, Any]]:
        for batch in datamodule.eval_dataloader(cfg.split, epoch=epoch):
            yield _on(batch, device)

    ground_truth = GroundTruth(normalizer=datamodule.normalizer)
    runner: ProtocolRunner | ReferenceOrderLoop = ProtocolRunner(
        loader=loader,
        evaluator=evaluator,
        ground_truth=ground_truth,
        sources=[
            measured(cfg, ground_truth, latency=False),
            *(measured(cfg, source) for source in sources),
        ],
        constants=constants,
        multimodality=not cfg.fast,
        generation_batch_size=cfg.generation_batch_size,
        progress=lambda message: log.info("%s", message),
        joints=motion_joints,
        success_thresholds=success_thresholds,
    )
    if order == "reference":
        runner = _reference_order_loop(cfg, datamodule, evaluator, sources[0], constants)
    header = _header(cfg, order, replications, evaluator, checkpoints, success_thresholds)
    header["device"] = str(device)
    start = time.process_time()
    result = runner.run(header)
    # CPU seconds of the protocol itself (models and data already loaded; all threads)
    result.header["protocol_cpu_s"] = round(time.process_time() - start, 3)
    json_path, markdown_path = write_results(  # together or not at all
        result, output_dir, beside={"tensorboard": lambda path: _log_tensorboard(result, path)}
    )
    print(markdown_path.read_text())
    print(f"results: {json_path} and {markdown_path}")
    return result.to_dict()


def _released_interclip(sizes: Any):
    """The network a released ``interclip.ckpt`` is loaded into: the paper's (None) or InterGen's
    architecture at the sizes of its ``eval_model.yaml`` (``released_evaluator.interclip``:
    width, layers, heads, ff, text_ff, ...), e.g. a reduced one made for a CPU check."""
    if not sizes:
        return None
    from intermask.evaluator.interclip import InterCLIP
    from intermask.evaluator.load import RELEASED_CLIP_MODEL

    return InterCLIP(clip_model_name=RELEASED_CLIP_MODEL, **OmegaConf.to_container(sizes))


def _reference_order_loop(cfg: DictConfig, datamodule, evaluator, source, constants):
    """``order=reference``: the generation row of ``source`` in the authors' loop's order of
    draws (:mod:`intermask.evaluation.reference_order`), streams from ``reference_state`` or
    seeded with the protocol seed."""
    from intermask.evaluation.reference_order import (
        ReferenceItems,
        ReferenceOrderLoop,
        Streams,
        sampler_generation,
    )

    dataset = datamodule.datasets[cfg.split]
    if cfg.get("reference_state"):
        streams = Streams.load(cfg.reference_state)
    else:
        lines = dataset.split_file.read_text(encoding="utf-8").splitlines()
        streams = Streams.seeded(constants.seed, split_lines=len(lines))
    return ReferenceOrderLoop(
        items=ReferenceItems.from_interhuman(dataset),
        evaluator=evaluator,
        generate=sampler_generation(source.sampler, streams),
        constants=constants,
        streams=streams,
        progress=lambda message: log.info("%s", message),
    )


def _log_tensorboard(result, directory: Path) -> None:
    from torch.utils.tensorboard import SummaryWriter

    writer = SummaryWriter(str(directory))
    mode = result.header.get("mode", "eval")
    for row, metrics in result.rows.items():
        for name, summary in metrics.items():
            writer.add_scalar(f"{mode}/{row}/{name}", summary.mean, 0)
            writer.add_scalar(f"{mode}/{row}/{name}_ci95", summary.ci95, 0)
    writer.add_text(f"{mode}/table", markdown_table(result), 0)
    writer.close()


@hydra.main(version_base="1.3", config_path=CONFIG_DIR, config_name="eval")
def main(cfg: DictConfig) -> None:
    from intermask.utils.write_errors import reported_write_errors

    # a full or unwritable run folder: one line and exit 2; an earlier table there is kept
    with reported_write_errors(
        "python -m intermask.evaluate",
        fallback=cfg.paths.output_dir,
        elsewhere="choose another hydra.run.dir",
    ):
        evaluate(cfg)


if __name__ == "__main__":
    main()
