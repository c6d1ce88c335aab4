"""Intersection Volume and Frequency on fitted body meshes, for batches of generated motion:
what an evaluation row measures beside the capsule proxy when a body model is configured."""

from __future__ import annotations

import torch

from intermask.body.export import body_vertices
from intermask.body.fit import FitSettings, fit_bodies
from intermask.body.model import BodyModel
from intermask.metrics.penetration import MeshIntersectionFrequency, MeshIntersectionVolume
from intermask.physics.mesh_volume import mesh_intersection_volume
from intermask.physics.volume import DEFAULT_PITCH, DEFAULT_TOLERANCE

DEFAULT_FIT_SAMPLES = 8  # interactions fitted in one batch (2 persons each)


def pad_with_last_frame(x: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
    """(B, P, T, ...) -> the same with every frame from lengths[b] on a copy of frame
    lengths[b] - 1: a still pose changes neither the bone lengths' median much nor the smoothness,
    so one batch can hold interactions of different lengths."""
    batch, persons, frames = x.shape[:3]
    steps = torch.arange(frames, device=x.device)
    index = torch.minimum(steps[None], (lengths.to(x.device) - 1).clamp_min(0)[:, None])  # (B, T)
    trailing = x.shape[3:]
    index = index.reshape(batch, 1, frames, *([1] * len(trailing)))
    return x.gather(2, index.expand(batch, persons, frames, *trailing))


class MeshPenetration:
    """Fits one body per person of each interaction and accumulates the two meshes'
    intersection volume (cm^3 per valid frame) and frequency."""

    def __init__(
        self,
        model: BodyModel,
        *,
        pitch: float = DEFAULT_PITCH,
        tolerance: float = DEFAULT_TOLERANCE,
        settings: FitSettings | None = None,
        fit_samples: int = DEFAULT_FIT_SAMPLES,
    ) -> None:
        if fit_samples < 1:
            raise ValueError(f"MeshPenetration: fit_samples must be >= 1, got {fit_samples}")
        self.model, self.settings, self.fit_samples = model, settings or FitSettings(), fit_samples
        self.volume = MeshIntersectionVolume(pitch=pitch)
        self.frequency = MeshIntersectionFrequency(pitch=pitch, tolerance=tolerance)
        self.fit_errors: list[torch.Tensor] = []

    def reset(self) -> None:
        self.volume.reset()
        self.frequency.reset()
        self.fit_errors = []

    @torch.no_grad()
    def update(
        self, joints: torch.Tensor, features: torch.Tensor | None, lengths: torch.Tensor
    ) -> None:
        """joints (B, 2, T, 22, 3) Y up; features (B, 2, T, *F) de-normalized or None; lengths (B,)."""
        device, dtype = self.model.v_template.device, self.model.v_template.dtype
        lengths = lengths.to(joints.device)
        for start in range(0, joints.shape[0], self.fit_samples):
            rows = slice(start, start + self.fit_samples)
            count, persons = joints[rows].shape[:2]
            longest = int(lengths[rows].max())  # batches come padded to the protocol's length
            padded = pad_with_last_frame(joints[rows, :, :longest], lengths[rows]).flatten(0, 1)
            motion = (
                None
                if features is None
                else pad_with_last_frame(features[rows, :, :longest], lengths[rows]).flatten(0, 1)
            )
            with torch.enable_grad():
                fit = fit_bodies(
                    self.model,
                    padded.to(device=device, dtype=dtype),
                    None if motion is None else motion.to(device=device, dtype=dtype),
                    settings=self.settings,
                )
            for k in range(count):
                frames = int(lengths[rows][k])
                people = slice(k * persons, (k + 1) * persons)
                params = fit.params._replace(
                    betas=fit.params.betas[people],
                    rotations=fit.params.rotations[people, :frames],
                    hands=None if fit.params.hands is None else fit.params.hands[people, :frames],
                    transl=fit.params.transl[people, :frames],
                )
                vertices = body_vertices(self.model, params)  # (2, t, V, 3)
                volume = mesh_intersection_volume(
                    vertices[0], vertices[1], self.model.faces, pitch=self.volume.pitch
                )
                self.volume.update(volumes=volume)
                self.frequency.update(volumes=volume)
                self.fit_errors.append(fit.error[people, :frames].flatten().cpu())

    def compute(self) -> dict[str, float]:
        """{"mesh_iv_cm3", "mesh_if", "mesh_fit_error_mm"} over the valid frames so far."""
        if self.volume.frames == 0:
            raise ValueError("MeshPenetration.compute() called before any valid frame")
        error = torch.cat(self.fit_errors) if self.fit_errors else torch.zeros(0)
        return {
            "mesh_iv_cm3": float(self.volume.compute()),
            "mesh_if": float(self.frequency.compute()),
            "mesh_fit_error_mm": float(error.mean() * 1000.0) if error.numel() else float("nan"),
        }
