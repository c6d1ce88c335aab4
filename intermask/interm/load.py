"""Rebuild a trained generator (Inter-M + its frozen VQ-VAE + text encoder) from a train_gen run."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import NamedTuple

from hydra.utils import instantiate
from omegaconf import DictConfig

from intermask.interm.model import InterMTransformer
from intermask.text.cache import TextFeatureCache
from intermask.utils.files import RunCheckpoint, open_run_checkpoint
from intermask.utils.fingerprint import weights_digest
from intermask.utils.run_config import check_targets
from intermask.vq.load import load_vq
from intermask.vq.model import MotionVQVAE

log = logging.getLogger(__name__)


class LoadedGenerator(NamedTuple):
    net: InterMTransformer  # eval mode, frozen
    vq: MotionVQVAE  # eval mode, frozen
    text: TextFeatureCache
    checkpoint: Path  # the Inter-M checkpoint
    vq_checkpoint: Path
    config: DictConfig  # the run's resolved config


def check_vq_matches(
    net: InterMTransformer,
    vq: MotionVQVAE,
    hyper_parameters: dict,
    checkpoint: Path,
    vq_path: Path,
) -> None:
    """Refuse a VQ-VAE whose tokens are not the ones the generator was trained on: another
    codebook size or row count, or (when the checkpoint records it) other weights."""
    codes, rows = vq.quantizer.codebook_size, vq.token_rows
    if (codes, rows) != (net.codebook_size, net.rows):
        raise ValueError(
            f"{vq_path}: a VQ-VAE with {codes} codes x {rows} rows cannot decode the tokens of "
            f"{checkpoint} ({net.codebook_size} codes x {net.rows} rows)"
        )
    check_vq_digest(vq, hyper_parameters, checkpoint, vq_path)


def check_vq_digest(
    vq: MotionVQVAE, hyper_parameters: dict, checkpoint: Path, vq_path: Path
) -> None:
    """Refuse a VQ-VAE whose weights are not those the checkpoint records (``vq_digest``)."""
    expected = hyper_parameters.get("vq_digest")
    if expected is None:
        log.warning(
            "%s records no VQ digest (older run): the VQ's weights are not checked", checkpoint
        )
        return
    actual = weights_digest(vq)
    if actual != expected:
        raise ValueError(
            f"{vq_path}: not the VQ-VAE {checkpoint} was trained on (weights digest "
            f"{actual[:16]}, expected {expected[:16]}): its codes would decode into other "
            "motions. Pass the tokenizer of the generator's run (its config.yaml names vq_ckpt)"
        )


class GeneratorRun(NamedTuple):
    """A train_gen run opened and checked, before anything is built."""

    run: RunCheckpoint
    net_config: DictConfig
    text_config: DictConfig
    vq_path: Path
    hyper_parameters: dict


def open_generator_run(
    checkpoint: str | Path, *, vq_checkpoint: str | Path | None, map_location: str
) -> GeneratorRun:
    """Open a train_gen run's checkpoint and config; check its network and text targets and
    that its tokenizer file exists: ``vq_checkpoint``, else the run's ``vq_ckpt``, found from
    the run folder wherever the tree was moved (:mod:`intermask.utils.run_location`)."""
    run = open_run_checkpoint(checkpoint, kind="generator", map_location=map_location)
    config, config_path = run.config, run.config_path
    if "vq_ckpt" not in config or "net" not in config.get("model", {}):
        raise ValueError(f"{config_path}: not a train_gen run config (no vq_ckpt / model.net)")
    # both sections are checked before anything is built or read
    net_config = check_targets(config.model.net, source=config_path, section="model.net")
    text_config = check_targets(config.text, source=config_path, section="text")
    text_config = run.location.relocated(text_config)
    if vq_checkpoint is not None:
        vq_path = Path(vq_checkpoint)
        if not vq_path.is_file():
            raise FileNotFoundError(
                f"{vq_path}: the VQ checkpoint given for {run.checkpoint} is missing"
            )
    else:
        try:
            vq_path = run.location.locate(
                config.vq_ckpt, what="the generator's VQ checkpoint", source=config_path
            )
        except FileNotFoundError as error:
            raise FileNotFoundError(f"{error}; pass vq_checkpoint= to point to it") from None
    hyper_parameters = run.stored.get("hyper_parameters", {})
    return GeneratorRun(run, net_config, text_config, vq_path, hyper_parameters)


def load_generator(
    checkpoint: str | Path,
    *,
    vq_checkpoint: str | Path | None = None,
    map_location: str = "cpu",
) -> LoadedGenerator:
    """checkpoint: ``<run>/checkpoints/<name>.ckpt`` of a train_gen run, or the run directory
    (its last.ckpt). The transformer is rebuilt from ``<run>/config.yaml`` and loaded strictly;
    the VQ-VAE comes from the run's ``vq_ckpt`` unless ``vq_checkpoint`` overrides it."""
    opened = open_generator_run(checkpoint, vq_checkpoint=vq_checkpoint, map_location=map_location)
    run, net_config, text_config = opened.run, opened.net_config, opened.text_config
    vq_path, hyper_parameters, config = opened.vq_path, opened.hyper_parameters, run.config
    net = instantiate(net_config)
    if not isinstance(net, InterMTransformer):  # the run took its codebook size from its VQ
        if "codebook_size" not in hyper_parameters:
            raise ValueError(
                f"{run.checkpoint}: its config leaves the codebook size to the VQ-VAE, but the "
                "checkpoint records none (hyper_parameters.codebook_size)"
            )
        code_dim = hyper_parameters.get("code_dim")  # absent before code vectors existed
        net = net(
            codebook_size=int(hyper_parameters["codebook_size"]),
            code_dim=None if code_dim is None else int(code_dim),
        )
    net.load_state_dict(run.weights("net."))
    vq = load_vq(vq_path, map_location=map_location)
    check_vq_matches(net, vq, hyper_parameters, run.checkpoint, vq_path)
    text = instantiate(text_config)
    return LoadedGenerator(
        net.eval().requires_grad_(False),
        vq,
        text,
        run.checkpoint,
        vq_path,
        config,
    )
