"""Measure the success signals on a dataset's ground truth: where the thresholds come from.

``intermask data success-stats ROOT [--max-length N]`` reads every split of a labelled dataset
exactly as the evaluation protocol does (interaction items of the DataModule: random crop of
``max_length`` frames, person order drawn per item, epoch ``epoch``), measures every signal of
every action with the annotated actor, and prints per signal its quantiles, the threshold in use
and the GT's pass rates. The suggested thresholds follow the rule of
:class:`~intermask.metrics.interaction.SuccessThresholds`: the 1st percentile of an "above"
signal rounded down, the 99th of a "below" one rounded up, to ``SUGGESTION_STEP``.
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from intermask.metrics.interaction import (
    ACTIONS,
    CHECKS,
    SuccessThresholds,
    measure,
)

SUGGESTION_STEP = 0.01  # rounding of suggested thresholds (cm, hundredths of a radian / second)
# Tolerance beyond the GT's own spread: an "above" threshold is 0.75 x the 1st percentile, a
# "below" one 1.25 x the 99th (a learned model's motion is noisier than the generator's).
TOLERANCE = 0.25
QUANTILES = (0.0, 0.01, 0.05, 0.5, 0.95, 0.99, 1.0)
# Definitions and policy, not measured: frame rate, the speed that counts as moving, how close a
# wrist must come to count as arrived, that the reactor never starts first, contact heights
# relative to the shoulders (signed: below / above them) and "stays in place" (half a step; the
# GT's standing pelvis drifts by 3 cm at most, a tolerance on that would forbid any sway).
UNMEASURED = ("fps", "moving_speed", "arrival", "lead", "low_contact", "high_contact", "still")


@dataclass
class SuccessStatistics:
    """Per action: the signals (one dict per item) and whether each item passed."""

    thresholds: SuccessThresholds
    signals: dict[str, list[dict[str, float]]] = field(default_factory=lambda: defaultdict(list))
    passed: dict[str, list[bool]] = field(default_factory=lambda: defaultdict(list))

    def add(self, joints: torch.Tensor, *, action: str, actor: int) -> None:
        """One GT item: joints (T, 2, 22, 3) valid frames, actor 0 or 1 (an index)."""
        signals = measure(joints, action=action, actor=actor, thresholds=self.thresholds)
        self.signals[action].append(signals)
        self.passed[action].append(
            all(check.passes(signals, self.thresholds) for check in CHECKS[action])
        )

    @property
    def overall(self) -> float:
        outcomes = [p for values in self.passed.values() for p in values]
        return float(np.mean(outcomes)) if outcomes else math.nan

    def rates(self) -> dict[str, float]:
        return {a: float(np.mean(self.passed[a])) for a in ACTIONS if self.passed[a]}

    def suggested_thresholds(self) -> dict[str, float]:
        """Threshold name -> (1 - TOLERANCE) q01 (above, rounded down) or (1 + TOLERANCE) q99
        (below, rounded up) of its signals, the loosest over the checks that share it."""
        suggestions: dict[str, float] = {}
        for action in ACTIONS:
            if not self.signals[action]:
                continue
            for check in CHECKS[action]:
                if check.threshold in UNMEASURED:
                    continue
                values = np.array([s[check.signal] for s in self.signals[action]])
                if check.above:
                    quantile = np.quantile(values, 0.01) * (1 - TOLERANCE)
                    value = math.floor(quantile / SUGGESTION_STEP)
                    value *= SUGGESTION_STEP
                    previous = suggestions.get(check.threshold, math.inf)
                    suggestions[check.threshold] = round(min(previous, value), 6)
                else:
                    quantile = np.quantile(values, 0.99) * (1 + TOLERANCE)
                    value = math.ceil(quantile / SUGGESTION_STEP)
                    value *= SUGGESTION_STEP
                    previous = suggestions.get(check.threshold, -math.inf)
                    suggestions[check.threshold] = round(max(previous, value), 6)
        return suggestions

    def report(self) -> str:
        """A plain-text table: per action its GT pass rate, per check the quantiles."""
        heading = "/".join(f"q{round(100 * q)}" for q in QUANTILES)
        lines = [f"GT success {self.overall:.3f} over {sum(map(len, self.passed.values()))} items"]
        for action in ACTIONS:
            if not self.passed[action]:
                continue
            count = len(self.passed[action])
            lines.append(f"{action}: {np.mean(self.passed[action]):.3f} of {count}")
            for check in CHECKS[action]:
                values = np.array([s[check.signal] for s in self.signals[action]])
                limit = getattr(self.thresholds, check.threshold)
                failed = np.mean(values < limit if check.above else values > limit)
                quantiles = " ".join(f"{v:.3f}" for v in np.quantile(values, QUANTILES))
                sign = ">=" if check.above else "<="
                lines.append(
                    f"  {check.signal} {sign} {check.threshold} {limit:g}: fails {failed:.3f}; "
                    f"{heading} {quantiles}"
                )
        suggestions = self.suggested_thresholds()
        lines.append(
            "suggested thresholds: " + ", ".join(f"{k}={v:g}" for k, v in suggestions.items())
        )
        return "\n".join(lines)


def success_statistics(
    root: str | Path,
    *,
    dataset: str = "interhuman",
    splits: Sequence[str] = ("train", "val", "test"),
    max_length: int | None = None,
    epoch: int = 0,
    seed: int = 3407,
    thresholds: SuccessThresholds | None = None,
) -> SuccessStatistics:
    """Signals and GT outcomes of every item of ``splits`` as the protocol loads them
    (``max_length`` frames, the DataModule's default when None; data seed ``seed``; pass
    ``epoch``). The dataset must carry interaction_meta.json (action and actor per clip)."""
    from intermask.data.datamodule import InteractionDataModule
    from intermask.motion.interx import to_joint_positions

    module = InteractionDataModule(
        dataset=dataset,
        root=str(root),
        max_length=max_length,
        normalize=False,
        mirror=False,  # every clip once (mirrored copies are training augmentation)
        seed=seed,
    )
    statistics = SuccessStatistics(thresholds=thresholds or SuccessThresholds())
    for split in splits:
        items = module.build_dataset(split, mode="interaction")
        for index in range(len(items)):
            item = items[(index, epoch)]
            if "action" not in item or item.get("actor") is None:
                raise ValueError(
                    f"{root}: items carry no action / actor (interaction_meta.json is missing); "
                    "success statistics need the synthetic dataset's annotations"
                )
            if item["action"] not in ACTIONS:
                raise ValueError(
                    f"{root}: action {item['action']!r} of clip {item['id']} is not one of the "
                    f"synthetic actions ({', '.join(ACTIONS)})"
                )
            length = int(item["length"])
            joints = to_joint_positions(item["motion"][:, :length], dataset)  # (T, 2, 22, 3)
            statistics.add(joints, action=item["action"], actor=int(item["actor"]) - 1)
    return statistics
