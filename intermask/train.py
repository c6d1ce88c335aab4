"""Train one stage from a Hydra config: ``python -m intermask.train --config-name train_vq [overrides]``.

Thin by design: compose, instantiate, record, fit. Everything else lives in the modules.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import hydra
import lightning as L
import torch
from hydra.utils import instantiate
from lightning.fabric.plugins.environments import SLURMEnvironment
from omegaconf import DictConfig, open_dict

from intermask.config_files import config_dir
from intermask.utils.checkpoint_io import AtomicCheckpointIO
from intermask.utils.lightning import NON_FINITE_POLICIES
from intermask.utils.precision import PrecisionChoice, resolve_precision
from intermask.utils.run_record import write_run_record
from intermask.utils.write_errors import reported_write_errors

log = logging.getLogger(__name__)
CONFIG_DIR = str(config_dir())


def instantiate_all(group: DictConfig | None) -> list[Any]:
    """Instantiate every ``_target_`` entry of a callbacks/logger group (None -> [])."""
    if not group:
        return []
    return [
        instantiate(entry)
        for entry in group.values()
        if isinstance(entry, DictConfig) and "_target_" in entry
    ]


def count_parameters(module: L.LightningModule) -> tuple[int, int]:
    """(total, trainable) parameters; buffers such as EMA codebooks are not parameters."""
    total = sum(p.numel() for p in module.parameters())
    return total, sum(p.numel() for p in module.parameters() if p.requires_grad)


def decide_precision(cfg: DictConfig) -> PrecisionChoice:
    """Resolve ``trainer.precision: auto`` in ``cfg`` (in place, once) and log the choice."""
    choice = resolve_precision(cfg.trainer.precision, str(cfg.trainer.get("accelerator", "auto")))
    if choice.requested != choice.precision:
        with open_dict(cfg):
            cfg.trainer.precision = choice.precision
    # e.g. "precision: 32-true (CPU capability AVX2, no native bf16)"
    log.info("precision: %s (%s)", choice.precision, choice.reason)
    return choice


def set_threads(cfg: DictConfig) -> int:
    """Apply the job's ``threads`` (torch's intra-op CPU threads; null keeps torch's default)
    and return the count in effect. Small networks can run faster on fewer threads than cores:
    their matmuls are too small to share, and a data worker needs a core of its own."""
    threads = cfg.get("threads")
    if threads is not None:
        if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
            raise ValueError(f"threads must be a positive integer or null, got {threads!r}")
        torch.set_num_threads(threads)
    threads = torch.get_num_threads()
    log.info("CPU threads: %d", threads)
    return threads


def resume_checkpoint(ckpt_path: str | None, *, allow_remote: bool = False) -> str | None:
    """The checkpoint to resume from, checked: a local file (named in the error when missing),
    or a URL only with ``allow_remote``. Either way it is read with ``weights_only=True``
    (see :func:`train`), which no environment variable overrides."""
    if ckpt_path is None:
        return None
    ckpt_path = str(ckpt_path)
    if "://" in ckpt_path:
        if not allow_remote:
            raise ValueError(
                f"ckpt_path={ckpt_path}: refusing to resume from a URL; download the file and "
                "pass its path, or set allow_remote_ckpt=true (it is still read with "
                "weights_only=True)"
            )
        return ckpt_path
    if not Path(ckpt_path).is_file():
        raise FileNotFoundError(f"ckpt_path={ckpt_path}: no such checkpoint file to resume from")
    return ckpt_path


EXISTING_RUN_POLICIES = ("resume", "refuse")


def existing_run_checkpoint(cfg: DictConfig, ckpt_path: str | None) -> str | None:
    """The checkpoint to resume when the run folder already holds ``checkpoints/last.ckpt``.

    A requeued cluster job (submitit requeues a pre-empted job with the same config, so the same
    run folder) finds the checkpoint of its previous life there: with ``existing_run=resume``
    (default) it continues from it, with ``refuse`` it stops. Either way a new run never
    overwrites the checkpoints of another: resuming from a different ``ckpt_path`` into a folder
    that holds one is refused.
    """
    policy = str(cfg.get("existing_run", "resume"))
    if policy not in EXISTING_RUN_POLICIES:
        raise ValueError(f"existing_run must be one of {EXISTING_RUN_POLICIES}, got {policy!r}")
    last = Path(cfg.paths.output_dir) / "checkpoints" / "last.ckpt"
    if not last.is_file():
        return ckpt_path
    if ckpt_path is not None and Path(ckpt_path).resolve() == last.resolve():
        return ckpt_path
    if ckpt_path is None and policy == "resume":
        log.warning("the run folder already holds %s (a requeued job?): resuming from it", last)
        return str(last)
    raise FileExistsError(
        f"{last} exists: this job would overwrite the checkpoints of the run in that folder. "
        + (
            f"Resume it (ckpt_path={last}) or choose another hydra.run.dir"
            if ckpt_path is not None
            else "Resume it (existing_run=resume) or choose another hydra.run.dir"
        )
    )


def non_finite_policy(cfg: DictConfig) -> str:
    """``non_finite_loss`` of the job config: ``stop`` (default) or ``skip``."""
    policy = str(cfg.get("non_finite_loss", "stop"))
    if policy not in NON_FINITE_POLICIES:
        raise ValueError(f"non_finite_loss must be one of {NON_FINITE_POLICIES}, got {policy!r}")
    return policy


def resolve_monitor(cfg: DictConfig, model: L.LightningModule) -> None:
    """``monitor: auto`` of the best-checkpoint callback -> the module's ``checkpoint_metric``
    (in place, logged), so the selection metric is one the module logs for this dataset."""
    checkpoint = (cfg.get("callbacks") or {}).get("model_checkpoint")
    if checkpoint is None or checkpoint.get("monitor") != "auto":
        return
    metric = getattr(model, "checkpoint_metric", None)
    if metric is None:
        raise ValueError(
            f"callbacks.model_checkpoint.monitor=auto: {type(model).__name__} names no "
            "checkpoint_metric; set the monitor explicitly"
        )
    with open_dict(cfg):
        cfg.callbacks.model_checkpoint.monitor = metric
    log.info("best checkpoint by %s", metric)


def log_effective_batch(cfg: DictConfig, trainer: L.Trainer) -> int:
    """Log (and return) the samples behind one optimizer step: the per-process batch x the
    processes x the gradient accumulation (the paper's batch on fewer devices: raise
    ``trainer.accumulate_grad_batches``)."""
    per_process = int(cfg.data.batch_size)
    accumulation = int(trainer.accumulate_grad_batches)
    effective = per_process * trainer.world_size * accumulation
    log.info(
        "effective batch %d = %d per process x %d process(es) x %d accumulated",
        effective,
        per_process,
        trainer.world_size,
        accumulation,
    )
    return effective


def trainer_plugins() -> list[Any]:
    """The Trainer's plugins: checkpoints written atomically (a kill mid-write never leaves a broken
    last.ckpt) and, in a task started by srun, Lightning's Slurm environment (ranks, world size
    and main address from Slurm) without its auto-requeue: Lightning saves and requeues from inside
    the signal handler, wherever the step is; ``callbacks.preemption.RequeueOnSignal`` does it at
    the end of the batch (docs/cluster.md)."""
    plugins: list[Any] = [AtomicCheckpointIO()]
    if SLURMEnvironment.detect():
        plugins.append(SLURMEnvironment(auto_requeue=False))
        log.info(
            "Slurm job %s, task %s of %s: rank and world size from Lightning's SLURMEnvironment",
            os.environ.get("SLURM_JOB_ID"),
            os.environ.get("SLURM_PROCID"),
            os.environ.get("SLURM_NTASKS"),
        )
    return plugins


def train(cfg: DictConfig) -> dict[str, float]:
    """Fit the configured model on the configured data; returns the final callback metrics."""
    L.seed_everything(cfg.seed, workers=True)
    ckpt_path = resume_checkpoint(
        cfg.get("ckpt_path"), allow_remote=bool(cfg.get("allow_remote_ckpt", False))
    )
    ckpt_path = existing_run_checkpoint(cfg, ckpt_path)
    non_finite = non_finite_policy(cfg)  # settings are checked before any data is read
    output_dir = Path(cfg.paths.output_dir)
    precision = decide_precision(cfg)
    set_threads(cfg)
    datamodule = instantiate(cfg.data)
    # bad data fails here, in seconds, before the model (text tower, VQ checkpoint) is built; the
    # datamodule keeps what it read, so fit does not read it again
    datamodule.prepare_data()
    datamodule.setup("fit")
    model = instantiate(cfg.model)
    model.non_finite_loss = non_finite
    model.draw_seed = int(cfg.seed)  # masks and code resets: the same with any number of processes
    resolve_monitor(cfg, model)
    write_run_record(
        output_dir, cfg, extra={"job": cfg.task_name, "precision": precision.as_record()}
    )
    total, trainable = count_parameters(model)
    log.info(
        "%s: %.2fM parameters (%.2fM trainable)", type(model).__name__, total / 1e6, trainable / 1e6
    )
    trainer = instantiate(
        cfg.trainer,
        callbacks=instantiate_all(cfg.get("callbacks")),
        logger=instantiate_all(cfg.get("logger")) or False,
        plugins=trainer_plugins(),
    )
    log_effective_batch(cfg, trainer)
    # weights_only=True explicitly: torch.load then ignores TORCH_FORCE_NO_WEIGHTS_ONLY_LOAD, and
    # Lightning's remote default (weights_only=False) never applies
    trainer.fit(model, datamodule=datamodule, ckpt_path=ckpt_path, weights_only=True)
    metrics = {name: float(value) for name, value in trainer.callback_metrics.items()}
    log.info("final metrics: %s", metrics)
    return metrics


@hydra.main(version_base="1.3", config_path=CONFIG_DIR, config_name="train_vq")
def main(cfg: DictConfig) -> None:
    # a full or unwritable run folder: one line and exit 2 (intermask.utils.write_errors); the
    # checkpoints written before stay whole (AtomicCheckpointIO), the run folder resumes from them
    with reported_write_errors(
        "python -m intermask.train",
        fallback=cfg.paths.output_dir,
        elsewhere="choose another hydra.run.dir",
        then=f"run the command again (hydra.run.dir={cfg.paths.output_dir} continues from its "
        "last checkpoint, if any)",
    ):
        train(cfg)


if __name__ == "__main__":
    main()
