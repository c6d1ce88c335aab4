"""Data-parallel training equals one process: 2 gloo processes (``trainer=ddp_cpu``) with 4
samples each reach, after k steps, the weights of 1 process with batches of 8.

Why it holds (intermask/utils/distributed.py): each rank reads a contiguous block of every
global batch (``EpochSampler``), random draws (masks, corruption, condition drops, codebook
initialisation and resets) are made for the whole global batch on every rank, and the Inter-M
loss divides by the masked tokens of the global batch. What remains is float reduction order
(the gradient all-reduce, per-rank sums): the tolerance below.

The proof is fp32's: both runs pin ``trainer.precision=32-true``. Under ``auto`` a CPU with native
bf16 (AVX512-BF16, AMX) trains in bf16-mixed, where splitting a batch changes which products
are rounded to bf16, and the weights part by far more than reduction order (docs/cluster.md
gives the measured differences). tests/slurm runs the same comparison through srun.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf, open_dict
from test_train_gen import _gen_config
from test_train_vq import _config as vq_config
from test_train_vq import _last

from intermask.train import train

pytestmark = pytest.mark.slow

STEPS = 3
PRECISION = "32-true"  # what the equality is proven for, on every CPU (module docstring)
# float32 weights after 3 AdamW steps at lr 1e-3..2e-4 differ by reduction order only
ATOL, RTOL = 2e-5, 1e-4


def _vq(root: Path, out: Path, processes: int) -> dict:
    overrides = [
        f"data.batch_size={8 // processes}",
        f"trainer.limit_train_batches={STEPS}",
        "trainer.limit_val_batches=1",
        "model.net.encoder.dropout=0.0",  # dropout draws per process (see module docstring)
        "callbacks.sample_animations=null",
        f"trainer.precision={PRECISION}",
    ]
    if processes > 1:
        overrides.append("trainer=ddp_cpu")
    train(vq_config(root, out, overrides))
    return _last(out)


def _assert_same_weights(one: dict, two: dict) -> None:
    assert one["global_step"] == two["global_step"] == STEPS
    state_one, state_two = one["state_dict"], two["state_dict"]
    assert state_one.keys() == state_two.keys()
    for name, value in state_one.items():
        other = state_two[name]
        if value.is_floating_point():
            torch.testing.assert_close(other, value, atol=ATOL, rtol=RTOL, msg=name)
        else:
            assert torch.equal(other, value), name


def _single_writer(out: Path) -> None:
    """One run directory: one TensorBoard event file and one set of checkpoints (rank 0)."""
    assert len(list((out / "tensorboard").rglob("events.out.tfevents.*"))) == 1
    names = sorted(p.name for p in (out / "checkpoints").iterdir())
    assert names[-1] == "last.ckpt" and len(names) == 2, names  # best-epoch000 and last


def test_vq_two_processes_equal_one(synthetic_interhuman_root, tmp_path, caplog):
    one = _vq(synthetic_interhuman_root, tmp_path / "one", 1)
    with caplog.at_level(logging.INFO, logger="intermask.train"):
        two = _vq(synthetic_interhuman_root, tmp_path / "two", 2)
    assert "effective batch 8 = 4 per process x 2 process(es) x 1 accumulated" in caplog.text
    # the codebook was initialised from, and reset to, rows of the same global batch
    assert bool(one["state_dict"]["net.quantizer.layers.0.initialized"])
    _assert_same_weights(one, two)
    _single_writer(tmp_path / "two")


def test_gen_two_processes_equal_one(synthetic_interhuman_root, tmp_path):
    vq_run = tmp_path / "vq"
    train(vq_config(synthetic_interhuman_root, vq_run))
    vq_ckpt = vq_run / "checkpoints" / "last.ckpt"
    runs = {}
    for processes in (1, 2):
        out = tmp_path / f"gen{processes}"
        cfg = _gen_config(synthetic_interhuman_root, vq_ckpt, out)
        overrides = {
            "data": {"batch_size": 8 // processes},
            "trainer": {"limit_train_batches": STEPS, "max_epochs": 1, "precision": PRECISION},
            "model": {
                "step_unroll": True,
                "validation_samples": 0,
                "net": {"dropout": 0.0, "text_dropout": 0.0},  # dropout draws per process
            },
        }
        with open_dict(cfg):
            cfg.merge_with(OmegaConf.create(overrides))
            cfg.callbacks.sample_animations = None
            if processes > 1:
                cfg.trainer.strategy, cfg.trainer.devices = "ddp_spawn", 2
        train(cfg)
        runs[processes] = _last(out)
    # masks, BERT corruption and condition drops were drawn for the global batch of 8
    _assert_same_weights(runs[1], runs[2])
    _single_writer(tmp_path / "gen2")
