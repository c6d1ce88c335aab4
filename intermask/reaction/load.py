"""Rebuild a trained ARFlow model from a train_arflow run (evaluation and scripts)."""

from __future__ import annotations

from pathlib import Path

from hydra.utils import instantiate

from intermask.reaction.module import ARFlowModule
from intermask.utils.files import open_run_checkpoint
from intermask.utils.run_config import check_targets


def load_arflow(checkpoint: str | Path, *, map_location: str = "cpu") -> ARFlowModule:
    """The frozen (eval) ARFlowModule of a ``train_arflow`` run.

    checkpoint: ``<run>/checkpoints/<name>.ckpt`` or the run directory (its last.ckpt). The
    module is rebuilt from ``<run>/config.yaml`` (network, representation, text tower) and its
    weights and normalization statistics are loaded strictly.
    """
    run = open_run_checkpoint(checkpoint, kind="ARFlow", map_location=map_location)
    model_config = run.config.get("model")
    if model_config is None or not str(model_config.get("_target_", "")).endswith("ARFlowModule"):
        raise ValueError(
            f"{run.config_path}: not a train_arflow run config (model is not ARFlowModule)"
        )
    checked = check_targets(model_config, source=run.config_path, section="model")
    module: ARFlowModule = instantiate(run.location.relocated(checked))
    module.load_state_dict(run.weights())
    return module.eval().requires_grad_(False)
