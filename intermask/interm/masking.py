"""Training-time masking of the Inter-M Transformer (InterMask section 3.2.1 and appendix G).

Token maps of both persons are stacked as ``(B, 2, rows, T')`` (person index 0 = A, 1 = B);
``-1`` marks VQ padding, and every step at or beyond ``lengths_in_steps`` (B,) is padding too.
Masks are boolean tensors of the same shape, True where a token is masked (predicted).

Stage 1 (eq. 3): with probability ``p_r`` random masking of both persons with ratio
``gamma(tau) = cos(pi * tau / 2)``, ``tau ~ U(0, 1)``; otherwise interaction masking (every
token of one person). This framework adds solo masking, off by default (``p_solo``): one person
wholly masked, the other randomly masked as in eq. 3, which is what decoding the persons in turn
asks of the model (person A is decoded while B is all [MASK]); and partner masking, off by
default (``p_partner``): one person wholly visible, the other masked on the schedule, the state of
every later iteration of B's turn and of reaction generation (interaction masking only shows its
first iteration, B all [MASK]). The masked positions are then
corrupted BERT-style. Stage 2 (step
unroll, after Kim et al. 2023b): the least confident of the stage-1 predictions are re-masked
with the ratio of the next step and predicted again.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import torch

from intermask.interm.tokens import Vocabulary, step_padding_mask

P_RANDOM = 0.8  # p_r, random- vs interaction-masking probability (section 3.2.1, Table 7)
BERT_RANDOM_PROB = 0.1  # reference: share of masked positions given a random code
BERT_MASK_PROB = 0.88  # reference: share of the remaining masked positions given [MASK]
STEP_UNROLL_TAU_STEP = 1 / 21  # reference: tau_next = tau + 1 / (total_timesteps + 1), 20 steps
# gamma^-1(0.5): interaction masking hides exactly half of the valid tokens (the reference
# gives those samples mask ratio 0.5 and inverts the schedule the same way).
INTERACTION_TAU = 2 / 3


def cosine_schedule(tau: torch.Tensor | float) -> torch.Tensor:
    """Mask ratio ``gamma(tau) = cos(pi * tau / 2)`` (eq. 3), exactly 0 at ``tau >= 1``.

    ``cos(pi / 2)`` is 6e-17 in floating point, and ``ceil(6e-17 * n)`` would leave one token
    masked after the last decoding iteration; hence the explicit zero.
    """
    tau = torch.as_tensor(tau, dtype=torch.float64)
    return torch.where(tau >= 1, torch.zeros_like(tau), torch.cos(math.pi * tau / 2))


def inverse_cosine_schedule(ratio: torch.Tensor | float) -> torch.Tensor:
    """``tau`` with ``gamma(tau) = ratio``: ``2 / pi * acos(ratio)``."""
    ratio = torch.as_tensor(ratio, dtype=torch.float64).clamp(0, 1)
    return torch.acos(ratio) * 2 / math.pi


class TrainingMask(NamedTuple):
    mask: torch.Tensor  # (B, 2, rows, T') bool, True at masked (predicted) tokens
    tau: torch.Tensor  # (B,) float64 schedule progress of each sample (for step unroll)
    is_random: torch.Tensor  # (B,) bool, True where random masking was used


class Corruption(NamedTuple):
    tokens: torch.Tensor  # (B, 2, rows, T') model input
    is_random: torch.Tensor  # (B, 2, rows, T') bool, masked positions given a random code
    is_mask: torch.Tensor  # (B, 2, rows, T') bool, masked positions given [MASK]


class StepUnroll(NamedTuple):
    tokens: torch.Tensor  # (B, 2, rows, T') input of the second forward pass
    mask: torch.Tensor  # (B, 2, rows, T') bool, loss positions of the second pass
    remasked: torch.Tensor  # (B, 2, rows, T') bool, positions that are [MASK] again
    tau: torch.Tensor  # (B,) float64 advanced progress


def stack_persons(tokens_a: torch.Tensor, tokens_b: torch.Tensor) -> torch.Tensor:
    """Two (B, rows, T') maps -> (B, 2, rows, T')."""
    if tokens_a.shape != tokens_b.shape or tokens_a.ndim != 3:
        raise ValueError(
            "tokens_a and tokens_b must both be (B, rows, T'), got "
            f"{tuple(tokens_a.shape)} and {tuple(tokens_b.shape)}"
        )
    return torch.stack([tokens_a, tokens_b], dim=1)


def valid_tokens(tokens: torch.Tensor, lengths_in_steps: torch.Tensor) -> torch.Tensor:
    """(B, 2, rows, T') tokens -> (B, 2, rows, T') bool, True inside the clip and not -1."""
    inside = ~step_padding_mask(lengths_in_steps, tokens.shape[-1])  # (B, T')
    return inside[:, None, None, :] & (tokens >= 0)


def _rand(shape: tuple[int, ...], like: torch.Tensor, generator: torch.Generator | None):
    return torch.rand(shape, generator=generator, device=like.device)


def scheduled_count(ratio: torch.Tensor, count: torch.Tensor, *, minimum: int = 0) -> torch.Tensor:
    """(B,) ``ceil(ratio * count)``, at least ``minimum``, as float64.

    A 1e-9 slack keeps float error from adding a token: ``cos(pi / 3) * 6`` is
    ``3.0000000000000004`` in float64, whose ceiling would be 4.
    """
    return torch.ceil(ratio * count.double() - 1e-9).clamp(min=minimum)


def lowest_ranks(scores: torch.Tensor, count: torch.Tensor) -> torch.Tensor:
    """(B, ...) scores, (B,) counts -> (B, ...) bool, True at the ``count`` lowest scores of each
    sample (ties broken by flat position: stable sort)."""
    flat = scores.flatten(1)
    ranks = flat.argsort(dim=1, stable=True).argsort(dim=1)
    return (ranks < count[:, None].to(ranks.device)).reshape(scores.shape)


def random_masking(
    tokens_a: torch.Tensor,
    tokens_b: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    *,
    generator: torch.Generator | None = None,
    tau: torch.Tensor | None = None,
) -> torch.Tensor:
    """Random masking of both persons (eq. 3) -> (B, 2, rows, T') bool mask.

    Per sample ``tau ~ U(0, 1)`` (or the given (B,) ``tau``), and ``ceil(gamma(tau) * n)``
    tokens, at least one, are masked, chosen uniformly among the ``n = 2 * rows * length``
    valid tokens of both persons; padding is never masked. The reference instead rounds the
    ratio times the padded length and then drops the padded positions, so short clips get a
    lower ratio than scheduled and can end with nothing masked.
    """
    tokens = stack_persons(tokens_a, tokens_b)
    valid = valid_tokens(tokens, lengths_in_steps)
    batch = tokens.shape[0]
    if tau is None:
        tau = _rand((batch,), tokens, generator).double()
    return scheduled_mask(valid, tau, generator)


def scheduled_mask(
    eligible: torch.Tensor, tau: torch.Tensor, generator: torch.Generator | None
) -> torch.Tensor:
    """(B, ...) bool -> ``ceil(gamma(tau) * n)`` (at least one) of each sample's ``n`` eligible
    positions, chosen uniformly."""
    count = scheduled_count(
        cosine_schedule(tau).to(eligible.device), eligible.flatten(1).sum(1), minimum=1
    )
    scores = _rand(tuple(eligible.shape), eligible, generator).masked_fill(~eligible, math.inf)
    return lowest_ranks(scores, count) & eligible


def _one_person(batch: int, like: torch.Tensor, generator: torch.Generator | None) -> torch.Tensor:
    """(B, 2, 1, 1) bool, True for one person per sample, chosen uniformly."""
    person = (_rand((batch,), like, generator) < 0.5).long()  # (B,)
    chosen = torch.arange(2, device=like.device)[None, :] == person[:, None]  # (B, 2)
    return chosen[:, :, None, None]


def _valid_and_one_person(
    tokens_a: torch.Tensor,
    tokens_b: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    generator: torch.Generator | None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, 2, rows, T') valid tokens and (B, 2, 1, 1) one person per sample, chosen uniformly."""
    tokens = stack_persons(tokens_a, tokens_b)
    return valid_tokens(tokens, lengths_in_steps), _one_person(tokens.shape[0], tokens, generator)


def interaction_masking(
    tokens_a: torch.Tensor,
    tokens_b: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    *,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Interaction masking -> (B, 2, rows, T') bool mask: all valid tokens of one person, chosen
    uniformly per sample, are masked; the other person stays fully visible (section 3.2.1)."""
    valid, chosen = _valid_and_one_person(tokens_a, tokens_b, lengths_in_steps, generator)
    return valid & chosen


def solo_masking(
    tokens_a: torch.Tensor,
    tokens_b: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    *,
    tau: torch.Tensor,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Solo masking -> (B, 2, rows, T') bool mask: every valid token of one person, chosen
    uniformly per sample, as if that person were still to come; of the other person's ``n``
    valid tokens ``ceil(gamma(tau) * n)``, at least one, chosen uniformly."""
    valid, hidden = _valid_and_one_person(tokens_a, tokens_b, lengths_in_steps, generator)
    return scheduled_mask(valid & ~hidden, tau, generator) | (valid & hidden)


def partner_masking(
    tokens_a: torch.Tensor,
    tokens_b: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    *,
    tau: torch.Tensor,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Partner masking -> (B, 2, rows, T') bool mask: one person, chosen uniformly per sample,
    is masked on the schedule (``ceil(gamma(tau) * n)`` of its ``n`` valid tokens, at least one)
    while the other, its partner, stays wholly visible. Interaction masking is its ``tau = 0``."""
    valid, masked = _valid_and_one_person(tokens_a, tokens_b, lengths_in_steps, generator)
    return scheduled_mask(valid & masked, tau, generator)


def training_mask(
    tokens_a: torch.Tensor,
    tokens_b: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    *,
    p_random: float = P_RANDOM,
    p_solo: float = 0.0,
    p_partner: float = 0.0,
    generator: torch.Generator | None = None,
) -> TrainingMask:
    """Stage-1 mask: per sample random masking with probability ``p_random`` (p_r = 0.8 in the
    paper), otherwise interaction masking, or solo masking for a ``p_solo`` share of those
    samples, and partner masking for a ``p_partner`` share of the samples left to interaction
    masking (each 0 in the paper and drawing nothing then: the random stream is the paper
    setting's).

    ``tau`` is the sampled progress for random masking and ``gamma^-1(0.5) = 2/3`` for
    interaction masking (half of the valid tokens are hidden); for solo and partner masking, the
    progress whose ratio is the share of valid tokens it hides. The reference draws one
    interaction/random decision per batch and masks person A in one half of the batch and
    person B in the other; we decide per sample.
    """
    for name, prob in (("p_random", p_random), ("p_solo", p_solo), ("p_partner", p_partner)):
        if not 0.0 <= prob <= 1.0:
            raise ValueError(f"{name} must lie in [0, 1], got {prob}")
    batch = tokens_a.shape[0]
    tau = _rand((batch,), tokens_a, generator).double()
    is_random = _rand((batch,), tokens_a, generator) < p_random
    random = random_masking(tokens_a, tokens_b, lengths_in_steps, generator=generator, tau=tau)
    interaction = interaction_masking(tokens_a, tokens_b, lengths_in_steps, generator=generator)
    mask = torch.where(is_random[:, None, None, None], random, interaction)
    tau = torch.where(is_random, tau, torch.full_like(tau, INTERACTION_TAU))
    is_solo = torch.zeros_like(is_random)
    if p_solo > 0:
        is_solo = ~is_random & (_rand((batch,), tokens_a, generator) < p_solo)
        solo_tau = _rand((batch,), tokens_a, generator).double()
        solo = solo_masking(tokens_a, tokens_b, lengths_in_steps, tau=solo_tau, generator=generator)
        mask = torch.where(is_solo[:, None, None, None], solo, mask)
    is_partner = torch.zeros_like(is_random)
    if p_partner > 0:
        is_partner = ~is_random & ~is_solo & (_rand((batch,), tokens_a, generator) < p_partner)
        partner_tau = _rand((batch,), tokens_a, generator).double()
        partner = partner_masking(
            tokens_a, tokens_b, lengths_in_steps, tau=partner_tau, generator=generator
        )
        mask = torch.where(is_partner[:, None, None, None], partner, mask)
    if p_solo > 0 or p_partner > 0:
        valid = valid_tokens(stack_persons(tokens_a, tokens_b), lengths_in_steps)
        share = mask.flatten(1).sum(1).double() / valid.flatten(1).sum(1).clamp(min=1).double()
        tau = torch.where(is_solo | is_partner, inverse_cosine_schedule(share), tau)
    return TrainingMask(mask, tau, is_random)


def bert_corruption(
    tokens: torch.Tensor,
    mask: torch.Tensor,
    vocabulary: Vocabulary,
    *,
    generator: torch.Generator | None = None,
    random_prob: float = BERT_RANDOM_PROB,
    mask_prob: float = BERT_MASK_PROB,
) -> Corruption:
    """BERT-style corruption of the masked positions of (B, 2, rows, T') ``tokens``.

    Each masked position independently (Bernoulli, as the reference's
    ``get_mask_subset_prob``): with probability ``random_prob`` it gets a code drawn uniformly
    from ``0..K-1`` (which may equal the true code); otherwise with probability ``mask_prob`` it
    becomes [MASK]; otherwise it keeps its true code. Reference values 0.1 / 0.88 give 10%
    random, 79.2% [MASK], 10.8% unchanged; MoMask's 80/10/10 is ``mask_prob = 8 / 9``.
    Unmasked positions (padding included) are returned unchanged.
    """
    for name, prob in (("random_prob", random_prob), ("mask_prob", mask_prob)):
        if not 0.0 <= prob <= 1.0:
            raise ValueError(f"{name} must lie in [0, 1], got {prob}")
    if mask.shape != tokens.shape:
        raise ValueError(f"mask {tuple(mask.shape)} must match tokens {tuple(tokens.shape)}")
    shape = tuple(tokens.shape)
    is_random = mask & (_rand(shape, tokens, generator) < random_prob)
    is_mask = mask & ~is_random & (_rand(shape, tokens, generator) < mask_prob)
    codes = torch.randint(
        0, vocabulary.codebook_size, shape, generator=generator, device=tokens.device
    )
    corrupted = torch.where(is_random, codes, tokens)
    corrupted = corrupted.masked_fill(is_mask, vocabulary.mask_id)
    return Corruption(corrupted, is_random, is_mask)


def step_unroll_mask(
    logits: torch.Tensor,
    tokens: torch.Tensor,
    mask: torch.Tensor,
    tau: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    vocabulary: Vocabulary,
    *,
    tau_step: float = STEP_UNROLL_TAU_STEP,
) -> StepUnroll:
    """Stage 2, step-unroll masking: keep the confident stage-1 predictions, re-mask the rest.

    Args:
        logits: (B, 2, rows, T', K) stage-1 logits (detached here).
        tokens: (B, 2, rows, T') stage-1 input (after :func:`bert_corruption`).
        mask: (B, 2, rows, T') bool stage-1 loss positions.
        tau: (B,) stage-1 progress (:class:`TrainingMask` ``tau``).

    Rule (paper: "we re-mask a portion (gamma(tau_{i+1})) of the predicted tokens with the
    lowest confidence scores and predict them again"; details from the reference):
    ``tau_next = min(tau + tau_step, 1)``; the candidates are the stage-1 [MASK] inputs
    (positions given a random or their true code stay as they were); confidence is the top
    softmax probability; the ``ceil(gamma(tau_next) * n)`` (at least one, ``n`` = valid tokens
    of both persons) least confident candidates stay [MASK], the other candidates take their
    argmax prediction. The second pass is scored on ``mask`` minus the filled-in predictions.

    Deviations from the reference, which derives tau from the share of [MASK] inputs over the
    padded length and rounds the count over the padded length: we advance the sampled tau and
    count over valid tokens, matching :func:`random_masking` and inference.
    """
    if logits.shape[:-1] != tokens.shape or mask.shape != tokens.shape:
        raise ValueError(
            f"logits (B, 2, rows, T', K), tokens and mask (B, 2, rows, T') must agree, got "
            f"{tuple(logits.shape)}, {tuple(tokens.shape)}, {tuple(mask.shape)}"
        )
    valid = ~step_padding_mask(lengths_in_steps, tokens.shape[-1])[:, None, None, :]
    candidates = mask & (tokens == vocabulary.mask_id) & valid
    confidence, prediction = logits.detach().float().softmax(dim=-1).max(dim=-1)
    tau_next = (tau.double() + tau_step).clamp(max=1.0)
    n_valid = valid.expand_as(tokens).flatten(1).sum(1)
    count = scheduled_count(cosine_schedule(tau_next).to(tokens.device), n_valid, minimum=1)
    scores = confidence.masked_fill(~candidates, math.inf)
    remasked = lowest_ranks(scores, count) & candidates
    retained = candidates & ~remasked
    return StepUnroll(
        tokens=torch.where(retained, prediction, tokens),
        mask=mask & ~retained,
        remasked=remasked,
        tau=tau_next,
    )
