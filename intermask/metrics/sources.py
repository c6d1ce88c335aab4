"""Rows of the evaluation table: ground truth, InterMask interaction / reaction generation and
VQ-VAE reconstruction, each turning an eval batch into de-normalized two-person motion."""

from __future__ import annotations

import torch
from einops import rearrange

from intermask.data.normalization import Normalizer
from intermask.interm.sampler import FRAMES_PER_STEP, InteractionSampler, joints_from_features
from intermask.metrics.mpjpe import MPJPE
from intermask.metrics.protocol import Batch, MotionSource
from intermask.vq.model import MotionVQVAE


def token_lengths(batch: Batch, frames: int) -> torch.Tensor:
    """(B,) GT lengths rounded down to a multiple of 4 (as InterMask does), within ``frames``."""
    lengths = batch["length"].long().clamp(max=frames)
    return (lengths - lengths % FRAMES_PER_STEP).clamp_min(FRAMES_PER_STEP)


def _usable_frames(motion: torch.Tensor) -> int:
    return motion.shape[2] - motion.shape[2] % FRAMES_PER_STEP


class GroundTruth(MotionSource):
    """The test motion itself (de-normalized with the dataset's statistics when it has them)."""

    generates = False

    def __init__(self, *, normalizer: Normalizer | None, name: str = "Ground Truth") -> None:
        self.normalizer, self.name = normalizer, name

    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        motion = batch["motion"]
        if self.normalizer is not None:
            motion = self.normalizer.denormalize(motion)
        return motion, batch["length"]


class InterMaskGeneration(MotionSource):
    """Interaction generation from the batch's captions at its (rounded) GT lengths."""

    generates = True

    def __init__(self, *, sampler: InteractionSampler, name: str = "InterMask") -> None:
        self.sampler, self.name = sampler, name

    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        lengths = token_lengths(batch, _usable_frames(batch["motion"]))
        out = self.sampler(list(batch["caption"]), lengths, seeds=seeds)
        return out.features, out.lengths


class InterMaskReaction(MotionSource):
    """Reaction generation (appendix G): person 1's tokens are fixed, person 2 is generated;
    the evaluator sees GT person 1 with the generated person 2 (the InterHuman convention).

    ``use_text=False`` generates from the null condition (reaction without text).
    """

    generates = True

    def __init__(
        self,
        *,
        sampler: InteractionSampler,
        normalizer: Normalizer | None,
        iterations: int = 10,  # the reference's reaction setting (the paper states 12)
        use_text: bool = True,
        name: str = "InterMask (reaction)",
    ) -> None:
        self.sampler, self.normalizer, self.iterations = sampler, normalizer, iterations
        self.use_text, self.name = use_text, name

    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        motion = batch["motion"].to(self.sampler.device)
        frames = _usable_frames(motion)
        lengths = token_lengths(batch, frames).to(motion.device)
        reference = self.sampler.vq.encode(motion[:, 0, :frames].float(), lengths)[:, 0]
        captions = list(batch["caption"]) if self.use_text else None
        out = self.sampler(
            captions, lengths, seeds=seeds, reference_tokens=reference, iterations=self.iterations
        )
        actor = motion[:, 0, :frames]
        if self.normalizer is not None:
            actor = self.normalizer.denormalize(actor)
        return torch.stack([actor.to(out.features.dtype), out.features[:, 1]], dim=1), lengths


class VQReconstruction(MotionSource):
    """Both persons through the VQ-VAE (encode -> nearest codes -> decode); also MPJPE (mm)
    against the GT joints when the representation has positions (paper Table 2)."""

    generates = False

    def __init__(self, *, vq: MotionVQVAE, name: str = "VQ-VAE reconstruction") -> None:
        self.vq, self.name = vq, name
        self.mpjpe = MPJPE()

    @property
    def device(self) -> torch.device:
        return next(self.vq.parameters()).device

    def reset(self) -> None:
        self.mpjpe.reset()

    @torch.no_grad()
    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        motion = batch["motion"].to(self.device).float()
        frames = _usable_frames(motion)
        lengths = token_lengths(batch, frames).to(motion.device)
        real = motion[:, :, :frames]
        flat = rearrange(real, "b p t ... -> (b p) t ...")
        indices = self.vq.encode(flat, lengths.repeat_interleave(2))
        decoded = rearrange(self.vq.decode(indices.clamp_min(0)), "(b p) t ... -> b p t ...", p=2)
        predicted_joints = joints_from_features(self.vq, decoded)
        real_joints = joints_from_features(self.vq, real)
        if predicted_joints is not None and real_joints is not None:
            mask = torch.arange(frames, device=lengths.device)[None, :] < lengths[:, None]
            self.mpjpe.update(
                rearrange(predicted_joints, "b t p j c -> (b p) t j c"),
                rearrange(real_joints, "b t p j c -> (b p) t j c"),
                mask.repeat_interleave(2, dim=0),
            )
        features = self.vq.view.denormalize(rearrange(decoded, "b p t ... -> (b p) t ..."))
        return rearrange(features, "(b p) t ... -> b p t ...", p=2), lengths

    def extra_metrics(self) -> dict[str, float]:
        if int(self.mpjpe.count) == 0:
            return {}
        return {"mpjpe_mm": float(self.mpjpe.compute())}
