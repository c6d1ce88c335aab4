"""Learning-rate schedules as pure functions of the step (wrapped by torch's LambdaLR)."""

from __future__ import annotations

import bisect
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from typing import Any

import lightning as L
from torch import nn
from torch.optim import Optimizer
from torch.optim.lr_scheduler import LambdaLR


def warmup_multistep_factor(
    step: int,
    *,
    total_steps: int,
    warmup_fraction: float,
    milestones: Sequence[float],
    gamma: float,
) -> float:
    """Multiplier of the base learning rate at ``step``.

    Linear warm-up from 1/warmup_steps to 1 over the first ``warmup_fraction`` of ``total_steps``,
    then multiplied by ``gamma`` once per milestone passed; milestones are fractions of
    ``total_steps`` (InterMask VQ: warm-up 1/4, x0.1 at 0.7 and 0.85; Inter-M: x1/3 at 0.5, 0.7, 0.85).
    """
    if total_steps <= 0:
        raise ValueError(f"total_steps must be positive, got {total_steps}")
    warmup_steps = int(warmup_fraction * total_steps)
    if step < warmup_steps:
        return (step + 1) / warmup_steps
    boundaries = sorted(int(m * total_steps) for m in milestones)
    return gamma ** bisect.bisect_right(boundaries, step)


def warmup_multistep_optimizers(
    module: L.LightningModule,
    optimizer_factory: Callable[..., Optimizer],
    *,
    parameters: Iterable[nn.Parameter],
    warmup_fraction: float,
    milestones: Sequence[float],
    gamma: float,
) -> dict[str, Any]:
    """``configure_optimizers`` result: an optimizer over ``parameters`` with the warm-up
    multistep schedule over the trainer's total optimizer steps, stepped every step."""
    optimizer = optimizer_factory(params=list(parameters))
    schedule = partial(
        warmup_multistep_factor,
        total_steps=max(int(module.trainer.estimated_stepping_batches), 1),
        warmup_fraction=warmup_fraction,
        milestones=tuple(milestones),
        gamma=gamma,
    )
    return {
        "optimizer": optimizer,
        "lr_scheduler": {"scheduler": LambdaLR(optimizer, schedule), "interval": "step"},
    }
