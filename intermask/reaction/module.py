"""ARFlowModule: trains ARFlow's clean-reaction predictor on actor/reactor pairs.

The frozen text encoder is not a submodule (held in :class:`_Frozen`), so checkpoints hold the
trainable network and the feature statistics (``space``) only; the encoder is rebuilt from its
config. Without text (``text=None``, ``net.text_dim=None``) the model is unconstrained, the
paper's main setting.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch
from torch.optim import Optimizer

from intermask.motion.kinds import DatasetKind
from intermask.physics import penetration_loss
from intermask.reaction.flow import SIGMA_MIN, STEPS, check_sigma_min, interpolate
from intermask.reaction.guidance import Guidance
from intermask.reaction.losses import InteractionTerms, interaction_loss, reconstruction_loss
from intermask.reaction.network import ReactionDecoder
from intermask.reaction.representation import FeatureSpace
from intermask.reaction.roles import actor_index, split_roles
from intermask.reaction.sampler import (
    ReactionParts,
    frame_mask_from_lengths,
    generate_reaction,
    pooled_text,
)
from intermask.text.cache import TextFeatureCache
from intermask.utils.lightning import LossStepsModule


class ARFlowLosses(NamedTuple):
    total: torch.Tensor  # () reconstruction + lambda_inter * interaction
    reconstruction: torch.Tensor  # () L_fm, eq. 5
    interaction: InteractionTerms  # L_inter, eq. 6, and its three terms


@dataclass
class _Frozen:
    """Holder that hides the frozen text encoder from ``nn.Module`` registration."""

    text: TextFeatureCache | None


class ARFlowModule(LossStepsModule):
    """Flow matching from the actor's motion x0 to the reactor's motion x1 (ARFlow).

    Batch: "motion" (B, 2, T, *F) normalized, "length" (B,), "caption" (B texts), optional
    "actor" (1 or 2; see :mod:`intermask.reaction.roles`).

    Args:
        net: the Transformer decoder; ``net.feature_dim`` must equal the representation's size.
        representation: "interhuman" (262-d) or "interx" ((56, 6) flattened).
        text: frozen text features (pooled at the end-of-text token) or None (unconstrained).
        optimizer: partial optimizer taking the parameters.
        sigma_min: the path's minimum noise (eq. 4; not stated by the paper).
        lambda_inter: weight of the interaction loss (appendix F: 1).
        condition_drop: per-sample probability of the null text condition (classifier-free).
        warmup_fraction, lr_milestones, lr_gamma: warm-up multistep schedule (fractions of all
            optimizer steps).
        validation_samples: every validation generates this many reactions of the first batch
            and logs their MPJPE and penetration, with and without guidance; 0 = off.
        sample_steps, guidance: Euler steps and guidance settings (:class:`Guidance` fields)
            for those samples.
    """

    def __init__(
        self,
        *,
        net: ReactionDecoder,
        representation: DatasetKind,
        text: TextFeatureCache | None,
        optimizer: Callable[..., Optimizer],
        sigma_min: float = SIGMA_MIN,
        lambda_inter: float = 1.0,
        condition_drop: float = 0.1,
        warmup_fraction: float = 0.0,
        lr_milestones: Sequence[float] = (),
        lr_gamma: float = 1.0,
        validation_samples: int = 8,
        sample_steps: int = STEPS,
        guidance: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__()
        self.space = FeatureSpace(representation=representation)
        if net.feature_dim != self.space.dim:
            raise ValueError(
                f"net.feature_dim ({net.feature_dim}) must equal the {representation} "
                f"representation size ({self.space.dim})"
            )
        if (text is None) != (net.text_dim is None):
            raise ValueError(
                "text and net.text_dim go together: give both (text-conditioned) or neither "
                f"(unconstrained); got text={'set' if text is not None else None}, "
                f"net.text_dim={net.text_dim}"
            )
        if text is not None and text.encoder.width != net.text_dim:
            raise ValueError(
                f"net.text_dim ({net.text_dim}) must equal the text encoder width ({text.encoder.width})"
            )
        check_sigma_min(sigma_min)
        if not 0.0 <= condition_drop <= 1.0 or lambda_inter < 0:
            raise ValueError(
                f"condition_drop must lie in [0, 1] and lambda_inter be >= 0, got "
                f"{condition_drop} and {lambda_inter}"
            )
        if not 0.0 <= warmup_fraction < 1.0:
            raise ValueError(f"warmup_fraction must lie in [0, 1), got {warmup_fraction}")
        if validation_samples < 0 or sample_steps < 1:
            raise ValueError(
                f"validation_samples must be >= 0 and sample_steps >= 1, got "
                f"{validation_samples} and {sample_steps}"
            )
        self.net = net
        self._frozen = _Frozen(text=text)
        self.optimizer_factory = optimizer
        self.guidance = Guidance(**dict(guidance or {}))
        # plain Python values only, so checkpoints load with torch.load(weights_only=True)
        self.save_hyperparameters(
            {
                "representation": str(representation),
                "sigma_min": float(sigma_min),
                "lambda_inter": float(lambda_inter),
                "condition_drop": float(condition_drop),
                "warmup_fraction": float(warmup_fraction),
                "lr_milestones": [float(m) for m in lr_milestones],
                "lr_gamma": float(lr_gamma),
                "validation_samples": int(validation_samples),
                "sample_steps": int(sample_steps),
                "guidance": {key: value for key, value in vars(self.guidance).items()},
            },
            logger=False,
        )

    @property
    def text(self) -> TextFeatureCache | None:
        return self._frozen.text

    def setup(self, stage: str) -> None:
        """Copy the datamodule's normalization statistics into ``space`` (then checkpoints
        carry them); a datamodule without normalization (Inter-X) leaves the identity."""
        normalizer = getattr(self.trainer.datamodule, "normalizer", None) if self.trainer else None
        if normalizer is not None:
            self.space.set_statistics(normalizer.mean, normalizer.std)

    def reaction_parts(self) -> ReactionParts:
        if self.text is not None and self.text.encoder.device != self.device:
            self.text.encoder.to(self.device)
        return ReactionParts(self.net, self.space, self.text, self.hparams.sigma_min)

    def encode_text(self, captions: Sequence[str] | None) -> torch.Tensor | None:
        if self.text is None or captions is None:
            return None
        self.reaction_parts()  # the encoder follows the module's device
        return pooled_text(self.text, captions, self.device)

    def compute_losses(
        self,
        batch: Mapping[str, Any],
        *,
        condition_drop: float,
        generator: torch.Generator | None = None,
    ) -> ARFlowLosses:
        """L_all = L_fm + lambda_inter L_inter at a uniformly drawn t per sample (``generator``
        draws t and the condition drops; torch's global generator when None)."""
        motion = batch["motion"]
        roles = split_roles(motion, actor_index(batch))
        x0, x1 = self.space.flatten(roles.actor), self.space.flatten(roles.reactor)
        frame_mask = frame_mask_from_lengths(
            torch.as_tensor(batch["length"], device=motion.device), x0.shape[1]
        )
        t = torch.rand(x0.shape[0], generator=generator, device=x0.device)
        x_t = interpolate(x0, x1, t, sigma_min=self.hparams.sigma_min)
        text = self.encode_text(batch.get("caption"))
        drop = torch.rand(x0.shape[0], generator=generator, device=x0.device) < condition_drop
        x1_hat = self.net(x_t, t, x0, frame_mask, text, drop)
        # geometry (root frames, distances in metres) in float32 even under bf16 autocast
        with torch.autocast(device_type=x0.device.type, enabled=False):
            x1_hat, x0, x1 = x1_hat.float(), x0.float(), x1.float()
            reconstruction = reconstruction_loss(x1_hat, x1, frame_mask)
            actor = self.space.joints(x0)
            inter = interaction_loss(
                self.space.joints(x1_hat), self.space.joints(x1), actor, frame_mask
            )
        total = reconstruction + self.hparams.lambda_inter * inter.total
        return ARFlowLosses(total, reconstruction, inter)

    def loss_values(self, losses: ARFlowLosses) -> dict[str, torch.Tensor]:
        return {
            "loss": losses.total,
            "reconstruction": losses.reconstruction,
            "interaction": losses.interaction.total,
            "interaction_distance": losses.interaction.distance,
            "interaction_orientation": losses.interaction.orientation,
            "interaction_translation": losses.interaction.translation,
        }

    def _log_validation_samples(self, batch: dict[str, Any]) -> None:
        """Reactions for the first items (fixed seeds), plain and guided: reactor MPJPE (mm)
        and mean penetration penalty relu(zeta - SDF) next to the ground truth's."""
        count = min(self.hparams.validation_samples, batch["motion"].shape[0])
        motion = batch["motion"][:count].float()
        roles = split_roles(motion, actor_index(batch)[:count])
        x0 = self.space.flatten(roles.actor)
        frame_mask = frame_mask_from_lengths(
            torch.as_tensor(batch["length"][:count], device=motion.device), x0.shape[1]
        )
        captions = batch.get("caption")
        text = self.encode_text(None if captions is None else list(captions[:count]))
        actor = self.space.joints(x0)
        real = self.space.joints(self.space.flatten(roles.reactor))
        zeta = self.guidance.zeta
        values = {
            "real_penetration": penetration_loss(real, actor, zeta=zeta, frame_mask=frame_mask)
        }
        for name, guidance in (("generated", Guidance.off()), ("guided", self.guidance)):
            reaction = generate_reaction(
                self.reaction_parts(),
                x0,
                frame_mask,
                text=text,
                steps=self.hparams.sample_steps,
                guidance=guidance,
                seeds=list(range(count)),
            )
            joints = self.space.joints(reaction)
            error = (joints - real).norm(dim=-1).mean(dim=-1)  # (B, T)
            values[f"{name}_mpjpe_mm"] = 1000.0 * error[frame_mask].mean()
            values[f"{name}_penetration"] = penetration_loss(
                joints, actor, zeta=zeta, frame_mask=frame_mask
            )
        for name, value in values.items():
            self.log(f"val_samples/{name}", value, batch_size=count)
