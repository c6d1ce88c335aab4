"""Iterative masked decoding of the Inter-M Transformer (InterMask section 3.3, appendix G).

Token maps are ``(B, 2, rows, T')`` (person A, person B); ``-1`` marks padding. Decoding starts
with every generated position set to [MASK] and runs ``I`` iterations; each iteration makes one
forward pass (conditional and null condition stacked into one batch for classifier-free
guidance), samples every still-masked position, and re-masks the
``ceil(gamma((i + 1) / I) * n)`` least confident of them (``n`` generated tokens of the
sample). A token that survives a re-masking is never masked again; after the last iteration
``gamma(1) = 0`` and nothing is masked.

Interaction generation generates everything; reaction generation fixes person A's tokens
(appendix G, "the reference tokens remain unmasked throughout"); inpainting (MoMask) fixes every
token outside a region.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import torch

from intermask.interm.masking import cosine_schedule, lowest_ranks, scheduled_count
from intermask.interm.model import InterMTransformer, TextFeatures
from intermask.interm.tokens import step_padding_mask

ITERATIONS = 20  # I, interaction generation (section 3.3); reaction: 12 (paper), 10 (reference)
CFG_SCALE = 2.0  # s, classifier-free guidance scale (appendix C.1)
TOP_K_RATIO = 0.1  # keep the ceil(0.1 * K) largest logits (reference topk_filter_thres=0.9)


class Edit(NamedTuple):
    """Inpainting request: only ``region`` may change; every other valid token is kept."""

    tokens: torch.Tensor  # (B, 2, rows, T') codes outside the region (ignored inside it)
    region: torch.Tensor  # (B, 2, rows, T') bool, True where tokens are generated


def null_condition(model: InterMTransformer, batch: int, device: torch.device) -> torch.Tensor:
    """(B, D) null condition: the condition of a dropped text (no text is needed for it)."""
    features = torch.zeros(batch, 1, model.text_dim, device=device)
    eot = torch.zeros(batch, dtype=torch.long, device=device)
    drop = torch.ones(batch, dtype=torch.bool, device=device)
    return model.encode_condition(TextFeatures(features, eot), drop_condition=drop)


def guided_logits(
    model: InterMTransformer,
    tokens: torch.Tensor,
    condition: torch.Tensor | None,
    null: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    cfg_scale: float,
) -> torch.Tensor:
    """One forward pass -> (B, 2, rows, T', K) logits ``uncond + s * (cond - uncond)``.

    Without a condition, or with ``s = 1``, the batch is not doubled: the null or the
    conditional logits are returned as they are.
    """
    if condition is None or cfg_scale == 1.0:
        used = null if condition is None else condition
        out = model.forward_with_condition(tokens[:, 0], tokens[:, 1], used, lengths_in_steps)
        return torch.stack([out.logits_a, out.logits_b], dim=1)
    doubled = torch.cat([tokens, tokens])
    out = model.forward_with_condition(
        doubled[:, 0],
        doubled[:, 1],
        torch.cat([condition, null]),
        torch.cat([lengths_in_steps, lengths_in_steps]),
    )
    cond, uncond = torch.stack([out.logits_a, out.logits_b], dim=1).chunk(2)
    return uncond + cfg_scale * (cond - uncond)


def top_k_filter(logits: torch.Tensor, ratio: float) -> torch.Tensor:
    """Keep the ``ceil(ratio * K)`` largest logits of the last axis, set the others to -inf."""
    k = max(1, math.ceil(ratio * logits.shape[-1]))
    values, indices = logits.topk(k, dim=-1)
    return torch.full_like(logits, -math.inf).scatter(-1, indices, values)


def sample_codes(
    logits: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    generators: Sequence[torch.Generator],
    temperature: float,
) -> torch.Tensor:
    """(B, 2, rows, T', K) filtered logits -> (B, 2, rows, T') codes, by the Gumbel-max trick
    on ``logits / temperature`` (an exact sample of ``softmax(logits / temperature)``).

    Each sample's noise comes from its own generator and has its own clip length, so its codes
    do not depend on the rest of the batch or on T'; this per-sample draw is the only Python
    loop of the decoding. ``temperature = 0`` is greedy (argmax) decoding.
    """
    if temperature == 0:
        return logits.argmax(dim=-1)
    uniform = torch.full_like(logits, 0.5)
    for b, generator in enumerate(generators):
        length = int(lengths_in_steps[b])
        shape = (*logits.shape[1:3], length, logits.shape[-1])
        uniform[b, :, :, :length] = torch.rand(shape, generator=generator, device=logits.device)
    gumbel = -torch.log(-torch.log(uniform.clamp(1e-20, 1 - 1e-7)))
    return (logits / temperature + gumbel).argmax(dim=-1)


def _generators(seeds, batch: int, device: torch.device) -> list[torch.Generator]:
    if seeds is None:
        seeds = torch.randint(0, 2**62, (batch,))
    seeds = [int(s) for s in (seeds.tolist() if isinstance(seeds, torch.Tensor) else seeds)]
    if len(seeds) != batch:
        raise ValueError(f"expected {batch} seeds (one per sample), got {len(seeds)}")
    return [torch.Generator(device=device).manual_seed(s) for s in seeds]


def _start(
    model: InterMTransformer,
    valid: torch.Tensor,
    reference_tokens: torch.Tensor | None,
    edit: Edit | None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """-> initial (B, 2, rows, T') tokens with [MASK] on the generated positions, and the
    (B, 2, rows, T') bool generated positions."""
    if reference_tokens is not None and edit is not None:
        raise ValueError("reference_tokens (reaction) and edit (inpainting) are exclusive")
    shape = tuple(valid.shape)
    if reference_tokens is not None:
        if tuple(reference_tokens.shape) != (shape[0], *shape[2:]):
            raise ValueError(
                f"reference_tokens must be (B, rows, T') = {(shape[0], *shape[2:])}, got "
                f"{tuple(reference_tokens.shape)}"
            )
        fixed = torch.stack([reference_tokens, torch.zeros_like(reference_tokens)], dim=1)
        region = torch.zeros(shape, dtype=torch.bool, device=valid.device)
        region[:, 1] = True
        edit = Edit(fixed, region)
    if edit is None:
        edit = Edit(torch.zeros(shape, dtype=torch.long, device=valid.device), valid)
    if tuple(edit.tokens.shape) != shape or tuple(edit.region.shape) != shape:
        raise ValueError(
            f"edit tokens and region must be (B, 2, rows, T') = {shape}, got "
            f"{tuple(edit.tokens.shape)} and {tuple(edit.region.shape)}"
        )
    generated = valid & edit.region.bool()
    kept = edit.tokens.long()
    bad = valid & ~generated & ((kept < 0) | (kept >= model.codebook_size))
    if bool(bad.any()):
        raise ValueError(
            f"fixed tokens inside the clip must be codes in [0, {model.codebook_size}); got "
            f"{kept[bad].unique().tolist()}"
        )
    tokens = torch.where(generated, model.vocabulary.mask_id, kept)
    return tokens.masked_fill(~valid, -1), generated


@torch.no_grad()
def generate(
    model: InterMTransformer,
    text: TextFeatures | tuple | None,
    lengths_in_steps: torch.Tensor,
    *,
    steps: int | None = None,
    iterations: int = ITERATIONS,
    cfg_scale: float = CFG_SCALE,
    top_k_ratio: float = TOP_K_RATIO,
    temperature: float = 1.0,
    seeds: torch.Tensor | Sequence[int] | None = None,
    reference_tokens: torch.Tensor | None = None,
    edit: Edit | None = None,
) -> torch.Tensor:
    """Text (and optionally fixed tokens) -> (B, 2, rows, T') generated codes, -1 on padding.

    Args:
        text: :class:`TextFeatures` or ``(features, eot_index)`` of B texts; None generates
            from the null condition only (no guidance), e.g. reaction without text.
        lengths_in_steps: (B,) clip lengths in token steps; ``steps`` (T') defaults to the
            longest (or the width of the given tokens).
        iterations: I, one forward pass each.
        cfg_scale: s in ``uncond + s * (cond - uncond)`` on logits.
        top_k_ratio: sampling keeps the ``ceil(ratio * K)`` largest logits.
        temperature: logits are divided by it before sampling (the reference divides the
            probabilities, which ``Categorical`` renormalises away); 0 is greedy decoding.
        seeds: (B,) one seed per sample; a sample's result depends only on its own seed,
            text, length and fixed tokens, not on the other samples of the batch.
        reference_tokens: (B, rows, T') person A's codes for reaction generation; A stays
            fixed and only person B is generated.
        edit: :class:`Edit` for inpainting: only ``edit.region`` changes.

    The confidence of a sampled code is its probability under the guided logits before top-k
    and temperature (as in the reference).
    """
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, got {iterations}")
    if temperature < 0:
        raise ValueError(f"temperature must be >= 0, got {temperature}")
    for given in (reference_tokens, None if edit is None else edit.tokens):
        if given is not None and steps is None:
            steps = given.shape[-1]
    batch, device = lengths_in_steps.shape[0], lengths_in_steps.device
    steps = int(lengths_in_steps.max()) if steps is None else steps
    valid = ~step_padding_mask(lengths_in_steps, steps)[:, None, None, :]  # (B, 1, 1, T')
    valid = valid.expand(batch, 2, model.rows, steps)
    tokens, undecided = _start(model, valid, reference_tokens, edit)
    n_generated = undecided.flatten(1).sum(1)  # (B,)
    generators = _generators(seeds, batch, device) if temperature > 0 else []

    was_training = model.training
    model.eval()
    try:
        condition = None if text is None else model.encode_condition(text)
        null = null_condition(model, batch, device)
        for i in range(iterations):
            logits = guided_logits(model, tokens, condition, null, lengths_in_steps, cfg_scale)
            filtered = top_k_filter(logits, top_k_ratio)
            sampled = sample_codes(filtered, lengths_in_steps, generators, temperature)
            confidence = logits.float().log_softmax(-1).gather(-1, sampled[..., None])[..., 0].exp()
            tokens = torch.where(undecided, sampled, tokens)
            # re-mask the least confident of the positions sampled now; kept tokens never return
            count = scheduled_count(cosine_schedule((i + 1) / iterations), n_generated)
            scores = confidence.masked_fill(~undecided, math.inf)
            undecided = lowest_ranks(scores, count) & undecided
            tokens = tokens.masked_fill(undecided, model.vocabulary.mask_id)
    finally:
        model.train(was_training)
    return tokens.masked_fill(~valid, -1)
