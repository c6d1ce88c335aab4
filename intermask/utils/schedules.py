"""Learning-rate schedules as pure functions of the step (wrapped by torch's LambdaLR)."""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Iterable, Sequence
from functools import partial
from typing import Any

import lightning as L
from torch import nn
from torch.optim import Optimizer
from torch.optim.lr_scheduler import LambdaLR

LR_DECAYS = ("multistep", "cosine", "linear")


def check_lr_decay(decay: str, milestones: Sequence[float], final: float) -> None:
    """Raise ValueError unless ``decay`` names a schedule of :data:`LR_DECAYS` whose settings
    agree: the milestones belong to ``multistep`` alone, ``final`` to the smooth decays."""
    if decay not in LR_DECAYS:
        raise ValueError(f"lr_decay must be one of {', '.join(LR_DECAYS)}, got {decay!r}")
    if decay != "multistep" and len(milestones) > 0:
        raise ValueError(
            f"lr_decay={decay!r} decays smoothly to lr_final and takes no lr_milestones "
            f"(got {list(milestones)}); set lr_milestones to []"
        )
    if not 0.0 <= final <= 1.0:
        raise ValueError(f"lr_final must lie in [0, 1] (a fraction of the base rate), got {final}")


def warmup_schedule_factor(
    step: int,
    *,
    total_steps: int,
    warmup_fraction: float,
    milestones: Sequence[float],
    gamma: float,
    decay: str = "multistep",
    final: float = 0.0,
) -> float:
    """Multiplier of the base learning rate at ``step``.

    Linear warm-up from 1/warmup_steps to 1 over the first ``warmup_fraction`` of ``total_steps``,
    then, by ``decay``:

    - ``multistep``: multiplied by ``gamma`` once per milestone passed; milestones are fractions
      of ``total_steps`` (InterMask VQ: warm-up 1/4, x0.1 at 0.7 and 0.85; Inter-M: x1/3 at 0.5,
      0.7, 0.85);
    - ``cosine``: half a cosine from 1 at the end of the warm-up to ``final`` at ``total_steps``;
    - ``linear``: a straight line between the same two points.
    """
    if total_steps <= 0:
        raise ValueError(f"total_steps must be positive, got {total_steps}")
    check_lr_decay(decay, milestones, final)
    warmup_steps = int(warmup_fraction * total_steps)
    if step < warmup_steps:
        return (step + 1) / warmup_steps
    if decay == "multistep":
        boundaries = sorted(int(m * total_steps) for m in milestones)
        return gamma ** bisect.bisect_right(boundaries, step)
    progress = min((step - warmup_steps) / max(total_steps - warmup_steps, 1), 1.0)
    shape = 0.5 * (1.0 + math.cos(math.pi * progress)) if decay == "cosine" else 1.0 - progress
    return final + (1.0 - final) * shape


def warmup_schedule_optimizers(
    module: L.LightningModule,
    optimizer_factory: Callable[..., Optimizer],
    *,
    parameters: Iterable[nn.Parameter] | Iterable[dict[str, Any]],
    warmup_fraction: float,
    milestones: Sequence[float],
    gamma: float,
    decay: str = "multistep",
    final: float = 0.0,
) -> dict[str, Any]:
    """``configure_optimizers`` result: an optimizer over ``parameters`` (or parameter groups,
    every group on the same schedule) with the warm-up
    schedule of :func:`warmup_schedule_factor` over the trainer's total optimizer steps,
    stepped every step."""
    optimizer = optimizer_factory(params=list(parameters))
    schedule = partial(
        warmup_schedule_factor,
        total_steps=max(int(module.trainer.estimated_stepping_batches), 1),
        warmup_fraction=warmup_fraction,
        milestones=tuple(milestones),
        gamma=gamma,
        decay=decay,
        final=final,
    )
    return {
        "optimizer": optimizer,
        "lr_scheduler": {"scheduler": LambdaLR(optimizer, schedule), "interval": "step"},
    }
