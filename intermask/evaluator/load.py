"""``load_evaluator``: a frozen evaluator from a train_evaluator run or from a released file."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict

from intermask.evaluator.checkpoints import (
    VOCABULARY_KEY,
    file_hash,
    is_released_interclip,
    is_released_t2m,
    load_state,
    read_checkpoint,
    released_interclip_state,
    released_t2m_state,
)
from intermask.evaluator.frozen import FrozenEvaluator
from intermask.evaluator.gru_matcher import GRUMatcher
from intermask.evaluator.interclip import InterCLIP
from intermask.evaluator.vocabulary import DEFAULT_GLOVE_PREFIX
from intermask.utils.files import run_config_path
from intermask.utils.run_config import instantiate_from_run

log = logging.getLogger(__name__)

RELEASED_CLIP_MODEL = "ViT-L-14-336"  # InterGen's tokenizer and embedding sizes


def load_evaluator(
    path: str | Path,
    *,
    strict: bool = True,
    glove_dir: str | Path | None = None,
    glove_prefix: str = DEFAULT_GLOVE_PREFIX,
    trusted: bool = False,
    map_location: str = "cpu",
    net: InterCLIP | GRUMatcher | None = None,
) -> FrozenEvaluator:
    """The frozen evaluator stored at ``path``.

    path: ``<run>/checkpoints/<name>.ckpt`` of a train_evaluator run (the network is rebuilt from
        ``<run>/config.yaml``), InterGen's ``interclip.ckpt`` or the Inter-X ``finest.tar``.
    strict: raise on any missing / unexpected / shape-mismatched key (the error lists them);
        False logs them and loads the matching tensors.
    glove_dir, glove_prefix: GloVe files for the released Inter-X evaluator (its word vectors
        are not in ``finest.tar``).
    trusted: allow unpickling Python objects beyond tensors (older Lightning checkpoints).
    net: the network a *released* file is loaded into; default the paper configuration
        (InterCLIP over ViT-L/14@336px embeddings; the GRU matcher with GloVe from glove_dir).
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
        net = _released_t2m(checkpoint, path, net, glove_dir, glove_prefix, strict)
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
) -> tuple[InterCLIP | GRUMatcher, str]:
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
    net: InterCLIP | GRUMatcher | None,
    glove_dir: str | Path | None,
    glove_prefix: str,
    strict: bool,
) -> GRUMatcher:
    if net is not None:
        if not isinstance(net, GRUMatcher) or net.word_embedding is None:
            raise ValueError(
                f"{path} is a T2M matcher checkpoint: net must be a GRUMatcher with its word "
                f"vectors (glove_dir), got {type(net).__name__}"
            )
    elif glove_dir is None:
        raise ValueError(
            f"{path}: the released Inter-X evaluator reads GloVe word vectors that are not in the "
            f"file: pass glove_dir=<folder with {glove_prefix}_data.npy, {glove_prefix}_words.pkl, "
            f"{glove_prefix}_idx.pkl>"
        )
    else:
        # the released matcher was trained on pytorch3d's 6D layout (first two matrix rows)
        net = GRUMatcher(
            word_vectors="glove",
            glove_dir=str(glove_dir),
            glove_prefix=glove_prefix,
            rot6d_input="pytorch3d",
        )
    load_state(
        net,
        released_t2m_state(checkpoint, path),
        source=str(path),
        strict=strict,
        ignore_missing=("word_embedding.",),
    )
    return net
