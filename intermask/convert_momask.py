"""``intermask convert-reference`` for a MoMask release (the authors' momask-codes, HumanML3D).

A release keeps each model as ``checkpoints/t2m/<name>/model/<which>.tar`` beside
``<name>/opt.txt``; the tokenizer's folder also holds ``meta/mean.npy`` and ``meta/std.npy``, the
statistics its features are normalized with. Every checkpoint is read with ``weights_only=True``.
The output is one run folder per model, which ``load_vq``, ``load_momask``, ``intermask
generate --checkpoint OUT/mask --residual OUT/residual`` and ``python -m intermask.evaluate
mode=text_to_motion mask_ckpt=OUT/mask residual_ckpt=OUT/residual`` accept::

    OUT/vq/config.yaml, OUT/vq/checkpoints/last.ckpt              (experiment=momask_rvq)
    OUT/mask/config.yaml, OUT/mask/checkpoints/last.ckpt          (experiment=momask_mask)
    OUT/residual/config.yaml, OUT/residual/checkpoints/last.ckpt  (experiment=momask_residual)

Every ``opt.txt`` option is mapped onto the config or refused by name
(:mod:`intermask.momask.reference`); every key that is dropped, computed, cannot be placed or has
another shape is reported by name, and any of the last three refuses the conversion. All models
are converted before anything is written; the folders then appear whole, or not at all.

The transformers condition on CLIP's projected sentence embedding; this framework's text cache
holds the feature before CLIP's text projection, so the conversion folds the projection of the
run's text encoder (``text``, by default MoMask's CLIP ViT-B/32) into the condition layer. The
reference behaviours of fine-tuning are switched on (docs/fidelity.md rows 6-7, 12, 13 and 15);
the depth is the release's (``n_layers``, row 11). Decoding settings are not part of a run: the
reference samples its residual layers (row 14), ``intermask generate --residual-temperature 1``.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from hydra.utils import instantiate
from omegaconf import DictConfig
from torch import nn

from intermask.convert import (
    checked,
    composed,
    read_options,
    release_state,
    run_payload,
    write_run,
)
from intermask.momask.reference import (
    DATASET,
    convert_reference_mask,
    convert_reference_residual,
    rvq_overrides,
    transformer_overrides,
)
from intermask.utils.fingerprint import weights_digest
from intermask.utils.staging import staged_outputs
from intermask.vq.reference import convert_reference_vq

RVQ_KEYS = ("vq_model", "net")  # what the authors' loaders accept (gen_t2m.py)
MASK_KEYS = ("t2m_transformer", "trans")
RESIDUAL_KEYS = ("res_transformer",)
MOMASK_DATASETS = ("t2m", "kit")  # the authors' dataset names
STATISTICS = ("view.mean", "view.std", "view.has_statistics")
# reference behaviours of fine-tuning (docs/fidelity.md): Gumbel code choice and the reference's
# dead-code rule (rows 6-7), smooth L1 (row 15), BERT's 0.88 (row 12), the skewed layer draw (13)
REFERENCE_RVQ = {
    "model.net.quantizer.stochastic_temperature": 0.5,
    "model.net.quantizer.reset": "reference",
    "model.loss_kind": "smooth_l1",
}
REFERENCE_MASK = {"model.bert_mask_prob": 0.88}
REFERENCE_RESIDUAL = {"model.layer_draw": "reference"}
TEXT = "clip_vit_b32"  # MoMask's CLIP ViT-B/32


@dataclass(frozen=True)
class ConvertedMoMask:
    runs: dict[str, Path]  # "vq", "mask", "residual" -> run folder
    reports: dict[str, str]


def is_momask_release(vq: Path) -> bool:
    """True when the tokenizer's opt.txt names one of the authors' MoMask datasets."""
    return read_options(Path(vq)).get("dataset_name") in MOMASK_DATASETS


def _opt_path(checkpoint: Path) -> str:
    return str(checkpoint.parent.parent / "opt.txt")


def _statistics(vq: Path) -> tuple[torch.Tensor, torch.Tensor]:
    """The release's ``<name>/meta/mean.npy`` and ``std.npy`` (what its features are z-scored by)."""
    meta = vq.parent.parent / "meta"
    paths = (meta / "mean.npy", meta / "std.npy")
    for path in paths:
        if not path.is_file():
            raise FileNotFoundError(
                f"{path}: the tokenizer's feature statistics are missing (the release keeps "
                "<name>/meta/mean.npy and std.npy beside <name>/model/)"
            )
    return tuple(torch.from_numpy(np.load(path)).float() for path in paths)


def _convert_rvq(
    vq: Path, ignore: Collection[str]
) -> tuple[DictConfig, nn.Module, str, dict[str, str]]:
    options = read_options(vq)
    mapped = rvq_overrides(options, source=_opt_path(vq), ignore=ignore)
    config = composed(
        "train_vq",
        ["data=humanml3d", "experiment=momask_rvq"],
        {**mapped, **REFERENCE_RVQ},
    )
    net = instantiate(config.model.net)
    conversion = convert_reference_vq(
        release_state(vq, RVQ_KEYS, "MoMask RVQ-VAE"), net.state_dict()
    )
    net.view.set_statistics(*_statistics(vq))
    conversion = conversion._replace(
        missing=[key for key in conversion.missing if key not in STATISTICS]
    )
    checked(conversion, vq, "MoMask RVQ-VAE")
    net.load_state_dict({**net.state_dict(), **conversion.state})
    return config, net.eval(), conversion.report(), options


def clip_text_projection(text: DictConfig) -> torch.Tensor:
    """(D_text, D_clip) ``text_projection`` of the CLIP the text config's encoder builds (the
    same open_clip model, pretrained weights or seeded random tower, as
    :class:`~intermask.text.clip_encoder.FrozenCLIPTextEncoder`, which keeps no projection)."""
    from intermask.text.clip_encoder import (
        FrozenCLIPTextEncoder,
        _create_clip,
        _resolve_pretrained,
        register_model_configs,
    )

    encoder = text.encoder
    target = encoder.get("_target_", "")
    expected = f"{FrozenCLIPTextEncoder.__module__}.{FrozenCLIPTextEncoder.__name__}"
    if target != expected:
        raise ValueError(f"text.encoder is {target!r}: the MoMask conversion needs {expected}")
    register_model_configs()
    name, pretrained = encoder.model_name, encoder.get("pretrained")
    _, checkpoint, quick_gelu = _resolve_pretrained(name, pretrained, encoder.get("quick_gelu"))
    with torch.random.fork_rng(devices=[]):  # as the encoder seeds a random tower
        torch.manual_seed(int(encoder.get("seed", 0)))
        clip = _create_clip(
            name, checkpoint, pretrained, int(encoder.get("context_length", 77)), quick_gelu
        )
    return clip.text_projection.detach().float().clone()


def _check_tokenizer_name(options: dict[str, str], vq: Path, checkpoint: Path) -> None:
    """The authors' loaders find a transformer's tokenizer by its ``vq_name``."""
    name = options.get("vq_name")
    if name is not None and name != vq.parent.parent.name:
        raise ValueError(
            f"{_opt_path(checkpoint)}: vq_name: {name}, but the tokenizer given is "
            f"{vq.parent.parent.name} ({vq}): the authors' code would load {name}"
        )


@dataclass(frozen=True)
class _Tokenizer:
    path: Path
    net: nn.Module
    code_dim: int  # E, the width of its codes (the release's code_dim)
    checkpoint: Path  # where its converted run's last.ckpt will be


def _convert_transformer(
    checkpoint: Path,
    *,
    residual: bool,
    tokenizer: _Tokenizer,
    text: str,
    clip: str | None,
    ignore: Collection[str],
) -> tuple[DictConfig, nn.Module, str, dict[str, str]]:
    options = read_options(checkpoint)
    _check_tokenizer_name(options, tokenizer.path, checkpoint)
    mapped = transformer_overrides(
        options, residual=residual, source=_opt_path(checkpoint), ignore=ignore
    )
    experiment = "momask_residual" if residual else "momask_mask"
    overrides = ["data=humanml3d", f"experiment={experiment}", f"text={text}",
                 f"vq_ckpt={tokenizer.checkpoint}"]  # fmt: skip
    if clip is not None:
        overrides.append(f"text.encoder.pretrained={clip}")
    vq, width = tokenizer.net, tokenizer.code_dim
    reference = REFERENCE_RESIDUAL if residual else REFERENCE_MASK
    config = composed("train_gen", overrides, {**mapped, "model.net.code_dim": width, **reference})
    projection = clip_text_projection(config.text)
    sizes = {"codebook_size": vq.quantizer.codebook_size, "text_dim": projection.shape[0]}
    if residual:
        sizes["num_quantizers"] = vq.quantizer.num_quantizers
    net = instantiate(config.model.net)(**sizes)
    if residual:
        state = release_state(checkpoint, RESIDUAL_KEYS, "MoMask residual transformer")
        conversion = convert_reference_residual(
            state, net.state_dict(), codebook_size=sizes["codebook_size"],
            text_projection=projection,
        )  # fmt: skip
    else:
        state = release_state(checkpoint, MASK_KEYS, "MoMask masked transformer")
        conversion = convert_reference_mask(state, net.state_dict(), text_projection=projection)
    checked(conversion, checkpoint, f"MoMask {'residual' if residual else 'masked'} transformer")
    net.load_state_dict(conversion.state)
    return config, net.eval(), conversion.report(), {**options, **sizes}


def convert_momask(
    *,
    vq: Path,
    mask: Path | None,
    residual: Path | None = None,
    out: Path,
    text: str = TEXT,
    clip: str | None = None,
    ignore_options: Collection[str] = (),
) -> ConvertedMoMask:
    """Convert a MoMask release's RVQ-VAE (and masked and residual transformers) into run
    folders under ``out``: ``vq``, ``mask``, ``residual``.

    ``text``: the config (configs/text/) of the transformers' text encoder, whose CLIP text
    projection is folded into their condition layers; ``clip``: a local CLIP checkpoint file for
    it (offline use). ``ignore_options``: opt.txt options the authors' code does not have that
    the user vouches do not change the network.
    """
    vq, out = Path(vq), Path(out)
    vq_options = read_options(vq)
    if vq_options.get("dataset_name") != DATASET:
        raise ValueError(
            f"{_opt_path(vq)}: dataset_name: {vq_options.get('dataset_name')} (this framework "
            f"builds MoMask for HumanML3D, dataset_name {DATASET})"
        )
    vq_config, vq_net, vq_report, vq_options = _convert_rvq(vq, ignore_options)
    reports = {"vq": vq_report}
    digest = weights_digest(vq_net)
    runs = {"vq": (vq_config, run_payload(vq_net, vq, vq_options))}
    last = out.absolute() / "vq" / "checkpoints" / "last.ckpt"
    tokenizer = _Tokenizer(vq, vq_net, int(vq_config.model.net.encoder.width), last)
    for name, checkpoint in (("mask", mask), ("residual", residual)):
        if checkpoint is None:
            continue
        checkpoint = Path(checkpoint)
        config, net, reports[name], options = _convert_transformer(
            checkpoint,
            residual=name == "residual",
            tokenizer=tokenizer,
            text=text,
            clip=clip,
            ignore=ignore_options,
        )
        sizes = {key: options.pop(key) for key in ("codebook_size", "text_dim", "num_quantizers")
                 if key in options}  # fmt: skip
        extra = {**sizes, "vq_digest": digest}
        runs[name] = (config, run_payload(net, checkpoint, options, **extra))
    with staged_outputs(out, tuple(runs)) as staged:  # every run appears whole, or none does
        for name, (config, payload) in runs.items():
            write_run(staged / name, out.absolute() / name, config, payload)
    return ConvertedMoMask({name: out / name for name in runs}, reports)
