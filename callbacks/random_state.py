"""The global random generators' state travels with every checkpoint, so a resumed run draws the
same masks, codebook resets and dropout as the run it continues (``ckpt_path=...last.ckpt``
after a kill equals the uninterrupted run; tests/test_resume_equality.py).

Only torch's generators are kept (CPU, and the current CUDA device's when CUDA is in use; the
ranks of a data-parallel run draw alike, so rank 0's state serves every rank): items,
crops and the sample order come from per-(seed, epoch, index) streams (``intermask.data``), and
the states are byte tensors, which ``torch.load(weights_only=True)`` reads.
"""

from __future__ import annotations

from typing import Any

import torch
from lightning.pytorch.callbacks import Callback


class RandomStateCheckpoint(Callback):
    """Saves ``torch.get_rng_state()`` (and the current CUDA device's) in the checkpoint;
    restores them when a fit resumes from it."""

    @property
    def state_key(self) -> str:
        return "RandomStateCheckpoint"

    def state_dict(self) -> dict[str, Any]:
        state: dict[str, Any] = {"torch": torch.get_rng_state()}
        if torch.cuda.is_available() and torch.cuda.is_initialized():
            state["cuda"] = torch.cuda.get_rng_state()
        return state

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        saved = state_dict.get("torch")
        if not isinstance(saved, torch.Tensor) or saved.dtype != torch.uint8:
            raise ValueError(
                "the checkpoint's RandomStateCheckpoint entry holds no torch generator state "
                f"(got {type(saved).__name__})"
            )
        torch.set_rng_state(saved)
        cuda = state_dict.get("cuda")
        if cuda is not None and torch.cuda.is_available():
            torch.cuda.set_rng_state(cuda)  # this process's current device
