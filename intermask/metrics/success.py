"""Interaction success: the share of motions that show their action, overall and per action.

The predicates and their thresholds are in :mod:`intermask.metrics.interaction`; this class only
accumulates their outcomes: which checks each motion fails (so a report can say why an action
fails, not only how often, and by how much). Like FID and Diversity it keeps one row per sample
(failed checks, action, sample id, and the signal each check read) rather than running sums, so
the padded duplicates a ``DistributedSampler`` adds can be dropped by id at ``compute``
(:mod:`intermask.metrics.dedup`) and medians taken; a row is three integers and ``MAX_CHECKS``
floats.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torchmetrics import Metric

from intermask.metrics.dedup import gather_samples, sample_id_column
from intermask.metrics.interaction import (
    ACTIONS,
    CHECKS,
    MAX_CHECKS,
    SuccessThresholds,
    interaction_judgements,
)

# (A, MAX_CHECKS): which slots of an action's row are checks of its own
_CHECK_SLOTS = torch.arange(MAX_CHECKS) < torch.tensor([len(CHECKS[a]) for a in ACTIONS])[:, None]


class SuccessRates(NamedTuple):
    """overall: () success rate; per_action: (A,) rates in ``ACTIONS`` order, NaN for an action
    without samples; counts: (A,) samples per action; failures: (A, MAX_CHECKS) share of each
    action's samples that fail ``CHECKS[action][i]``, NaN past the action's checks or without
    samples (a sample can fail several checks); signals: (A, MAX_CHECKS) median over all the
    action's samples of the value ``CHECKS[action][i]`` reads (how far from its threshold the
    action's motions are: a kick of 0.16 m where 0.26 m are needed; for an even count the lower
    of the two middle values, as ``torch.nanmedian``), NaN where ``failures`` is."""

    overall: torch.Tensor
    per_action: torch.Tensor
    counts: torch.Tensor
    failures: torch.Tensor
    signals: torch.Tensor

    def as_dict(self) -> dict[str, float]:
        """``{"success": rate, "success/<action>": rate, "samples/<action>": count,
        "fails/<action>/<check>": rate, "signal/<action>/<check>": median, ...}`` for the
        actions with samples, every check of theirs (``Check.name``)."""
        values = {"success": float(self.overall)}
        rows = zip(ACTIONS, self.per_action, self.counts, self.failures, self.signals, strict=True)
        for action, rate, count, failures, signals in rows:
            if int(count):
                values[f"success/{action}"] = float(rate)
                values[f"samples/{action}"] = float(count)
                for check, share, signal in zip(CHECKS[action], failures, signals, strict=False):
                    values[f"fails/{action}/{check.name}"] = float(share)
                    values[f"signal/{action}/{check.name}"] = float(signal)
        return values


class InteractionSuccess(Metric):
    """Success rate of :func:`~intermask.metrics.interaction.interaction_success`.

    ``update(joints (B, T, 2, 22, 3), lengths (B,), action_ids (B,), actors (B,) | None = None,
    *, sample_ids (B,) int64 | None = None)``: joints in metres, Y up; actors 1 or 2 in the joints'
    person order, 0 or None when unknown (generated motion: either person may act).
    ``compute() -> SuccessRates``.
    """

    full_state_update = False
    higher_is_better = True
    is_differentiable = False

    def __init__(self, *, thresholds: SuccessThresholds | None = None) -> None:
        super().__init__()
        self.thresholds = thresholds or SuccessThresholds()
        for name in ("outcomes", "signals", "sample_ids"):
            self.add_state(name, default=[], dist_reduce_fx="cat")

    def update(
        self,
        joints: torch.Tensor,
        lengths: torch.Tensor,
        action_ids: torch.Tensor,
        actors: torch.Tensor | None = None,
        *,
        sample_ids: torch.Tensor | None = None,
    ) -> None:
        failed, signals = interaction_judgements(
            joints, lengths, action_ids, actors, thresholds=self.thresholds
        )
        ids = sample_id_column(
            sample_ids, joints.shape[0], metric="InteractionSuccess", device=self.device
        )
        rows = torch.stack((failed.to(self.device), action_ids.long().to(self.device)), -1)
        self.outcomes.append(rows)  # (B, 2): failed checks as bits, action id
        self.signals.append(signals.to(self.device))  # (B, MAX_CHECKS) float64, NaN-padded
        self.sample_ids.append(ids)

    def compute(self) -> SuccessRates:
        rows = gather_samples(self.outcomes, self.sample_ids, metric="InteractionSuccess")
        failed, actions = rows[:, 0], rows[:, 1]
        passed = (failed == 0).double()
        counts = torch.bincount(actions, minlength=len(ACTIONS)).double()
        hits = torch.bincount(actions, weights=passed, minlength=len(ACTIONS))
        per_action = torch.where(counts > 0, hits / counts.clamp_min(1), torch.nan)
        bits = (failed[:, None] >> torch.arange(MAX_CHECKS, device=failed.device)) & 1  # (N, K)
        misses = counts.new_zeros(len(ACTIONS), MAX_CHECKS).index_add_(0, actions, bits.double())
        measured = _CHECK_SLOTS.to(failed.device) & (counts[:, None] > 0)
        failures = torch.where(measured, misses / counts.clamp_min(1)[:, None], torch.nan)
        signals = gather_samples(self.signals, self.sample_ids, metric="InteractionSuccess")
        medians = torch.full_like(failures, torch.nan)
        for action in torch.unique(actions).tolist():  # at most len(ACTIONS) medians of columns
            medians[action] = signals[actions == action].nanmedian(dim=0).values
        medians = torch.where(measured, medians, torch.nan)
        return SuccessRates(passed.mean(), per_action, counts.long(), failures, medians)
