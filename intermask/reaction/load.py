"""Rebuild a trained ARFlow model from a train_arflow run (evaluation and scripts)."""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

from intermask.reaction.module import ARFlowModule
from intermask.utils.checkpoint_files import read_checkpoint_file
from intermask.utils.files import resolve_checkpoint, run_config_path
from intermask.utils.run_config import instantiate_from_run


def load_arflow(checkpoint: str | Path, *, map_location: str = "cpu") -> ARFlowModule:
    """The frozen (eval) ARFlowModule of a ``train_arflow`` run.

    checkpoint: ``<run>/checkpoints/<name>.ckpt`` or the run directory (its last.ckpt). The
    module is rebuilt from ``<run>/config.yaml`` (network, representation, text tower) and its
    weights and normalization statistics are loaded strictly.
    """
    checkpoint = resolve_checkpoint(checkpoint, kind="ARFlow")
    config_path = run_config_path(checkpoint, kind="ARFlow")
    model_config = OmegaConf.load(config_path).get("model")
    if model_config is None or not str(model_config.get("_target_", "")).endswith("ARFlowModule"):
        raise ValueError(
            f"{config_path}: not a train_arflow run config (model is not ARFlowModule)"
        )
    module: ARFlowModule = instantiate_from_run(model_config, source=config_path, section="model")
    state = read_checkpoint_file(checkpoint, map_location=map_location)["state_dict"]
    module.load_state_dict(state)
    return module.eval().requires_grad_(False)
