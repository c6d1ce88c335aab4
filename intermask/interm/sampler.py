"""From captions to motion: text features -> iterative decoding -> VQ decoding -> joints.

One object that the training module (validation samples), the ``intermask generate`` command and
the evaluation protocol share, so the three can never decode differently.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any, NamedTuple

import torch
from einops import rearrange

from intermask.interm.decoding import Decoding, Edit, generate
from intermask.interm.graphs import GraphedForward
from intermask.interm.model import InterMTransformer, TextFeatures
from intermask.text.cache import TextFeatureCache
from intermask.utils.precision import BF16, FP32
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE

PRECISIONS = (FP32, BF16)


class GeneratedMotion(NamedTuple):
    tokens: torch.Tensor  # (B, 2, rows, T') codes, -1 on padding
    features: torch.Tensor  # (B, 2, T, *F) de-normalized dataset representation, T = 4 T'
    joints: torch.Tensor | None  # (B, T, 2, 22, 3) metres, Y-up; None without positions
    lengths: torch.Tensor  # (B,) frames (multiples of 4); frames beyond are padding


def decode_tokens(vq: MotionVQVAE, tokens: torch.Tensor) -> torch.Tensor:
    """(B, 2, rows, T') codes (-1 on padding) -> (B, 2, 4 T', *F) *normalized* features, 0 on
    the padding.

    Both persons go through the single-person decoder as one batch of 2B, each over its own
    steps (:meth:`~intermask.vq.model.MotionVQVAE.decode_valid`).
    """
    if tokens.ndim != 4 or tokens.shape[1] != 2:
        raise ValueError(f"tokens must be (B, 2, rows, T'), got {tuple(tokens.shape)}")
    flat = rearrange(tokens, "b p r t -> (b p) 1 r t")
    features = vq.decode_valid(flat)  # (2B, T, *F)
    return rearrange(features, "(b p) t ... -> b p t ...", p=2)


def joints_from_features(vq: MotionVQVAE, features: torch.Tensor) -> torch.Tensor | None:
    """(B, 2, T, *F) normalized features -> (B, T, 2, 22, 3) joints through the VQ's view
    (None when the representation has no positions, e.g. Inter-X without a body model)."""
    flat = rearrange(features, "b p t ... -> (b p) t ...")
    positions = vq.view.geometry(flat).positions
    if positions is None:
        return None
    return rearrange(positions, "(b p) t j c -> b t p j c", p=2)


def checked_steps(
    captions: Sequence[str] | None, lengths: torch.Tensor | Sequence[int], device: torch.device
) -> torch.Tensor:
    """(B,) frames -> (B,) token steps on ``device`` (rounded down), checked: at least one step
    each, and one caption per length when there are captions."""
    lengths = torch.as_tensor(lengths, device=device).long()
    if lengths.ndim != 1 or bool((lengths < FRAMES_PER_STEP).any()):
        raise ValueError(
            f"lengths must be (B,) frames >= {FRAMES_PER_STEP}, got {lengths.tolist()}"
        )
    if captions is not None and len(captions) != lengths.shape[0]:
        raise ValueError(f"got {len(captions)} captions for {lengths.shape[0]} lengths")
    return lengths // FRAMES_PER_STEP


class InteractionSampler:
    """Batched generation with a trained Inter-M Transformer and its frozen VQ-VAE.

    ``settings``: the :class:`~intermask.interm.decoding.Decoding` settings, whole (None: the
    paper's, section 3.3 and appendix C.1); ``changes`` replace single ones (``iterations=5``).
    ``cuda_graphs``: on a CUDA device, each shape of decoding pass is captured once as a CUDA
    graph and replayed (:mod:`intermask.interm.graphs`; the same kernels, so the same tokens); it
    does nothing elsewhere. ``precision``: ``32-true`` (the default) or ``bf16-mixed``, which runs
    the decoding passes and the VQ decoding under bf16 autocast on the sampler's device. bf16
    changes the numbers (other codes win near ties), so it is a choice the caller makes and
    labels; the outputs are fp32 either way.
    """

    def __init__(
        self,
        *,
        net: InterMTransformer,
        vq: MotionVQVAE,
        text: TextFeatureCache,
        settings: Decoding | None = None,
        cuda_graphs: bool = True,
        precision: str = FP32,
        **changes: Any,
    ) -> None:
        if precision not in PRECISIONS:
            raise ValueError(
                f"sampler precision must be one of {PRECISIONS} (resolve 'auto' first with "
                f"intermask.utils.precision.resolve_precision), got {precision!r}"
            )
        self.net, self.vq, self.text = net, vq, text
        self.settings = replace(settings or Decoding(), **changes)
        self.precision = precision
        self.forward = GraphedForward(net, enabled=cuda_graphs)

    @property
    def noise(self) -> str:
        """The settings' noise (the reference-order evaluation needs ``reference``)."""
        return self.settings.noise

    @property
    def device(self) -> torch.device:
        return next(self.net.parameters()).device

    def text_features(self, captions: Sequence[str]) -> TextFeatures:
        features = self.text.get_or_encode(list(captions))
        return TextFeatures(*(t.to(self.device) for t in features))

    def tokenize(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """(B, 2, T, *F) normalized features, (B,) frames -> (B, 2, rows, T/4) base-layer codes
        (-1 beyond ``lengths // FRAMES_PER_STEP``), for reaction and inpainting inputs."""
        tokens = [self.vq.encode(motion[:, person], lengths)[:, 0] for person in range(2)]
        return torch.stack(tokens, dim=1)

    @torch.no_grad()
    def __call__(
        self,
        captions: Sequence[str] | None,
        lengths: torch.Tensor,
        *,
        seeds: Sequence[int] | torch.Tensor | None = None,
        reference_tokens: torch.Tensor | None = None,
        edit: Edit | None = None,
        iterations: int | None = None,
    ) -> GeneratedMotion:
        """Generate B interactions.

        captions: B texts, or None for the null condition (reaction without text).
        lengths: (B,) frames; rounded down to a multiple of 4 (at least 4).
        seeds: (B,) one per sample (reproducible and independent of the batch).
        reference_tokens / edit: reaction (person A fixed) and inpainting, see :func:`generate`.
        iterations: in place of the settings' (a reaction's 12, appendix C).
        """
        steps = checked_steps(captions, lengths, self.device)
        text = None if captions is None else self.text_features(captions)
        settings = (
            self.settings if iterations is None else replace(self.settings, iterations=iterations)
        )
        with torch.autocast(self.device.type, dtype=torch.bfloat16, enabled=self.precision == BF16):
            tokens = generate(
                self.net,
                text,
                steps,
                settings=settings,
                seeds=seeds,
                reference_tokens=reference_tokens,
                edit=edit,
                forward=self.forward,
            )
            normalized = decode_tokens(self.vq, tokens).float()
        joints = joints_from_features(self.vq, normalized)
        flat = rearrange(normalized, "b p t ... -> (b p) t ...")
        features = rearrange(self.vq.view.denormalize(flat), "(b p) t ... -> b p t ...", p=2)
        return GeneratedMotion(tokens, features, joints, steps * FRAMES_PER_STEP)
