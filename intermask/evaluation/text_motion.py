"""Rows of the single-person (text-to-motion, HumanML3D) table: each turns an eval batch of
items ``{"motion": (B, T, 263) z-scored, "length", "caption", ...}`` into de-normalized
``(B, T, 263)`` motion for the T2M evaluator, which ignores the frames past each length (the
protocol itself is shape-agnostic)."""

from __future__ import annotations

from collections.abc import Callable

import torch

from intermask.evaluation.protocol import Batch, MotionSource
from intermask.evaluation.sources import VQReconstruction, token_lengths
from intermask.motion.masks import length_mask
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE


def _usable_frames(motion: torch.Tensor) -> int:
    return motion.shape[1] - motion.shape[1] % FRAMES_PER_STEP


class SoloReconstruction(VQReconstruction):
    """The items through the tokenizer (encode -> nearest codes of every layer, or of the first
    ``layers`` -> decode), with MPJPE (mm) of the recovered joints against the GT's (the
    two-person row's metric, reset and device)."""

    def __init__(
        self, *, vq: MotionVQVAE, layers: int | None = None, name: str = "RVQ reconstruction"
    ) -> None:
        quantizers = vq.quantizer.num_quantizers
        if layers is not None and not 1 <= layers <= quantizers:
            raise ValueError(
                f"layers must be in [1, {quantizers}] for this tokenizer, got {layers}"
            )
        super().__init__(vq=vq, name=name)
        self.layers = layers

    @torch.no_grad()
    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        motion = batch["motion"].to(self.device).float()
        frames = _usable_frames(motion)
        lengths = token_lengths(batch, frames).to(motion.device)
        real = motion[:, :frames]
        indices = self.vq.encode(real, lengths)
        if self.layers is not None:
            indices = indices[:, : self.layers]
        decoded = self.vq.decode_valid(indices)
        mask = length_mask(lengths, frames)
        predicted, target = self.vq.view.geometry(decoded), self.vq.view.geometry(real)
        if predicted.positions is not None and target.positions is not None:
            self.mpjpe.update(predicted.positions, target.positions, mask)
        return self.vq.view.denormalize(decoded), lengths


class TextToMotion(MotionSource):
    """Generation from the batch's captions at its lengths (rounded down to token steps):
    ``generate(captions, lengths, seeds) -> (B, T, 263)`` de-normalized features."""

    generates = True

    def __init__(
        self,
        *,
        generate: Callable[[list[str], torch.Tensor, torch.Tensor], torch.Tensor],
        name: str,
    ) -> None:
        self.generate, self.name = generate, name

    @torch.no_grad()
    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        lengths = token_lengths(batch, _usable_frames(batch["motion"]))
        return self.generate(list(batch["caption"]), lengths, seeds), lengths
