"""LightningModule bases shared by the VQ-VAE, Inter-M, ARFlow and the evaluator."""

from __future__ import annotations

import logging
from collections.abc import Iterable, Mapping
from typing import Any, NamedTuple

import lightning as L
import torch
from torch import nn

from intermask.utils.optim import builds_muon, muon_groups
from intermask.utils.schedules import warmup_schedule_optimizers
from intermask.utils.seeds import keyed_generator

log = logging.getLogger(__name__)


def writes_step_logs(module: L.LightningModule) -> bool:
    """Whether the logger writes the values a ``training_step`` logs now (every
    ``log_every_n_steps`` optimizer steps, Lightning's rule); values logged on other steps are
    dropped, so costly ones can be skipped there. True outside a trainer."""
    trainer = module._trainer
    if trainer is None:
        return True
    every = trainer.log_every_n_steps
    return every > 0 and ((module.global_step + 1) % every == 0 or trainer.should_stop)


NON_FINITE_POLICIES = ("stop", "skip")


class NonFiniteLoss(RuntimeError):
    """A training loss term is NaN or infinite (policy ``stop``)."""


class ScheduledModule(L.LightningModule):
    """Optimizer ``self.optimizer_factory`` over :meth:`optimized_parameters`, with the warm-up
    schedule of the hyper-parameters ``warmup_fraction``, ``lr_milestones`` and ``lr_gamma``
    (fractions of the run's optimizer steps), stepped every step; a module that also records
    ``lr_decay`` and ``lr_final`` may replace the milestones by a smooth decay
    (:func:`~intermask.utils.schedules.warmup_schedule_factor`).

    Training steps pass their loss terms through :meth:`skip_non_finite`: a NaN or infinite term
    stops the run (``non_finite_loss = "stop"``, the default; the checkpoints written so far are
    the last good ones) or skips that optimizer step (``"skip"``), naming the step, the terms
    and the batch's clip ids. ``train.py`` sets the policy from the job config.
    """

    non_finite_loss: str = "stop"
    skipped_steps: int = 0
    draw_seed: int = 0  # train.py sets the job's seed

    def batch_generator(self, stage: str, batch_idx: int) -> torch.Generator | None:
        """The generator of a batch's random draws (masks, corruption, condition drops, code
        resets): seeded by (``draw_seed``, stage, batch), where a training batch counts from the
        start of the fit (Lightning restores the count on resume) and a validation batch is its
        index, so every validation pass draws alike. The draws then depend neither on the
        number of processes nor on what else used torch's global generator, and a resumed run
        draws what the uninterrupted one drew. None outside a trainer (the global generator)."""
        trainer = self._trainer
        if trainer is None:
            return None
        if stage == "train":
            counter, stream = trainer.fit_loop.epoch_loop.total_batch_idx, 0
        elif stage == "val":
            counter, stream = batch_idx, 1
        else:
            raise ValueError(f"stage must be 'train' or 'val', got {stage!r}")
        return keyed_generator(self.draw_seed, stream, counter, device=self.device)

    def skip_non_finite(self, terms: Mapping[str, torch.Tensor], batch: Mapping[str, Any]) -> bool:
        """True when this step must be skipped (policy ``skip``); raises :class:`NonFiniteLoss`
        under ``stop``. All processes of a DDP run take the same decision."""
        finite = torch.stack([torch.isfinite(value).all() for value in terms.values()]).tolist()
        bad = [name for name, ok in zip(terms, finite, strict=True) if not ok]  # one device sync
        trainer = self._trainer
        if trainer is not None and trainer.world_size > 1:
            if not trainer.strategy.reduce_boolean_decision(bool(bad), all=False):
                return False
        elif not bad:
            return False
        ids = [str(i) for i in batch.get("id", [])]
        shown = ", ".join(ids[:8]) + (f" and {len(ids) - 8} more" if len(ids) > 8 else "")
        where = (
            f"step {self.global_step}: non-finite training loss "
            f"({', '.join(bad) if bad else 'on another process'}) on the batch of clips "
            f"[{shown}]"
        )
        if self.non_finite_loss == "skip":
            self.skipped_steps += 1
            log.warning("%s: step skipped (%d so far)", where, self.skipped_steps)
            return True
        raise NonFiniteLoss(
            f"{where}; the run stops (non_finite_loss=stop) and its checkpoints hold the last "
            "good weights. Set non_finite_loss=skip to skip such steps instead"
        )

    def optimized_parameters(self) -> Iterable[nn.Parameter]:
        """What the optimizer updates (default: every parameter)."""
        return self.parameters()

    def muon_excluded(self) -> Iterable[nn.Parameter]:
        """Matrices that take AdamW steps when the optimizer is :class:`~intermask.utils.optim.Muon`
        (default: the embedding tables); a module adds its output layer."""
        return [p for m in self.modules() if isinstance(m, nn.Embedding) for p in m.parameters()]

    def configure_optimizers(self) -> dict[str, Any]:
        parameters: Iterable[Any] = self.optimized_parameters()
        if builds_muon(self.optimizer_factory):
            parameters = muon_groups(parameters, adamw=self.muon_excluded())
        return warmup_schedule_optimizers(
            self,
            self.optimizer_factory,
            parameters=parameters,
            warmup_fraction=self.hparams.warmup_fraction,
            milestones=self.hparams.lr_milestones,
            gamma=self.hparams.lr_gamma,
            # recorded by Inter-M only; the other modules, and Inter-M runs saved before the
            # option existed, get the schedule's own default (the milestones)
            **{
                argument: self.hparams[name]
                for name, argument in (("lr_decay", "decay"), ("lr_final", "final"))
                if name in self.hparams
            },
        )


class LossStepsModule(ScheduledModule):
    """Training and validation steps of a module trained on one tuple of losses per batch.

    Subclasses provide ``compute_losses(batch, condition_drop=p, generator=g)`` returning a NamedTuple with a
    ``total``, :meth:`loss_values` naming what to log, ``_log_validation_samples(batch)``, and the
    hyper-parameters ``condition_drop`` (training only; validation drops nothing) and
    ``validation_samples`` (generate from the first validation batch when positive).
    """

    def loss_values(self, losses: NamedTuple) -> Mapping[str, torch.Tensor]:
        """Logged as ``train/<name>`` and ``val/<name>``; "loss" also goes to the progress bar."""
        raise NotImplementedError

    def _log_losses(self, prefix: str, losses: NamedTuple, batch_size: int) -> None:
        for name, value in self.loss_values(losses).items():
            self.log(
                f"{prefix}/{name}",
                value,
                batch_size=batch_size,
                prog_bar=name == "loss",
                sync_dist=prefix == "val",
            )

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor | None:
        losses = self.compute_losses(
            batch,
            condition_drop=self.hparams.condition_drop,
            generator=self.batch_generator("train", batch_idx),
        )
        if self.skip_non_finite(self.loss_values(losses), batch):
            return None
        self._log_losses("train", losses, batch["motion"].shape[0])
        return losses.total

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> None:
        with torch.no_grad():
            losses = self.compute_losses(
                batch, condition_drop=0.0, generator=self.batch_generator("val", batch_idx)
            )
        self._log_losses("val", losses, batch["motion"].shape[0])
        if batch_idx == 0 and self.hparams.validation_samples > 0:
            self._log_validation_samples(batch)
