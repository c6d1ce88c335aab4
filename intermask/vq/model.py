"""The motion VQ-VAE network: view -> encoder -> (residual) quantizer -> decoder -> view."""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from intermask.motion.masks import length_mask
from intermask.vq.convolutions import MotionDecoder, MotionEncoder
from intermask.vq.quantizers import ResidualQuantizer
from intermask.vq.views import TwoPersonView

# one token step covers 4 frames: the encoder halves time twice (convolutions.py)
FRAMES_PER_STEP = 4


class VQVAEOutput(NamedTuple):
    reconstruction: torch.Tensor  # (B, T, *F) normalized features
    indices: torch.Tensor  # (B, Q, rows, T/4)
    commit_loss: torch.Tensor  # ()
    perplexity: torch.Tensor  # (Q,)
    dead_codes: torch.Tensor  # (Q,)


class MotionVQVAE(nn.Module):
    """Tokenizes one person's motion into a (rows, T/4) grid of codes per quantizer layer.

    ``view`` adapts the dataset features (see :mod:`intermask.vq.views`); time must be a multiple
    of 4 (the two stride-2 stages). ``persons=2`` is the interaction-level ablation: the input is
    (B, T, 2, *F) and both persons share one token grid, so the encoder takes twice the channels.
    """

    def __init__(
        self,
        *,
        view: nn.Module,
        encoder: MotionEncoder,
        quantizer: ResidualQuantizer,
        decoder: MotionDecoder,
        persons: int = 1,
    ) -> None:
        super().__init__()
        if persons not in (1, 2):
            raise ValueError(f"persons must be 1 or 2, got {persons}")
        view = TwoPersonView(person=view) if persons == 2 else view
        if (encoder.num_joints, encoder.in_channels) != (view.num_joints, view.channels):
            raise ValueError(
                f"the encoder takes {encoder.num_joints} joints x {encoder.in_channels} channels, the "
                f"{persons}-person view gives {view.num_joints} x {view.channels}"
            )
        self.view, self.encoder, self.quantizer, self.decoder = view, encoder, quantizer, decoder

    @property
    def token_rows(self) -> int:
        """Rows of the token grid: 5 body parts (2D tokens) or 1 (the 1D-token ablation)."""
        return self.decoder.latent_rows

    @staticmethod
    def _check_frames(frames: int) -> None:
        if frames % FRAMES_PER_STEP:
            raise ValueError(
                f"the VQ-VAE needs a multiple of {FRAMES_PER_STEP} frames, got {frames}"
            )

    def forward(
        self, features: torch.Tensor, *, generator: torch.Generator | None = None
    ) -> VQVAEOutput:
        """(B, T, *F) normalized features -> reconstruction and quantizer statistics;
        ``generator`` draws the quantizer's random choices (torch's global one when None)."""
        self._check_frames(features.shape[1])
        latent = self.encoder(self.view.to_joints(features))
        quantized = self.quantizer(latent, generator=generator)
        reconstruction = self.view.from_joints(self.decoder(quantized.quantized))
        return VQVAEOutput(
            reconstruction,
            quantized.indices,
            quantized.commit_loss,
            quantized.perplexity,
            quantized.dead_codes,
        )

    @torch.no_grad()
    def encode(self, features: torch.Tensor, lengths: torch.Tensor | None = None) -> torch.Tensor:
        """(B, T, *F) normalized features -> (B, Q, rows, T/4) nearest-code indices.

        With ``lengths`` (B,) in frames, token steps at or beyond ``lengths // FRAMES_PER_STEP`` (padding; the
        generator works on lengths rounded down to a multiple of 4) are set to -1.
        """
        self._check_frames(features.shape[1])
        indices = self.quantizer.encode(self.encoder(self.view.to_joints(features)))
        if lengths is not None:
            steps = lengths.to(indices.device) // FRAMES_PER_STEP
            padding = ~length_mask(steps, indices.shape[-1])  # (B, T/4)
            indices = indices.masked_fill(padding[:, None, None, :], -1)
        return indices

    def decode(self, indices: torch.Tensor) -> torch.Tensor:
        """(B, Q', rows, T') indices (Q' <= Q layers, -1 = unused) -> (B, 4 T', *F) normalized features."""
        return self.view.from_joints(self.decoder(self.quantizer.lookup(indices)))

    def decode_valid(self, indices: torch.Tensor) -> torch.Tensor:
        """:meth:`decode` of a padded batch, each sample over its own steps only.

        indices: (B, Q', rows, T'), the base layer -1 on the padding steps at the end of a
        sample (what :meth:`encode` with lengths and the generators return). Returns (B, 4 T', *F)
        normalized features, 0 beyond each sample's steps. Decoding the padding too would let the
        decoder's convolutions carry whatever code stands there into the last valid frames; here
        a sample decodes as it would alone, whatever batch it is in.
        """
        steps = (indices[:, 0, 0] >= 0).sum(-1)  # (B,)
        valid = length_mask(steps, indices.shape[-1])  # (B, T')
        if not bool(((indices[:, 0] >= 0) == valid[:, None]).all()):
            raise ValueError(
                "decode_valid: the base layer's -1 (padding) must fill the last steps of every "
                "row of a sample, and nothing before them"
            )
        if bool((steps == indices.shape[-1]).all()):
            return self.decode(indices)
        features = None
        for count in steps.unique().tolist():
            if count == 0:
                continue  # a sample of padding only stays 0
            members = (steps == count).nonzero()[:, 0]
            decoded = self.decode(indices[members, ..., :count])  # (n, 4 count, *F)
            if features is None:
                shape = (indices.shape[0], FRAMES_PER_STEP * indices.shape[-1], *decoded.shape[2:])
                features = decoded.new_zeros(shape)
            features[members, : decoded.shape[1]] = decoded
        if features is None:
            raise ValueError("decode_valid: every sample of the batch is padding")
        return features
