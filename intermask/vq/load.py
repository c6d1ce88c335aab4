"""Rebuild a trained tokenizer from a train_vq run (used frozen by the generator)."""

from __future__ import annotations

from pathlib import Path

from intermask.utils.files import open_run_checkpoint
from intermask.utils.run_config import instantiate_from_run
from intermask.vq.model import MotionVQVAE


def load_vq(checkpoint: str | Path, *, map_location: str = "cpu") -> MotionVQVAE:
    """The frozen (eval) MotionVQVAE of a ``train_vq`` run.

    checkpoint: ``<run>/checkpoints/<name>.ckpt`` or the run directory (its last.ckpt); the
    network is rebuilt from the run's resolved ``<run>/config.yaml`` and loaded strictly
    (weights only), statistics buffers included.
    """
    run = open_run_checkpoint(checkpoint, kind="VQ", map_location=map_location)
    net = instantiate_from_run(run.config.model.net, source=run.config_path, section="model.net")
    net.load_state_dict(run.weights("net."))
    return net.eval().requires_grad_(False)
