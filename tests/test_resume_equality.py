"""A run killed with SIGKILL in the middle of an epoch and resumed from its ``last.ckpt`` ends
with the weights of the run that was never interrupted, bit for bit.

The resumed run repeats the interrupted epoch from its start: the batches come from
(seed, epoch) streams, the masks, corruption and code resets from (seed, batch count) streams
(``ScheduledModule.batch_generator``), and torch's global generator state travels with the
checkpoint (``callbacks/random_state.py``).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from pathlib import Path

import pytest
import torch
from lightning.pytorch import Callback
from omegaconf import open_dict
from test_train_gen import _gen_config
from test_train_vq import _config as vq_config
from test_train_vq import _last

from intermask.train import train

pytestmark = pytest.mark.slow

EPOCHS, BATCHES = 2, 3


class KillAt(Callback):
    """SIGKILL this process at the start of batch ``batch`` of epoch ``epoch`` (no handler runs,
    nothing is saved: the last checkpoint is the previous epoch's)."""

    def __init__(self, epoch: int, batch: int) -> None:
        self.epoch, self.batch = epoch, batch

    def on_train_batch_start(self, trainer, pl_module, batch, batch_idx) -> None:
        if trainer.current_epoch == self.epoch and batch_idx == self.batch:
            os.kill(os.getpid(), signal.SIGKILL)


def _train_with_threads(cfg, threads: int) -> None:
    """``train`` in a spawned child with the parent's intra-op thread count (a forked child
    deadlocks in the parent's OpenMP pool once the parent has trained; a different count could
    change the last bits of the epoch the resumed run starts from)."""
    torch.set_num_threads(threads)
    train(cfg)


def _config(job: str, root: Path, vq_ckpt: Path | None, out: Path, *, kill=False, resume=None):
    if job == "vq":
        cfg = vq_config(root, out, [f"trainer.max_epochs={EPOCHS}"])
    else:
        cfg = _gen_config(root, vq_ckpt, out)
    with open_dict(cfg):
        # fp32 on every CPU: `auto` picks bf16-mixed where the CPU has native bf16, and what is
        # proven here is the arithmetic of the uninterrupted run repeated (docs/cluster.md)
        cfg.trainer.precision = "32-true"
        if job == "gen":
            # one text cache for the three runs, as a resumed run shares its data folder's: a
            # caption's features are computed once, in whichever batch first holds it (batched
            # float math differs in the last bits with the batch around a caption)
            cfg.text.cache_dir = str(out.parent / "text_cache")
        cfg.trainer.max_epochs, cfg.trainer.limit_train_batches = EPOCHS, BATCHES
        if job == "gen":
            cfg.model.step_unroll = True  # the second pass re-masks from the first's logits
        if kill:  # in epoch 1, after epoch 0's last.ckpt
            cfg.callbacks.kill = {"_target_": f"{__name__}.KillAt", "epoch": 1, "batch": 1}
        if resume is not None:
            cfg.ckpt_path = str(resume)
    return cfg


@pytest.mark.parametrize("job", ["vq", "gen"])
def test_sigkill_mid_epoch_then_resume_equals_the_uninterrupted_run(
    job, synthetic_interhuman_root, tmp_path
):
    root, vq_ckpt = synthetic_interhuman_root, None
    if job == "gen":
        train(vq_config(root, tmp_path / "vq"))
        vq_ckpt = tmp_path / "vq" / "checkpoints" / "last.ckpt"
    train(_config(job, root, vq_ckpt, tmp_path / "whole"))

    killed = _config(job, root, vq_ckpt, tmp_path / "killed", kill=True)
    process = multiprocessing.get_context("spawn").Process(
        target=_train_with_threads, args=(killed, torch.get_num_threads())
    )
    process.start()
    process.join(timeout=600)
    assert process.exitcode == -signal.SIGKILL
    last = tmp_path / "killed" / "checkpoints" / "last.ckpt"
    assert _last(tmp_path / "killed")["global_step"] == BATCHES  # epoch 0's checkpoint survived

    train(_config(job, root, vq_ckpt, tmp_path / "resumed", resume=last))
    whole, resumed = _last(tmp_path / "whole"), _last(tmp_path / "resumed")
    assert resumed["global_step"] == whole["global_step"] == EPOCHS * BATCHES
    assert whole["state_dict"].keys() == resumed["state_dict"].keys()
    for name, value in whole["state_dict"].items():
        assert torch.equal(resumed["state_dict"][name], value), name
    for name, state in whole["optimizer_states"][0]["state"].items():
        assert torch.equal(
            resumed["optimizer_states"][0]["state"][name]["exp_avg"], state["exp_avg"]
        )
