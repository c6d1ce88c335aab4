"""Rebuild a trained tokenizer from a train_vq run (used frozen by the generator)."""

from __future__ import annotations

from pathlib import Path

from omegaconf import OmegaConf

from intermask.utils.checkpoint_files import read_checkpoint_file
from intermask.utils.files import run_config_path
from intermask.utils.run_config import instantiate_from_run
from intermask.vq.model import MotionVQVAE


def load_vq(checkpoint: str | Path, *, map_location: str = "cpu") -> MotionVQVAE:
    """The frozen (eval) MotionVQVAE of a ``train_vq`` run.

    checkpoint: ``<run>/checkpoints/<name>.ckpt``; the network is rebuilt from the run's resolved
    ``<run>/config.yaml`` and loaded strictly (weights only), statistics buffers included.
    """
    checkpoint = Path(checkpoint)
    if not checkpoint.is_file():
        raise FileNotFoundError(f"{checkpoint}: VQ checkpoint not found")
    config_path = run_config_path(checkpoint, kind="VQ")
    net = instantiate_from_run(
        OmegaConf.load(config_path).model.net, source=config_path, section="model.net"
    )
    state = read_checkpoint_file(checkpoint, map_location=map_location)["state_dict"]
    net.load_state_dict(
        {k.removeprefix("net."): v for k, v in state.items() if k.startswith("net.")}
    )
    return net.eval().requires_grad_(False)
