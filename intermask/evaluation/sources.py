"""Rows of the evaluation table: ground truth, InterMask interaction / reaction generation,
ARFlow reactions and VQ-VAE reconstruction, each turning an eval batch into de-normalized
two-person motion; :class:`Measured` adds penetration and latency to any of them;
:func:`motion_joints` gives the protocol the joints that interaction success judges."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import torch
from einops import rearrange

from intermask.data.normalization import Normalizer
from intermask.evaluation.protocol import Batch, MotionSource
from intermask.interm.sampler import InteractionSampler, joints_from_features
from intermask.metrics.mpjpe import MPJPE
from intermask.metrics.penetration import IntersectionFrequency, IntersectionVolume
from intermask.motion import interx as ix
from intermask.motion.masks import length_mask
from intermask.physics.volume import DEFAULT_PITCH, DEFAULT_TOLERANCE, intersection_volume
from intermask.reaction.guidance import GUIDANCE_LABELS, Guidance
from intermask.reaction.roles import actor_index
from intermask.reaction.sampler import sample_reactions
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE

if TYPE_CHECKING:
    from intermask.body.penetration import MeshPenetration


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
    """Interaction generation from the batch's captions at its (rounded) GT lengths; either
    generated person may be the actor (``knows_roles`` False)."""

    generates = True
    knows_roles = False

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
        iterations: int,  # configs/eval.yaml reaction.iterations (the paper's 12)
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
        decoded = rearrange(self.vq.decode_valid(indices), "(b p) t ... -> b p t ...", p=2)
        predicted_joints = joints_from_features(self.vq, decoded)
        real_joints = joints_from_features(self.vq, real)
        if predicted_joints is not None and real_joints is not None:
            mask = length_mask(lengths, frames)
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


class ARFlowReaction(MotionSource):
    """ARFlow reactions: the ODE transports the actor's motion to the reactor's (ARFlow eq. 9).

    The actor is the batch's annotation (``batch["actor"]``; person 1 without it), as ARFlow is
    trained; the evaluator sees the GT actor with the generated reactor in the batch's person
    order. Sampling is deterministic unless ``guidance.beta`` > 0, so MultiModality applies only
    to stochastic sampling.
    """

    def __init__(
        self,
        *,
        model: Any,
        normalizer: Normalizer | None,
        steps: int,
        guidance: Guidance,
        use_text: bool = True,
        name: str | None = None,
    ) -> None:
        self.model, self.normalizer, self.steps, self.guidance = model, normalizer, steps, guidance
        self.use_text = use_text
        self.generates = guidance.beta > 0
        guided = guidance.mode != "none" and guidance.lambda_pene > 0
        plural = "" if steps == 1 else "s"
        label = f" + {GUIDANCE_LABELS[guidance.mode]}" if guided else ""
        self.name = name or f"ARFlow{label} ({steps} step{plural})"

    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        inputs = batch if self.use_text else {k: v for k, v in batch.items() if k != "caption"}
        sample = sample_reactions(
            self.model, inputs, steps=self.steps, guidance=self.guidance, seeds=seeds
        )
        motion = batch["motion"].to(sample.features.device).float()
        if self.normalizer is not None:
            motion = self.normalizer.denormalize(motion)
        actor = actor_index(batch).to(motion.device)
        rows = torch.arange(motion.shape[0], device=motion.device)
        pair = motion.clone()
        pair[rows, 1 - actor] = sample.features.to(pair.dtype)
        return pair, batch["length"]


def feature_joints(features: torch.Tensor) -> torch.Tensor:
    """(..., T, *F) de-normalized InterHuman (262) or Inter-X (56, 6) features -> (..., T, 22, 3)
    joint positions in metres (Inter-X through the template skeleton, Z-up raw frame)."""
    return ix.person_joint_positions(features)


def motion_joints(motion: torch.Tensor) -> torch.Tensor | None:
    """(B, 2, T, *F) de-normalized features -> (B, T, 2, 22, 3) joints in metres, Y up, or None
    for a representation without positions (the protocol's ``joints``: interaction success)."""
    try:
        joints = feature_joints(motion.float())
    except ValueError:
        return None
    return rearrange(joints, "b p t j c -> b t p j c")


class Measured(MotionSource):
    """A row plus its Intersection Volume (cm^3 per frame), Intersection Frequency (share of
    frames over ``tolerance`` cm^3) and, with ``latency``, the wall time of the row's call per
    sample (ms; batches of the protocol's eval batch size) over the evaluation pass (ARFlow
    section 4.1; capsule proxy of :mod:`intermask.physics`). With ``mesh`` (a body model is
    configured) the same measures on fitted body meshes too (``mesh_iv_cm3``, ``mesh_if``) and
    the fit's mean joint error (``mesh_fit_error_mm``; docs/bodies.md).

    Only the evaluation pass counts: measurement stops at ``extra_metrics`` (read after that
    pass) and restarts at ``reset`` (before the next), so MultiModality batches do not enter.
    """

    def __init__(
        self,
        source: MotionSource,
        *,
        penetration: bool = True,
        latency: bool = True,
        pitch: float = DEFAULT_PITCH,
        tolerance: float = DEFAULT_TOLERANCE,
        mesh: MeshPenetration | None = None,
    ) -> None:
        self.source, self.penetration, self.latency = source, penetration, latency
        self.mesh = mesh if penetration else None
        self.volume = IntersectionVolume(pitch=pitch)
        self.frequency = IntersectionFrequency(pitch=pitch, tolerance=tolerance)
        self.name, self.generates = source.name, source.generates
        self.knows_roles = source.knows_roles
        self.reset()

    def reset(self) -> None:
        self.source.reset()
        self._measuring = True
        self.volume.reset()
        self.frequency.reset()
        if self.mesh is not None:
            self.mesh.reset()
        self._seconds, self._samples = 0.0, 0

    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        start = time.perf_counter()
        motion, lengths = self.source(batch, seeds)
        if self._measuring:
            if motion.is_cuda:
                torch.cuda.synchronize(motion.device)
            self._seconds += time.perf_counter() - start
            self._samples += motion.shape[0]
            if self.penetration:
                self._measure_penetration(motion, lengths)
        return motion, lengths

    @torch.no_grad()
    def _measure_penetration(self, motion: torch.Tensor, lengths: torch.Tensor) -> None:
        joints = feature_joints(motion.float())  # (B, 2, T, 22, 3)
        lengths = lengths.to(joints.device)
        valid = length_mask(lengths, joints.shape[2])
        volume = intersection_volume(
            joints[:, 0], joints[:, 1], pitch=self.volume.pitch, frame_mask=valid
        )[valid]
        self.volume.update(volumes=volume)  # computed once, counted by both metrics
        self.frequency.update(volumes=volume)
        if self.mesh is not None:
            self.mesh.update(joints, motion.float(), lengths)

    def extra_metrics(self) -> dict[str, float]:
        self._measuring = False
        values = dict(self.source.extra_metrics())
        if self.penetration and self.volume.frames > 0:
            values["iv_cm3"] = float(self.volume.compute())
            values["if"] = float(self.frequency.compute())
            if self.mesh is not None:
                values |= self.mesh.compute()
        if self.latency and self._samples:
            values["latency_ms"] = 1000.0 * self._seconds / self._samples
        return values
