"""Interaction success: the share of motions that show their action, overall and per action.

The predicates and their thresholds are in :mod:`intermask.metrics.interaction`; this class only
accumulates their outcomes: which checks each motion fails (so a report can say why an action
fails, not only how often). Like FID and Diversity it keeps one row per sample (failed checks,
action, sample id) rather than running sums, so the padded duplicates a ``DistributedSampler``
adds can be dropped by id at ``compute`` (:mod:`intermask.metrics.dedup`); a row is three
integers.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torchmetrics import Metric

from intermask.metrics.dedup import gather_samples, sample_id_column
from intermask.metrics.interaction import (
    ACTIONS,
    CHECKS,
    SuccessThresholds,
    interaction_failures,
)

MAX_CHECKS = max(len(checks) for checks in CHECKS.values())
# (A, MAX_CHECKS): which slots of an action's row are checks of its own
_CHECK_SLOTS = torch.arange(MAX_CHECKS) < torch.tensor([len(CHECKS[a]) for a in ACTIONS])[:, None]


class SuccessRates(NamedTuple):
    """overall: () success rate; per_action: (A,) rates in ``ACTIONS`` order, NaN for an action
    without samples; counts: (A,) samples per action; failures: (A, MAX_CHECKS) share of each
    action's samples that fail ``CHECKS[action][i]``, NaN past the action's checks or without
    samples (a sample can fail several checks)."""

    overall: torch.Tensor
    per_action: torch.Tensor
    counts: torch.Tensor
    failures: torch.Tensor

    def as_dict(self) -> dict[str, float]:
        """``{"success": rate, "success/<action>": rate, "samples/<action>": count,
        "fails/<action>/<check>": rate, ...}`` for the actions with samples, every check of
        theirs (``Check.name``)."""
        values = {"success": float(self.overall)}
        rows = zip(ACTIONS, self.per_action, self.counts, self.failures, strict=True)
        for action, rate, count, failures in rows:
            if int(count):
                values[f"success/{action}"] = float(rate)
                values[f"samples/{action}"] = float(count)
                for check, share in zip(CHECKS[action], failures, strict=False):
                    values[f"fails/{action}/{check.name}"] = float(share)
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
        for name in ("outcomes", "sample_ids"):
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
        failed = interaction_failures(
            joints, lengths, action_ids, actors, thresholds=self.thresholds
        )
        ids = sample_id_column(
            sample_ids, joints.shape[0], metric="InteractionSuccess", device=self.device
        )
        rows = torch.stack((failed.to(self.device), action_ids.long().to(self.device)), -1)
        self.outcomes.append(rows)  # (B, 2): failed checks as bits, action id
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
        return SuccessRates(passed.mean(), per_action, counts.long(), failures)
