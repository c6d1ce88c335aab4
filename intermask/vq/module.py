"""VQVAEModule: trains the motion tokenizer (losses, optimizer, schedule, logging)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import asdict
from typing import Any

import torch
from torch.optim import Optimizer

from intermask.metrics.mpjpe import MPJPE
from intermask.utils.lightning import ScheduledModule, writes_step_logs
from intermask.vq.losses import LossKind, LossTerms, LossWeights, vq_losses
from intermask.vq.model import MotionVQVAE, VQVAEOutput
from intermask.vq.views import NormalizedView, TwoPersonView, person_view

log = logging.getLogger(__name__)


class VQVAEModule(ScheduledModule):
    """Trains :class:`MotionVQVAE` on single-person windows ``batch["motion"]: (B, T, *F)``.

    Args:
        net: the VQ-VAE network.
        optimizer: partial optimizer taking the parameters (paper: AdamW lr 2e-4, betas (0.9, 0.99)).
        loss_weights: weights of every loss term (per dataset, from the config).
        loss_kind: elementwise loss of reconstruction and geometric terms.
        warmup_fraction, lr_milestones, lr_gamma: the schedule (paper: 1/4 warm-up, x0.1 at 70%, 85%).
    """

    def __init__(
        self,
        *,
        net: MotionVQVAE,
        optimizer: Callable[..., Optimizer],
        loss_weights: LossWeights | dict[str, float] | None = None,
        loss_kind: LossKind = "smooth_l1",
        warmup_fraction: float = 0.25,
        lr_milestones: Sequence[float] = (0.7, 0.85),
        lr_gamma: float = 0.1,
    ) -> None:
        super().__init__()
        self.net = net
        self.optimizer_factory = optimizer
        self.loss_weights = (
            loss_weights
            if isinstance(loss_weights, LossWeights)
            else LossWeights(**(loss_weights or {}))
        )
        self.loss_kind = loss_kind
        # plain Python values only, so checkpoints load with torch.load(weights_only=True)
        self.save_hyperparameters(
            {
                "loss_weights": asdict(self.loss_weights),
                "loss_kind": str(loss_kind),
                "warmup_fraction": float(warmup_fraction),
                "lr_milestones": [float(m) for m in lr_milestones],
                "lr_gamma": float(lr_gamma),
            },
            logger=False,
        )
        self.val_mpjpe = MPJPE(scale=1000.0)
        self._warned_no_positions = False

    def muon_excluded(self) -> list[torch.nn.Parameter]:
        # the input layer reads raw features, the output layer writes them
        return [
            *super().muon_excluded(),
            *self.net.encoder.net[0].parameters(),
            *self.net.decoder.net[-1].parameters(),
        ]

    @property
    def checkpoint_metric(self) -> str:
        """What ``monitor: auto`` selects checkpoints by: MPJPE when the representation has
        positions (InterHuman; Inter-X with body offsets), else the reconstruction loss (the
        only validation quality the Inter-X view logs without a body model)."""
        return "val/mpjpe_mm" if person_view(self.net.view).has_positions else "val/reconstruction"

    def setup(self, stage: str) -> None:
        """Copy the datamodule's normalization statistics into the view (then they live in checkpoints)."""
        view = person_view(self.net.view)
        if isinstance(view, NormalizedView) and not bool(view.has_statistics):
            normalizer = (
                getattr(self.trainer.datamodule, "normalizer", None) if self.trainer else None
            )
            if normalizer is None:
                raise RuntimeError(
                    f"the {type(view).__name__} tokenizer needs normalization statistics: the "
                    "datamodule exposes none"
                )
            view.set_statistics(normalizer.mean, normalizer.std)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.net(features).reconstruction

    def compute_losses(
        self, batch: dict[str, Any], *, generator: torch.Generator | None = None
    ) -> LossTerms:
        """The loss terms a training step minimises on ``batch`` (no logging, no trainer)."""
        return self._step(batch, measure_unweighted=False, generator=generator)[0]

    def _step(
        self,
        batch: dict[str, Any],
        *,
        measure_unweighted: bool = True,
        generator: torch.Generator | None = None,
    ) -> tuple[LossTerms, torch.Tensor, Any, Any]:
        motion = batch["motion"]
        frame_mask = batch.get("frame_mask")
        if frame_mask is None:
            frame_mask = torch.ones(motion.shape[:2], dtype=torch.bool, device=motion.device)
        out = self.net(motion, generator=generator)
        with torch.autocast(device_type=motion.device.type, enabled=False):
            # geometry (Gram-Schmidt, bone lengths, metres) and losses in float32 under bf16
            return self._losses(out, motion.float(), frame_mask, measure_unweighted)

    def _losses(
        self,
        out: VQVAEOutput,
        motion: torch.Tensor,
        frame_mask: torch.Tensor,
        measure_unweighted: bool,
    ) -> tuple[LossTerms, torch.Tensor, VQVAEOutput, Any]:
        prediction, target, view = out.reconstruction.float(), motion, self.net.view
        if isinstance(view, TwoPersonView):  # losses and metrics per person
            prediction, target = view.split_persons(prediction), view.split_persons(target)
            frame_mask, view = frame_mask.repeat_interleave(2, dim=0), view.person
        predicted, real = view.geometry(prediction), view.geometry(target)
        if real.positions is None and not self._warned_no_positions:
            log.info(
                "no body model for this representation: position, velocity, bone and foot losses are off"
            )
            self._warned_no_positions = True
        terms = vq_losses(
            prediction=prediction,
            target=target,
            predicted_geometry=predicted,
            target_geometry=real,
            reconstruction_mask=view.reconstruction_mask(motion.device),
            frame_mask=frame_mask,
            commit_loss=out.commit_loss,
            weights=self.loss_weights,
            kind=self.loss_kind,
            measure_unweighted=measure_unweighted,
        )
        return terms, frame_mask, out, (predicted, real)

    def training_step(self, batch: dict[str, Any], batch_idx: int) -> torch.Tensor | None:
        logged = writes_step_logs(self)
        # unweighted loss terms only matter on steps whose logs are written
        terms, _, out, _ = self._step(
            batch, measure_unweighted=logged, generator=self.batch_generator("train", batch_idx)
        )
        if self.skip_non_finite(terms._asdict(), batch):
            return None
        batch_size = batch["motion"].shape[0]
        self.log("train/loss", terms.total, batch_size=batch_size, prog_bar=True)
        if not logged:
            # the rest would be dropped; a dozen self.log calls are ~5% of a CPU demo step
            return terms.total
        self.log_dict(
            {f"train/{name}": value for name, value in terms._asdict().items()},
            batch_size=batch_size,
            prog_bar=False,
        )
        codebook_size = self.net.quantizer.codebook_size
        for layer, (perplexity, dead) in enumerate(
            zip(out.perplexity, out.dead_codes, strict=True)
        ):
            self.log(f"codebook/perplexity_{layer}", perplexity, batch_size=batch_size)
            self.log(f"codebook/dead_codes_{layer}", dead.float(), batch_size=batch_size)
            used = torch.unique(out.indices[:, layer][out.indices[:, layer] >= 0]).numel()
            self.log(f"codebook/usage_{layer}", used / codebook_size, batch_size=batch_size)
        return terms.total

    def validation_step(self, batch: dict[str, Any], batch_idx: int) -> None:
        terms, frame_mask, _, (predicted, real) = self._step(batch)
        batch_size = batch["motion"].shape[0]
        self.log("val/loss", terms.total, batch_size=batch_size, sync_dist=True)
        self.log(
            "val/reconstruction",
            terms.reconstruction,
            batch_size=batch_size,
            sync_dist=True,
            prog_bar=True,
        )
        if real.positions is not None:
            self.val_mpjpe.update(predicted.positions, real.positions, frame_mask)
            self.log("val/mpjpe_mm", self.val_mpjpe, batch_size=batch_size, prog_bar=True)
