"""Rebuild MoMask's trained transformers (with their frozen tokenizer and text encoder) from
train_gen runs, and the sampler that chains them."""

from __future__ import annotations

from pathlib import Path
from typing import Any, NamedTuple

from hydra.utils import instantiate
from omegaconf import DictConfig

from intermask.interm.load import check_vq_digest, open_generator_run
from intermask.momask.model import MaskedTransformer, ResidualTransformer
from intermask.momask.sampler import MoMaskSampler
from intermask.text.cache import TextFeatureCache
from intermask.vq.load import load_vq
from intermask.vq.model import MotionVQVAE

# what each network takes from the run's tokenizer and text encoder (saved as hyper-parameters)
_FACTORY_ARGUMENTS = {
    MaskedTransformer: ("codebook_size", "text_dim"),
    ResidualTransformer: ("codebook_size", "num_quantizers", "text_dim"),
}


class LoadedMoMask(NamedTuple):
    net: MaskedTransformer | ResidualTransformer  # eval mode, frozen
    vq: MotionVQVAE  # eval mode, frozen
    text: TextFeatureCache
    checkpoint: Path
    vq_checkpoint: Path
    config: DictConfig  # the run's resolved config


def load_momask(
    checkpoint: str | Path,
    *,
    vq_checkpoint: str | Path | None = None,
    vq: MotionVQVAE | None = None,
    map_location: str = "cpu",
) -> LoadedMoMask:
    """A masked or residual transformer from its train_gen run (``<run>`` or a checkpoint in
    ``<run>/checkpoints``), rebuilt from the run's config and loaded strictly. The tokenizer is
    ``vq`` when given (already loaded, e.g. shared with the partner network), else read from
    ``vq_checkpoint`` or the run's ``vq_ckpt``; either way its weights must be the ones the run
    trained on."""
    opened = open_generator_run(checkpoint, vq_checkpoint=vq_checkpoint, map_location=map_location)
    run, hyper_parameters = opened.run, opened.hyper_parameters
    factory = instantiate(opened.net_config)
    cls = getattr(factory, "func", factory)
    if cls not in _FACTORY_ARGUMENTS:
        raise ValueError(
            f"{run.config_path}: model.net is {getattr(cls, '__name__', cls)}, not a MoMask "
            "transformer (MaskedTransformer or ResidualTransformer)"
        )
    missing = [name for name in _FACTORY_ARGUMENTS[cls] if hyper_parameters.get(name) is None]
    if missing:
        raise ValueError(
            f"{run.checkpoint}: hyper_parameters lack {missing} to rebuild {cls.__name__}"
        )
    net = factory(**{name: int(hyper_parameters[name]) for name in _FACTORY_ARGUMENTS[cls]})
    net.load_state_dict(run.weights("net."))
    vq = vq if vq is not None else load_vq(opened.vq_path, map_location=map_location)
    check_vq_digest(vq, hyper_parameters, run.checkpoint, opened.vq_path)
    return LoadedMoMask(
        net.eval().requires_grad_(False),
        vq,
        instantiate(opened.text_config),
        run.checkpoint,
        opened.vq_path,
        run.config,
    )


def load_momask_sampler(
    mask_checkpoint: str | Path,
    residual_checkpoint: str | Path | None = None,
    *,
    vq_checkpoint: str | Path | None = None,
    map_location: str = "cpu",
    **settings: Any,
) -> tuple[MoMaskSampler, dict[str, Path]]:
    """The sampler of a masked transformer run and (optionally) a residual one trained on the
    same tokenizer -> (sampler, {"mask": ..., "residual": ..., "vq": ...} checkpoint paths).
    ``settings``: :class:`MoMaskSampler`'s decoding arguments."""
    mask = load_momask(mask_checkpoint, vq_checkpoint=vq_checkpoint, map_location=map_location)
    if not isinstance(mask.net, MaskedTransformer):
        raise ValueError(
            f"{mask.checkpoint} holds a {type(mask.net).__name__}, not the masked transformer"
        )
    paths = {"mask": mask.checkpoint, "vq": mask.vq_checkpoint}
    residual_net = None
    if residual_checkpoint is not None:
        residual = load_momask(residual_checkpoint, vq=mask.vq, map_location=map_location)
        if not isinstance(residual.net, ResidualTransformer):
            raise ValueError(
                f"{residual.checkpoint} holds a {type(residual.net).__name__}, not the residual transformer"
            )
        residual_net, paths["residual"] = residual.net, residual.checkpoint
    sampler = MoMaskSampler(
        mask_net=mask.net, residual_net=residual_net, vq=mask.vq, text=mask.text, **settings
    )
    return sampler, paths
