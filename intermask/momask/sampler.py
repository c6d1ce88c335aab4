"""MoMask inference (section 3.4): base-layer mask-predict, then the residual layers.

Base layer: every valid step starts as [MASK]. Each of the ``L`` iterations (10) makes one
guided forward pass, samples every still-masked step from the top-k filtered logits (Gumbel-max
at the temperature), and re-masks the ``ceil(gamma((l + 1) / L) * n)`` least confident of them
(``n`` valid steps of the sample); after the last iteration ``gamma(1) = 0`` and nothing is
masked. A kept token never changes. Confidence is the probability of the sampled code under the
guided logits before filtering and temperature (the reference's). Steps beyond a length are
[PAD] for the network, never sampled, and -1 in the result. (The reference code instead counts
``max(1, round(gamma(l / (L - 1)) * n))`` masked tokens before iteration ``l``.)

Residual layers: one guided pass per layer ``j = 1..Q-1`` given the layers below. Greedy
(``temperature = 0``) by default, this framework's choice: the reference samples them with
temperature 1 and the same top-k filter, which ``temperature=1`` reproduces.

Guidance: ``uncond + s * (cond - uncond)`` on logits, the conditional and null rows stacked in
one doubled batch. That is the reference's form, in which its scales (4 and 5 on HumanML3D) are
given; the paper's eq. 5, ``(1 + s') cond - s' uncond``, is the same with ``s = 1 + s'``.

Top-k: ``top_k_ratio = 0.1`` keeps the ``ceil(0.1 K)`` largest logits, what the reference's
``top_k(logits, thres=0.9)`` keeps (``ceil((1 - 0.9) K)``, i.e. the top 10%, not 90%).

Randomness comes from one ``torch.Generator`` (None: torch's global one), drawn sample by sample
over each sample's valid steps, so a seeded generator reproduces the result.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from functools import partial
from typing import Any, NamedTuple

import torch
from torch import nn

from intermask.interm.decoding import (
    NOISES,
    SCHEDULES,
    reference_draw,
    remask,
    sample_codes,
    top_k_filter,
)
from intermask.interm.sampler import checked_steps
from intermask.interm.tokens import step_padding_mask
from intermask.momask.model import MaskedTransformer, ResidualTransformer, sentence_features
from intermask.text.cache import TextFeatureCache
from intermask.vq.model import FRAMES_PER_STEP, MotionVQVAE

# MoMask's decoding settings (section 4, HumanML3D): the defaults of :class:`MoMaskDecoding` and
# of the networks' own decoders, :func:`decode_base` and :func:`decode_residual`; the same numbers
# as configs/sampler/momask.yaml (tests/test_configs.py keeps them equal)
ITERATIONS = 10  # L (section 4, figure 7)
MASK_CFG_SCALE = 4.0  # s of the masked transformer on HumanML3D (section 4; KIT-ML: 2)
RESIDUAL_CFG_SCALE = 5.0  # s of the residual transformer (section 4)
TOP_K_RATIO = 0.1  # reference top_k filter_thres 0.9
TEMPERATURE = 1.0  # base-layer sampling temperature (reference)
RESIDUAL_TEMPERATURE = 0.0  # greedy residual layers (ours; the reference samples at 1)
SCHEDULE = "paper"  # base-layer re-masking: paper | reference (docs/fidelity.md row 4)
NOISE = "per_sample"  # per_sample | reference: the authors' draw order (row 4b)


def classifier_free_guidance(
    cond: torch.Tensor, uncond: torch.Tensor, scale: float
) -> torch.Tensor:
    """Guided logits ``uncond + scale * (cond - uncond)`` (scale 1: the conditional ones)."""
    return uncond + scale * (cond - uncond)


@contextmanager
def evaluating(*nets: nn.Module) -> Iterator[None]:
    """Eval mode (no dropout) for the block, then each network's previous mode."""
    modes = [net.training for net in nets]
    for net in nets:
        net.eval()
    try:
        yield
    finally:
        for net, mode in zip(nets, modes, strict=True):
            net.train(mode)


def guided_logits(
    run: Callable[[int, torch.Tensor], torch.Tensor],
    batch: int,
    conditional: bool,
    cfg_scale: float,
    device: torch.device,
) -> torch.Tensor:
    """``run(copies, drop)`` evaluates the network on ``copies`` stacked copies of the batch with
    condition drops ``drop`` (copies * B,). Without a caption the null condition alone; with
    ``cfg_scale = 1`` the conditional logits alone; otherwise both in one doubled batch."""
    if not conditional or cfg_scale == 1.0:
        return run(1, torch.full((batch,), not conditional, dtype=torch.bool, device=device))
    drop = torch.arange(2 * batch, device=device) >= batch  # conditional rows, then null rows
    cond, uncond = run(2, drop).chunk(2)
    return classifier_free_guidance(cond, uncond, cfg_scale)


def _runner(
    net: Callable[..., torch.Tensor], inputs: tuple[torch.Tensor, ...]
) -> Callable[[int, torch.Tensor], torch.Tensor]:
    """``run(copies, drop)`` of :func:`guided_logits`: ``net(*inputs, drop_condition=drop)``
    with every input repeated ``copies`` times along the batch."""

    def run(copies: int, drop: torch.Tensor) -> torch.Tensor:
        repeated = [x.repeat(copies, *([1] * (x.ndim - 1))) for x in inputs]
        return net(*repeated, drop_condition=drop)

    return run


def _check_settings(temperature: float, top_k_ratio: float, name: str = "temperature") -> None:
    if temperature < 0:
        raise ValueError(f"{name} must be >= 0, got {temperature}")
    if not 0.0 < top_k_ratio <= 1.0:
        raise ValueError(f"top_k_ratio must lie in (0, 1], got {top_k_ratio}")


def _check_base(iterations: int, schedule: str, noise: str) -> None:
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, got {iterations}")
    if schedule not in SCHEDULES or noise not in NOISES:
        raise ValueError(
            f"schedule must be one of {SCHEDULES} and noise one of {NOISES}, got {schedule!r} "
            f"and {noise!r}"
        )


@dataclass(frozen=True)
class MoMaskDecoding:
    """MoMask's decoding settings: one field per key of ``configs/sampler/momask.yaml`` (which
    ``intermask generate`` and the evaluation compose as ``momask``), whose values are these
    defaults. Construction checks them as :func:`decode_base` and :func:`decode_residual` do.

    Attributes:
        iterations: L, the base layer's forward passes.
        mask_cfg_scale, residual_cfg_scale: each transformer's guidance (module docstring).
        top_k_ratio: both layers' top-k filter.
        temperature, residual_temperature: the base and residual layers' sampling temperatures
            (0: greedy).
        schedule, noise: the base layer's re-masking and noise (:func:`decode_base`); both
            "reference" decode a converted release seed for seed as the authors' code does.
    """

    iterations: int = ITERATIONS
    mask_cfg_scale: float = MASK_CFG_SCALE
    residual_cfg_scale: float = RESIDUAL_CFG_SCALE
    top_k_ratio: float = TOP_K_RATIO
    temperature: float = TEMPERATURE
    residual_temperature: float = RESIDUAL_TEMPERATURE
    schedule: str = SCHEDULE
    noise: str = NOISE

    def __post_init__(self) -> None:
        _check_base(self.iterations, self.schedule, self.noise)
        _check_settings(self.temperature, self.top_k_ratio)
        _check_settings(self.residual_temperature, self.top_k_ratio, "residual_temperature")


def _text_or_null(text: torch.Tensor | None, batch: int, dim: int, device) -> torch.Tensor:
    if text is None:
        return torch.zeros(batch, dim, device=device)
    if tuple(text.shape) != (batch, dim):
        raise ValueError(f"text must be (B, D_text) = {(batch, dim)}, got {tuple(text.shape)}")
    return text.to(device)


Generators = torch.Generator | Sequence[torch.Generator] | None


def per_sample(generator: Generators, batch: int) -> list[torch.Generator | None]:
    """One generator per sample: a sequence is taken as is (one each, so a sample's draw
    depends only on its own generator), a single generator (or None) draws the whole batch."""
    if isinstance(generator, Sequence):
        if len(generator) != batch:
            raise ValueError(f"got {len(generator)} generators for {batch} samples")
        return list(generator)
    return [generator] * batch


def _sample(
    logits: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    generator: Generators,
    temperature: float,
    top_k_ratio: float,
) -> torch.Tensor:
    """(B, T', K) guided logits -> (B, T') codes: greedy at temperature 0, else Gumbel-max
    over the top-k filtered logits divided by the temperature."""
    if temperature == 0:
        return logits.argmax(dim=-1)
    filtered = top_k_filter(logits, top_k_ratio)
    return sample_codes(
        filtered, lengths_in_steps, per_sample(generator, logits.shape[0]), temperature
    )


@torch.no_grad()
def decode_base(
    net: MaskedTransformer,
    text: torch.Tensor | None,
    lengths_in_steps: torch.Tensor,
    *,
    steps: int | None = None,
    iterations: int = ITERATIONS,
    cfg_scale: float = MASK_CFG_SCALE,
    top_k_ratio: float = TOP_K_RATIO,
    temperature: float = TEMPERATURE,
    generator: Generators = None,
    schedule: str = SCHEDULE,
    noise: str = NOISE,
) -> torch.Tensor:
    """Mask-predict decoding of the base layer -> (B, T') codes, -1 at steps beyond a length.

    Args:
        text: (B, D_text) sentence features, or None for the null condition (no guidance).
        lengths_in_steps: (B,) clip lengths in token steps; ``steps`` (T') defaults to the
            longest.
        iterations: L forward passes.
        cfg_scale, top_k_ratio, temperature: see the module docstring; temperature 0 is greedy.
        generator: source of the sampling noise, or one generator per sample.
        schedule: "paper" (the module docstring) or "reference": the authors' re-masking counts
            and tie order (docs/fidelity.md row 4, shared with Inter-M's decoding).
        noise: "per_sample" or "reference": one ``Categorical`` draw over every step of the
            batch per pass, in order, from ``generator`` (the first, given one per sample), as
            the authors' loop draws after ``torch.manual_seed`` (row 4b).
    """
    _check_base(iterations, schedule, noise)
    _check_settings(temperature, top_k_ratio)
    batch_generator = generator[0] if isinstance(generator, Sequence) else generator
    device = next(net.parameters()).device
    lengths_in_steps = lengths_in_steps.to(device).long()
    batch = lengths_in_steps.shape[0]
    steps = int(lengths_in_steps.max()) if steps is None else steps
    valid = ~step_padding_mask(lengths_in_steps, steps)  # (B, T')
    features = _text_or_null(text, batch, net.text_dim, device)
    mask_id = net.vocabulary.mask_id
    tokens = torch.full((batch, steps), mask_id, dtype=torch.long, device=device)
    tokens = tokens.masked_fill(~valid, -1)
    undecided, count_valid = valid.clone(), valid.sum(dim=1)

    with evaluating(net):
        for i in range(iterations):
            run = _runner(net, (tokens, features, lengths_in_steps))
            logits = guided_logits(run, batch, text is not None, cfg_scale, device)  # (B, T', K)
            if noise == "reference" and temperature > 0:
                filtered = top_k_filter(logits, top_k_ratio)
                sampled = reference_draw(filtered, batch_generator, temperature)
            else:
                sampled = _sample(logits, lengths_in_steps, generator, temperature, top_k_ratio)
            confidence = logits.float().softmax(dim=-1).gather(-1, sampled[..., None])[..., 0]
            tokens = torch.where(undecided, sampled, tokens)
            undecided = remask(confidence, undecided, count_valid, i, iterations, schedule)
            tokens = tokens.masked_fill(undecided, mask_id)
    return tokens.masked_fill(~valid, -1)


@torch.no_grad()
def decode_residual(
    net: ResidualTransformer,
    base: torch.Tensor,
    text: torch.Tensor | None,
    lengths_in_steps: torch.Tensor,
    *,
    cfg_scale: float = RESIDUAL_CFG_SCALE,
    temperature: float = RESIDUAL_TEMPERATURE,
    top_k_ratio: float = TOP_K_RATIO,
    generator: Generators = None,
    layers: int | None = None,
) -> torch.Tensor:
    """Layers 1..``layers`` (default Q-1) from the base layer -> (B, Q, T') codes, -1 beyond
    each length and in the layers not predicted.

    Args:
        base: (B, T') base-layer codes (-1 allowed beyond the lengths).
        text: (B, D_text) sentence features, or None for the null condition.
        cfg_scale, temperature, top_k_ratio: see the module docstring (temperature 0: greedy).
    """
    _check_settings(temperature, top_k_ratio)
    q = net.num_quantizers
    layers = q - 1 if layers is None else layers
    if not 0 <= layers <= q - 1:
        raise ValueError(f"layers must lie in [0, {q - 1}], got {layers}")
    if base.ndim != 2:
        raise ValueError(f"base must be (B, T') codes, got {tuple(base.shape)}")
    device = next(net.parameters()).device
    base, lengths_in_steps = base.to(device).long(), lengths_in_steps.to(device).long()
    batch, steps = base.shape
    valid = ~step_padding_mask(lengths_in_steps, steps)
    if bool((valid & ((base < 0) | (base >= net.codebook_size))).any()):
        raise ValueError(
            f"base codes inside each length must lie in [0, {net.codebook_size}), got values in "
            f"[{int(base[valid].min())}, {int(base[valid].max())}]"
        )
    features = _text_or_null(text, batch, net.text_dim, device)
    tokens = torch.full((batch, q, steps), -1, dtype=torch.long, device=device)
    tokens[:, 0] = base.masked_fill(~valid, -1)

    with evaluating(net):
        for layer in range(1, layers + 1):
            run = _runner(partial(net, layer=layer), (tokens, features, lengths_in_steps))
            logits = guided_logits(run, batch, text is not None, cfg_scale, device)
            codes = _sample(logits, lengths_in_steps, generator, temperature, top_k_ratio)
            tokens[:, layer] = codes.masked_fill(~valid, -1)
    return tokens


class MoMaskSample(NamedTuple):
    tokens: torch.Tensor  # (B, Q, 1, T') codes, -1 beyond each length (and in unpredicted layers)
    features: torch.Tensor  # (B, 4 T', *F) normalized features decoded by the VQ-VAE
    lengths: torch.Tensor  # (B,) frames (multiples of 4); frames beyond are padding


class MoMaskSampler:
    """Captions and lengths -> MoMask tokens -> features, with the frozen VQ-VAE and text cache.

    Args:
        mask_net: the base-layer masked transformer.
        residual_net: the residual transformer, or None to decode the base layer alone
            ("MoMask (base)" in Table 1).
        vq: the residual VQ-VAE both were trained on (one token row).
        text: feature cache in front of the frozen text encoder.
        settings: the :class:`MoMaskDecoding` settings, whole (None: section 4's); ``changes``
            replace single ones (``iterations=4``).
    """

    def __init__(
        self,
        *,
        mask_net: MaskedTransformer,
        residual_net: ResidualTransformer | None,
        vq: MotionVQVAE,
        text: TextFeatureCache,
        settings: MoMaskDecoding | None = None,
        **changes: Any,
    ) -> None:
        if vq.token_rows != 1:
            raise ValueError(
                f"MoMask needs 1D tokens (one token row), the VQ-VAE has {vq.token_rows}"
            )
        codes, layers = vq.quantizer.codebook_size, vq.quantizer.num_quantizers
        nets = [("mask_net", mask_net)] + ([("residual_net", residual_net)] if residual_net else [])
        for name, net in nets:
            if net.codebook_size != codes:
                raise ValueError(
                    f"{name} has {net.codebook_size} codes per layer, the VQ-VAE {codes}"
                )
        if residual_net is not None and residual_net.num_quantizers != layers:
            raise ValueError(
                f"residual_net predicts {residual_net.num_quantizers} layers, the VQ-VAE has "
                f"{layers}"
            )
        self.mask_net, self.residual_net, self.vq, self.text = mask_net, residual_net, vq, text
        self.settings = replace(settings or MoMaskDecoding(), **changes)

    @property
    def device(self) -> torch.device:
        return next(self.mask_net.parameters()).device

    def sentence(self, captions: Sequence[str]) -> torch.Tensor:
        """B captions -> (B, D_text) sentence features on the networks' device."""
        return sentence_features(self.text.get_or_encode(list(captions))).to(self.device)

    @torch.no_grad()
    def tokens(
        self,
        captions: Sequence[str] | None,
        lengths: torch.Tensor,
        *,
        generator: Generators = None,
    ) -> torch.Tensor:
        """B captions (None: unconditional) and (B,) frames -> (B, Q, 1, T') codes, T' the
        longest length // 4; lengths are rounded down to a multiple of 4 (at least 4).
        ``generator``: one for the batch, or one per sample (then a sample's codes depend on its
        own generator only)."""
        steps = checked_steps(captions, lengths, self.device)
        text = None if captions is None else self.sentence(captions)
        settings = self.settings
        base = decode_base(
            self.mask_net,
            text,
            steps,
            iterations=settings.iterations,
            cfg_scale=settings.mask_cfg_scale,
            top_k_ratio=settings.top_k_ratio,
            temperature=settings.temperature,
            generator=generator,
            schedule=settings.schedule,
            noise=settings.noise,
        )
        if self.residual_net is None:
            layers = self.vq.quantizer.num_quantizers
            tokens = base.new_full((base.shape[0], layers, base.shape[1]), -1)
            tokens[:, 0] = base
        else:
            tokens = decode_residual(
                self.residual_net,
                base,
                text,
                steps,
                cfg_scale=settings.residual_cfg_scale,
                temperature=settings.residual_temperature,
                top_k_ratio=settings.top_k_ratio,
                generator=generator,
            )
        return tokens[:, :, None, :]

    @torch.no_grad()
    def __call__(
        self,
        captions: Sequence[str] | None,
        lengths: torch.Tensor,
        *,
        generator: Generators = None,
    ) -> MoMaskSample:
        """Generate B motions: :meth:`tokens`, then the VQ-VAE decoder."""
        tokens = self.tokens(captions, lengths, generator=generator)
        self.vq.to(self.device)
        features = self.vq.decode_valid(tokens)
        lengths = torch.as_tensor(lengths, device=self.device).long()
        return MoMaskSample(tokens, features, lengths - lengths % FRAMES_PER_STEP)
