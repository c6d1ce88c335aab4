"""``load_evaluator``: a frozen evaluator from a train_evaluator run or from a released file."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict

from intermask.evaluator.checkpoints import (
    VOCABULARY_KEY,
    default_t2m_meta_dir,
    file_hash,
    is_released_interclip,
    is_released_t2m,
    load_state,
    read_checkpoint,
    released_interclip_state,
    released_t2m_input_size,
    released_t2m_state,
    released_t2m_statistics,
)
from intermask.evaluator.frozen import FrozenEvaluator
from intermask.evaluator.gru_matcher import GRUMatcher, T2MMatcher
from intermask.evaluator.humanml3d_matcher import STATISTICS_BUFFERS, HumanML3DMatcher
from intermask.evaluator.interclip import InterCLIP
from intermask.evaluator.vocabulary import DEFAULT_GLOVE_PREFIX, HUMANML3D_GLOVE_PREFIX
from intermask.motion.humanml3d import FEATURE_DIM
from intermask.utils.files import run_config_path
from intermask.utils.run_config import instantiate_from_run

log = logging.getLogger(__name__)

RELEASED_CLIP_MODEL = "ViT-L-14-336"  # InterGen's tokenizer and embedding sizes
T2M_VARIANTS: dict[str, type[T2MMatcher]] = {"interx": GRUMatcher, "humanml3d": HumanML3DMatcher}
RELEASED_GLOVE_PREFIX = {"interx": DEFAULT_GLOVE_PREFIX, "humanml3d": HUMANML3D_GLOVE_PREFIX}


def load_evaluator(
    path: str | Path,
    *,
    strict: bool = True,
    dataset: str | None = None,
    glove_dir: str | Path | None = None,
    glove_prefix: str | None = None,
    meta_dir: str | Path | None = None,
    trusted: bool = False,
    map_location: str = "cpu",
    net: InterCLIP | T2MMatcher | None = None,
) -> FrozenEvaluator:
    """The frozen evaluator stored at ``path``.

    path: ``<run>/checkpoints/<name>.ckpt`` of a train_evaluator run (the network is rebuilt from
        ``<run>/config.yaml``), InterGen's ``interclip.ckpt`` or a T2M ``finest.tar`` (Inter-X,
        or HumanML3D's ``t2m/text_mot_match/model/finest.tar``).
    strict: raise on any missing / unexpected / shape-mismatched key (the error lists them);
        False logs them and loads the matching tensors.
    dataset: which T2M matcher a ``finest.tar`` is, "interx" or "humanml3d"; default: ``net``'s,
        else read from the file's movement encoder (672 input channels Inter-X, 259 HumanML3D).
    glove_dir, glove_prefix: GloVe files of a released T2M matcher (its word vectors are not in
        ``finest.tar``); the prefix defaults to the dataset's (``hhi_vab``, ``our_vab``).
    meta_dir: the released HumanML3D matcher's ``mean.npy`` and ``std.npy``; default
        ``t2m/Comp_v6_KLD01/meta`` of the release tree ``finest.tar`` is in (MoMask's tree:
        ``t2m/Comp_v6_KLD005/meta``).
    trusted: allow unpickling Python objects beyond tensors (older Lightning checkpoints).
    net: the network a *released* file is loaded into; default the paper configuration
        (InterCLIP over ViT-L/14@336px embeddings; the dataset's T2M matcher with GloVe from
        glove_dir).
    """
    path = Path(path)
    checkpoint = read_checkpoint(path, trusted=trusted, map_location=map_location)
    if isinstance(checkpoint, dict) and _is_our_run(checkpoint):
        config_path = run_config_path(path, kind="evaluator")
        if net is not None:
            raise ValueError(
                f"{path}: a train_evaluator checkpoint rebuilds its own network; drop net"
            )
        net, source = _from_run(checkpoint, config_path, path, strict=strict)
    elif is_released_t2m(checkpoint):
        net = _released_t2m(
            checkpoint,
            path,
            net=net,
            dataset=dataset,
            glove_dir=glove_dir,
            glove_prefix=glove_prefix,
            meta_dir=meta_dir,
            strict=strict,
        )
        source = "released"
    elif is_released_interclip(checkpoint):
        if net is None:
            net = InterCLIP(clip_model_name=RELEASED_CLIP_MODEL)
        if not isinstance(net, InterCLIP):
            raise ValueError(f"{path} is an InterCLIP checkpoint, got net={type(net).__name__}")
        load_state(net, released_interclip_state(checkpoint, path), source=str(path), strict=strict)
        source = "released"
    else:
        keys = sorted(map(str, checkpoint))[:10] if isinstance(checkpoint, dict) else []
        raise ValueError(
            f"{path}: not an evaluator checkpoint: expected a train_evaluator checkpoint (with "
            f"{path.parent.parent / 'config.yaml'}), InterGen's interclip.ckpt ('state_dict' with 'model.' keys) or a "
            f"T2M finest.tar (movement_encoder/text_encoder/motion_encoder); top-level keys {keys}"
        )
    evaluator = FrozenEvaluator(
        net, name=f"{net.architecture}[{source}]", file_hash=file_hash(path)
    )
    log.info("evaluator %s (file %s, sha256 %s)", evaluator.name, path, evaluator.file_hash)
    return evaluator


def _is_our_run(checkpoint: dict[str, Any]) -> bool:
    state = checkpoint.get("state_dict")
    return isinstance(state, dict) and any(k.startswith("net.") for k in state)


def _from_run(
    checkpoint: dict[str, Any], config_path: Path, path: Path, *, strict: bool
) -> tuple[InterCLIP | T2MMatcher, str]:
    cfg = OmegaConf.load(config_path)
    if "net" not in cfg.get("model", {}):
        raise ValueError(f"{config_path}: no model.net section (not a train_evaluator run)")
    net_cfg: DictConfig = cfg.model.net
    with open_dict(net_cfg):
        if "text_encoder" in net_cfg:
            # the CLIP embeddings are in the checkpoint: only the tokenizer is needed, so no CLIP
            # weights are downloaded or read to rebuild the network
            text_cfg = net_cfg.text_encoder
            net_cfg.text_encoder = None
            net_cfg.clip_model_name = text_cfg.model_name
            net_cfg.context_length = text_cfg.context_length
        if "word_vectors" in net_cfg:
            if VOCABULARY_KEY not in checkpoint:
                raise ValueError(f"{path}: no '{VOCABULARY_KEY}' entry (the GRU matcher's words)")
            net_cfg.vocabulary = list(checkpoint[VOCABULARY_KEY])
            net_cfg.glove_dir = None  # the vectors are in the state dict
    net = instantiate_from_run(net_cfg, source=config_path, section="model.net")
    state = {
        k.removeprefix("net."): v
        for k, v in checkpoint["state_dict"].items()
        if k.startswith("net.")
    }
    load_state(net, state, source=str(path), strict=strict)
    trained_on = cfg.model.get("trained_on") or "unknown"
    return net, f"trained:{trained_on}"


def _released_t2m(
    checkpoint: dict[str, Any],
    path: Path,
    *,
    net: InterCLIP | T2MMatcher | None,
    dataset: str | None,
    glove_dir: str | Path | None,
    glove_prefix: str | None,
    meta_dir: str | Path | None,
    strict: bool,
) -> T2MMatcher:
    dataset = _t2m_dataset(checkpoint, path, net, dataset)
    if meta_dir is not None and dataset != "humanml3d":
        raise ValueError(f"{path}: meta_dir is for the HumanML3D matcher, this one is {dataset}")
    statistics = None
    if dataset == "humanml3d":
        statistics = released_t2m_statistics(
            meta_dir if meta_dir is not None else default_t2m_meta_dir(path),
            feature_shape=(FEATURE_DIM,),
        )
    prefix = glove_prefix or RELEASED_GLOVE_PREFIX[dataset]
    if net is None:
        if glove_dir is None:
            raise ValueError(
                f"{path}: the released {dataset} evaluator reads GloVe word vectors that are not "
                f"in the file: pass glove_dir=<folder with {prefix}_data.npy, {prefix}_words.pkl, "
                f"{prefix}_idx.pkl>"
            )
        if dataset == "interx":
            # the released matcher was trained on pytorch3d's 6D layout (first two matrix rows)
            net = GRUMatcher(
                word_vectors="glove",
                glove_dir=str(glove_dir),
                glove_prefix=prefix,
                rot6d_input="pytorch3d",
            )
        else:
            net = HumanML3DMatcher(
                word_vectors="glove", glove_dir=str(glove_dir), glove_prefix=prefix
            )
    ignore: tuple[str, ...] = ("word_embedding.",)
    if isinstance(net, HumanML3DMatcher) and statistics is not None:
        net.set_statistics(statistics.mean, statistics.std, source=statistics.source)
        ignore += STATISTICS_BUFFERS
    load_state(
        net,
        released_t2m_state(checkpoint, path),
        source=str(path),
        strict=strict,
        ignore_missing=ignore,
    )
    return net


def _t2m_dataset(
    checkpoint: dict[str, Any], path: Path, net: InterCLIP | T2MMatcher | None, dataset: str | None
) -> str:
    """Which T2M matcher ``path`` holds: ``net``'s, ``dataset``, or the file's input width."""
    if dataset is not None and dataset not in T2M_VARIANTS:
        raise ValueError(f"dataset must be one of {sorted(T2M_VARIANTS)}, got {dataset!r}")
    if net is not None:
        if not isinstance(net, T2MMatcher) or net.word_embedding is None:
            raise ValueError(
                f"{path} is a T2M matcher checkpoint: net must be a GRUMatcher or "
                f"HumanML3DMatcher with its word vectors (glove_dir), got {type(net).__name__}"
            )
        if dataset is not None and dataset != net.dataset:
            raise ValueError(f"{path}: dataset={dataset!r}, but net is the {net.dataset} matcher")
        return net.dataset
    if dataset is not None:
        return dataset
    width = released_t2m_input_size(checkpoint)
    for name, variant in T2M_VARIANTS.items():
        if variant.motion_input_size == width:
            return name
    widths = ", ".join(f"{v.motion_input_size} {k}" for k, v in T2M_VARIANTS.items())
    raise ValueError(
        f"{path}: cannot tell which dataset this T2M matcher is for: its movement encoder reads "
        f"{width} channels ({widths}); pass dataset='interx' or 'humanml3d'"
    )
