"""The evaluation protocol during generator training: quality against training time.

Every ``every_n_epochs`` validations, :class:`PeriodicProtocol` runs ``replications`` fast
replications of the protocol (GT and generated rows, no MultiModality) on a split of the
training DataModule with a frozen evaluator, and logs ``protocol/{top1,top2,top3,fid,mm_dist,
diversity,success}`` of the generated row, the GT row's ``protocol/gt_top3``, and
``protocol/hours`` (wall time of the fit, summed over the runs it resumed from: the clock and the
count of validations travel in the checkpoint). That is the curve of a long run, and a
checkpoint monitor can select on ``protocol/fid`` or ``protocol/top3``. Rank zero only.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import lightning as L
import torch
from lightning.pytorch.callbacks import Callback

from intermask.evaluation.protocol import ProtocolConstants, ProtocolRunner
from intermask.evaluation.sources import GroundTruth, InterMaskGeneration, motion_joints
from intermask.metrics.interaction import SuccessThresholds

log = logging.getLogger(__name__)


class PeriodicProtocol(Callback):
    """Fast protocol replications every ``every_n_epochs`` validations of an Inter-M run.

    Args:
        evaluator: a train_evaluator checkpoint (or a released one) the metrics embed with.
        constants: the protocol's constants (``configs/protocol/``); ``replications`` of them
            run per evaluation.
        split: the DataModule split evaluated ("val" keeps the test split for the final table).
        every_n_epochs: evaluate after every n-th validation (the sanity check never does).
        iterations: decoding iterations of the generated row (per person when ``persons`` is
            "in_turn"; the sampler's other settings are the paper's).
        persons: "together" (the paper) or "in_turn" (intermask.interm.decoding).
        success: thresholds of the interaction-success predicates (labelled synthetic data).
    """

    def __init__(
        self,
        *,
        evaluator: str,
        constants: ProtocolConstants,
        split: str = "val",
        every_n_epochs: int = 1,
        iterations: int = 10,
        persons: str = "together",
        success: SuccessThresholds | None = None,
    ) -> None:
        if every_n_epochs < 1 or iterations < 1:
            raise ValueError(
                f"every_n_epochs and iterations must be >= 1, got {every_n_epochs} and {iterations}"
            )
        if split not in ("train", "val", "test"):
            raise ValueError(f"split must be 'train', 'val' or 'test', got {split!r}")
        self.evaluator_path = Path(evaluator)
        if not self.evaluator_path.is_file():
            raise FileNotFoundError(f"{self.evaluator_path}: evaluator checkpoint not found")
        self.constants, self.split = constants, split
        self.every_n_epochs, self.iterations = every_n_epochs, iterations
        self.persons = persons
        self.success = success or SuccessThresholds()
        self._evaluator = None
        self._validations = 0
        self._hours_before = 0.0  # wall hours of the runs this fit resumed from
        self._started = time.monotonic()

    def on_fit_start(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        self._started = time.monotonic()

    def hours(self) -> float:
        """Wall hours of the fit so far, including the runs it resumed from."""
        return self._hours_before + (time.monotonic() - self._started) / 3600

    def state_dict(self) -> dict[str, Any]:
        return {"validations": self._validations, "hours": self.hours()}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        self._validations = int(state_dict["validations"])
        self._hours_before = float(state_dict["hours"])

    def _load_evaluator(self, device: torch.device):
        if self._evaluator is None:
            from intermask.evaluator import load_evaluator

            self._evaluator = load_evaluator(self.evaluator_path)
        return self._evaluator.to(device)

    def on_validation_epoch_end(self, trainer: L.Trainer, pl_module: L.LightningModule) -> None:
        if trainer.sanity_checking:
            return
        self._validations += 1
        if self._validations % self.every_n_epochs or not trainer.is_global_zero:
            return
        values = self.evaluate(trainer.datamodule, pl_module)
        hours = self.hours()
        for name, value in values.items():
            pl_module.log(f"protocol/{name}", value, rank_zero_only=True)
        pl_module.log("protocol/hours", hours, rank_zero_only=True)
        summary = ", ".join(f"{name} {value:.3f}" for name, value in values.items())
        log.info("protocol at step %d (%.2f h): %s", trainer.global_step, hours, summary)

    @torch.no_grad()
    def evaluate(self, datamodule: Any, pl_module: Any) -> dict[str, float]:
        """Generated row's means over the replications (+ ``gt_top3``, ``gt_success``)."""
        device = pl_module.device
        evaluator = self._load_evaluator(device)
        sampler = pl_module.sampler(iterations=self.iterations, persons=self.persons)
        was_training = pl_module.training
        pl_module.eval()
        batch_size = self.constants.eval_batch_size

        def loader(epoch: int) -> Iterator[dict[str, Any]]:
            passes = datamodule.eval_dataloader(self.split, batch_size=batch_size, epoch=epoch)
            for batch in passes:
                yield {k: v.to(device) if torch.is_tensor(v) else v for k, v in batch.items()}

        ground_truth = GroundTruth(normalizer=datamodule.normalizer)
        generated = InterMaskGeneration(sampler=sampler)
        runner = ProtocolRunner(
            loader=loader,
            evaluator=evaluator,
            ground_truth=ground_truth,
            sources=[ground_truth, generated],
            constants=self.constants,
            multimodality=False,
            joints=motion_joints,
            success_thresholds=self.success,
        )
        try:
            result = runner.run({"split": self.split})
        finally:
            pl_module.train(was_training)
        rows = result.rows
        # the per-check failure shares and signal medians (fails/ and signal/<action>/<check>) and
        # the per-action counts stay in the eval's results.json: a training log keeps the rates
        values = {
            name: summary.mean
            for name, summary in rows[generated.name].items()
            if not name.startswith(("fails/", "samples/", "signal/"))
        }
        truth = rows[ground_truth.name]
        values["gt_top3"] = truth["top3"].mean
        if "success" in truth:
            values["gt_success"] = truth["success"].mean
        return values
