"""Iterative masked decoding of the Inter-M Transformer (InterMask section 3.3, appendix G).

Token maps are ``(B, 2, rows, T')`` (person A, person B); ``-1`` marks padding. Decoding starts
with every generated position set to [MASK] and runs ``I`` iterations; each iteration makes one
forward pass (conditional and null condition stacked into one batch for classifier-free
guidance), samples every still-masked position, and re-masks the
``ceil(gamma((i + 1) / I) * n)`` least confident of them (``n`` generated tokens of the
sample). A token that survives a re-masking is never masked again; after the last iteration
``gamma(1) = 0`` and nothing is masked.

``schedule="reference"`` is the reference code's (MoMask's) reading instead: before iteration
``k`` it masks ``max(1, round(gamma(k / (I - 1)) * n))`` tokens, so the last iteration re-predicts
the single least confident token (docs/fidelity.md).

``persons="in_turn"`` (this framework's switch, off by default) decodes a collaborative model's
persons one after the other: person A's ``I`` iterations with person B all [MASK], then B's
``I`` iterations conditioned on A's finished tokens, as in reaction generation. The model is
permutation-equivariant, so from an all-[MASK] start both persons get the same prediction; when
the two roles of an interaction differ, tokens committed in the same iteration can take one
role in one person and the other role in the other, or the same role in both (both persons at the
actor's place). Decoding A first commits one role before B is drawn (docs/decisions.md:
sampler.persons).

Interaction generation generates everything; reaction generation fixes person A's tokens
(appendix G, "the reference tokens remain unmasked throughout"); inpainting (MoMask) fixes every
token outside a region.

A model with ``modeling="alternative"`` (appendix E, figure 8b) decodes one person per forward
pass: in each of the ``I`` rounds person A's masked tokens are predicted and re-masked by
confidence, then person B's, conditioned on A's current tokens; each person follows its own
schedule ``ceil(gamma((i + 1) / I) * n_p)``. ``I`` is then I_alter, the iterations *per person*
(at most 2I forward passes; a person with nothing left to generate, e.g. the reference person of
a reaction, is skipped).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import torch

from intermask.interm.masking import cosine_schedule, lowest_ranks, scheduled_count
from intermask.interm.model import InterMOutput, InterMTransformer, TextFeatures
from intermask.interm.tokens import step_padding_mask

SCHEDULES = ("paper", "reference")  # re-masking counts: eq. 3 (ceil) or MoMask's code
NOISES = ("per_sample", "reference")  # each sample its own generator, or the reference's draws
PERSON_ORDERS = ("together", "in_turn")  # both persons each pass (section 3.3), or A then B


class SettingsError(ValueError):
    """A decoding setting out of its range, or two that do not go together. ``rule`` names the
    check, so that a caller that spells the settings otherwise (``intermask generate``'s
    options) can say the same in its own words."""

    def __init__(self, rule: str, message: str) -> None:
        super().__init__(message)
        self.rule = rule


@dataclass(frozen=True)
class Decoding:
    """Inter-M's decoding settings: one field per key of ``configs/sampler/paper.yaml``, whose
    values are these defaults, the paper's inference settings (section 3.3, appendix C.1;
    tests/test_sampler_settings.py keeps the two equal). ``intermask generate``, the evaluation
    and the training module's samples build one and pass it whole to the sampler and
    :func:`generate`. Construction checks each range and the rules between the settings;
    :meth:`check_for` the rules that also depend on the model and the request.

    Attributes:
        iterations: I, one forward pass each; for an alternative-modeling model I_alter, the
            rounds per person (A then B in each round, one pass per person).
        cfg_scale: s in ``uncond + s * (cond - uncond)`` on logits.
        top_k_ratio: sampling keeps the ``ceil(ratio * K)`` largest logits (the reference's
            ``topk_filter_thres=0.9`` keeps 10%).
        temperature: logits are divided by it before sampling (the reference divides the
            probabilities, which ``Categorical`` renormalises away); 0 is greedy decoding.
        schedule: how many tokens each iteration re-masks: "paper" (the module docstring) or
            "reference" (the reference code's counts).
        noise: "per_sample" (each sample's draws from its own seed: results independent of the
            batch) or "reference": one generator seeded with ``seeds[0]`` draws every position of
            the batch in the reference's order (``torch.multinomial``), so that with the
            reference schedule and the same seed the reference's tokens come out; a sample then
            depends on its batch.
        persons: "together" (the paper: both persons in every pass) or "in_turn": ``iterations``
            passes for person A with B all [MASK], then ``iterations`` for B given A (2I passes;
            the module docstring says why). An alternative-modeling model always decodes in turn.
        revisits: with ``persons="in_turn"``, this many more turns after B's: person A's
            generated tokens are all [MASK]ed and decoded again given B's finished tokens, then
            B's given the new A, alternating (``iterations`` passes each). The first turn of A
            saw no B; a revisit sees it (docs/decisions.md: sampler.revisits). 0 is plain in-turn
            decoding.
        partner_scale: g of partner guidance (:func:`partner_guided_logits`), for passes that
            decode one person beside the other's fixed tokens: in-turn decoding's turns after
            the first (B's turn and every revisit; the first too where an edit fixes some of
            B's tokens), and reaction generation (B beside the fixed A). Each such pass runs
            one more copy of the batch. 0 (the paper) is plain guidance.
        remask_noise: t >= 0; with t > 0 each iteration ranks the sampled codes for re-masking
            by their log confidence plus Gumbel noise of scale ``t (1 - (i + 1) / I)`` drawn from
            the sample's own seed (MaskGIT's randomised re-masking); 0 (the paper) ranks by the
            confidence alone. Needs ``noise="per_sample"``.
    """

    iterations: int = 20  # I, interactions (section 3.3); reactions: 12 (configs: reaction)
    cfg_scale: float = 2.0  # s (appendix C.1)
    top_k_ratio: float = 0.1
    temperature: float = 1.0
    schedule: str = "paper"
    noise: str = "per_sample"
    persons: str = "together"
    revisits: int = 0
    partner_scale: float = 0.0
    remask_noise: float = 0.0

    def __post_init__(self) -> None:
        if self.iterations < 1:
            raise SettingsError(
                "iterations", f"iterations must be at least 1, got {self.iterations}"
            )
        if self.temperature < 0:
            raise SettingsError("temperature", f"temperature must be >= 0, got {self.temperature}")
        if not self.remask_noise >= 0:  # NaN too
            raise SettingsError(
                "remask_noise_range", f"remask_noise must be >= 0, got {self.remask_noise}"
            )
        if self.remask_noise and self.noise != "per_sample":
            raise SettingsError(
                "remask_noise",
                f"remask_noise ({self.remask_noise}) draws each sample's noise from its own "
                f"seed; it needs noise='per_sample', got {self.noise!r}",
            )
        for name, choices in (
            ("schedule", SCHEDULES),
            ("noise", NOISES),
            ("persons", PERSON_ORDERS),
        ):
            if getattr(self, name) not in choices:
                raise SettingsError(
                    name, f"{name} must be one of {choices}, got {getattr(self, name)!r}"
                )
        if self.revisits < 0 or (self.revisits > 0 and self.persons != "in_turn"):
            raise SettingsError(
                "revisits_range" if self.revisits < 0 else "revisits",
                f"revisits must be >= 0 and needs persons='in_turn', got {self.revisits} with "
                f"{self.persons!r}",
            )

    def check_for(self, *, modeling: str | None, reaction: bool) -> None:
        """The rules that also depend on the model (``modeling``: "collaborative" or
        "alternative"; None while it is not known) and on the request (``reaction``: person A
        is fixed)."""
        alternately = "decodes the persons alternately (modeling='alternative')"
        if self.revisits and modeling == "alternative":  # its rounds interleave the persons
            raise SettingsError(
                "revisits_alternative",
                f"revisits ({self.revisits}) re-decode a collaborative model's turns; this model "
                f"{alternately}: use revisits=0",
            )
        if self.partner_scale and modeling == "alternative":
            raise SettingsError(
                "partner_scale_alternative",
                f"partner_scale ({self.partner_scale}) guides a collaborative model's passes; "
                f"this model {alternately}: use partner_scale=0",
            )
        if self.partner_scale and self.persons != "in_turn" and not reaction:
            raise SettingsError(
                "partner_scale",
                f"partner_scale ({self.partner_scale}) needs one person decoded beside the "
                "other's fixed tokens: persons='in_turn' or reference_tokens, got "
                f"persons={self.persons!r}",
            )


# a drop-in for InterMTransformer.forward_with_condition(tokens_a, tokens_b, condition, lengths)
Forward = Callable[[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor], InterMOutput]


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


def _text_guided(condition: torch.Tensor | None, cfg_scale: float) -> bool:
    """Whether guidance needs the null condition's pass: a condition and a scale other than 1."""
    return condition is not None and cfg_scale != 1.0


def _guided(
    run: Callable[..., torch.Tensor],
    token_maps: tuple[torch.Tensor, ...],
    condition: torch.Tensor | None,
    null: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    cfg_scale: float,
) -> torch.Tensor:
    """``run(*token_maps, condition, lengths)`` with guidance: conditional and null condition
    stacked into one doubled batch, combined as ``uncond + s * (cond - uncond)``."""
    if not _text_guided(condition, cfg_scale):
        return run(*token_maps, null if condition is None else condition, lengths_in_steps)
    doubled = [torch.cat([t, t]) for t in token_maps]
    out = run(
        *doubled, torch.cat([condition, null]), torch.cat([lengths_in_steps, lengths_in_steps])
    )
    cond, uncond = out.chunk(2)
    return uncond + cfg_scale * (cond - uncond)


def _both_persons(out: InterMOutput) -> torch.Tensor:
    """(B, 2, rows, T', K) logits of both persons in fp32: guidance, top-k and sampling read
    fp32 under bf16 autocast too (a no-op in fp32)."""
    return torch.stack([out.logits_a, out.logits_b], dim=1).float()


def guided_logits(
    model: InterMTransformer,
    tokens: torch.Tensor,
    condition: torch.Tensor | None,
    null: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    cfg_scale: float,
    *,
    forward: Forward | None = None,
) -> torch.Tensor:
    """One forward pass -> (B, 2, rows, T', K) logits ``uncond + s * (cond - uncond)``.

    Without a condition, or with ``s = 1``, the batch is not doubled: the null or the
    conditional logits are returned as they are. ``forward`` replaces
    ``model.forward_with_condition`` (e.g. :class:`~intermask.interm.graphs.GraphedForward`).
    """
    forward = forward or model.forward_with_condition

    def run(a, b, c, lengths):
        return _both_persons(forward(a, b, c, lengths))

    return _guided(run, (tokens[:, 0], tokens[:, 1]), condition, null, lengths_in_steps, cfg_scale)


def guided_person_logits(
    model: InterMTransformer,
    tokens: torch.Tensor,
    person: int,
    condition: torch.Tensor | None,
    null: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    cfg_scale: float,
) -> torch.Tensor:
    """Alternative modeling: (B, 2, rows, T') tokens -> (B, rows, T', K) guided logits of
    ``person`` (0 = A, 1 = B), conditioned on the other person's tokens; one forward pass."""
    return _guided(
        model.forward_person,
        (tokens[:, person], tokens[:, 1 - person]),
        condition,
        null,
        lengths_in_steps,
        cfg_scale,
    )


def partner_guided_logits(
    model: InterMTransformer,
    tokens: torch.Tensor,
    partner: torch.Tensor,
    condition: torch.Tensor | None,
    null: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    cfg_scale: float,
    partner_scale: float,
    *,
    forward: Forward | None = None,
) -> torch.Tensor:
    """:func:`guided_logits` plus partner guidance, in one forward pass of a tripled batch
    (doubled without text guidance):
    ``uncond + s * (cond - uncond) + g * (cond - cond_hidden)``, where ``cond_hidden`` is the
    conditional prediction with the ``partner`` (B, 2, rows, T') positions set to [MASK].

    The model knows both predictions: interaction masking trains a person beside its visible
    partner, solo masking beside a wholly masked one. Their difference is what the partner adds,
    and ``g > 0`` follows it further, as text guidance follows the text (docs/decisions.md:
    sampler.partner_scale). Without a condition, ``cond`` is the null prediction. ``forward`` as in
    :func:`guided_logits`.
    """
    forward = forward or model.forward_with_condition
    conditional = null if condition is None else condition
    text_guided = _text_guided(condition, cfg_scale)
    hidden = tokens.masked_fill(partner, model.vocabulary.mask_id)
    maps = torch.cat([tokens, hidden, tokens] if text_guided else [tokens, hidden])
    conditions = [conditional, conditional, null] if text_guided else [conditional, conditional]
    out = forward(
        maps[:, 0],
        maps[:, 1],
        torch.cat(conditions),
        lengths_in_steps.repeat(len(conditions)),
    )
    logits = _both_persons(out).chunk(len(conditions))
    cond, cond_hidden = logits[0], logits[1]
    guided = logits[2] + cfg_scale * (cond - logits[2]) if text_guided else cond
    return guided + partner_scale * (cond - cond_hidden)


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
    active: torch.Tensor | None = None,
) -> torch.Tensor:
    """(B, ..., T', K) filtered logits -> (B, ..., T') codes, by the Gumbel-max trick on
    ``logits / temperature`` (an exact sample of ``softmax(logits / temperature)``).

    Each sample's noise comes from its own generator and has its own clip length, so its codes
    do not depend on the rest of the batch or on T'; this per-sample draw is the only Python
    loop of the decoding. Samples where ``active`` (B,) is False draw nothing (their generator
    is not advanced) and get the argmax. ``temperature = 0`` is greedy (argmax) decoding.
    """
    if temperature == 0:
        return logits.argmax(dim=-1)
    gumbel = _gumbel(logits, lengths_in_steps, generators, active, time_dim=-2)
    return (logits / temperature + gumbel).argmax(dim=-1)


def _gumbel(
    like: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    generators: Sequence[torch.Generator],
    active: torch.Tensor | None,
    *,
    time_dim: int,
) -> torch.Tensor:
    """Standard Gumbel noise shaped like ``like`` (B, ...): sample b's from its own generator,
    over its first ``lengths_in_steps[b]`` steps of ``time_dim`` (a negative dimension) only;
    the rest, and samples where ``active`` is False (no draw), get the constant
    ``-log(-log(0.5))``."""
    uniform = torch.full_like(like, 0.5)
    lengths = lengths_in_steps.tolist()  # one read-back for the batch, not one per sample
    drawing = [True] * len(generators) if active is None else active.tolist()
    for b, generator in enumerate(generators):
        if drawing[b]:
            view = uniform[b].narrow(time_dim, 0, lengths[b])
            view.copy_(torch.rand(view.shape, generator=generator, device=like.device))
    return -torch.log(-torch.log(uniform.clamp(1e-20, 1 - 1e-7)))


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


def _partner(tokens: torch.Tensor, person: int, model: InterMTransformer) -> torch.Tensor:
    """(B, 2, rows, T') bool: ``person``'s codes (neither [MASK] nor padding, -1)."""
    codes = (tokens >= 0) & (tokens != model.vocabulary.mask_id)
    partner = torch.zeros_like(codes)
    partner[:, person] = codes[:, person]
    return partner


class _Call(NamedTuple):
    """What every pass of one :func:`generate` call reads."""

    settings: Decoding
    condition: torch.Tensor | None  # (B, D), None = null condition only
    null: torch.Tensor  # (B, D)
    lengths_in_steps: torch.Tensor  # (B,)
    generators: list[torch.Generator]
    forward: Forward | None = None  # None: model.forward_with_condition


def _sample(
    logits: torch.Tensor, call: _Call, active: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, ..., T', K) guided logits -> sampled codes and the probability of each under the
    guided logits before top-k and temperature (as in the reference), both (B, ..., T')."""
    settings = call.settings
    filtered = top_k_filter(logits, settings.top_k_ratio)
    if settings.noise == "reference" and settings.temperature > 0:
        sampled = reference_draw(filtered, call.generators[0], settings.temperature)
        confidence = logits.float().softmax(-1).gather(-1, sampled[..., None])[..., 0]
        return sampled, confidence
    sampled = sample_codes(
        filtered, call.lengths_in_steps, call.generators, settings.temperature, active
    )
    confidence = logits.float().log_softmax(-1).gather(-1, sampled[..., None])[..., 0].exp()
    return sampled, confidence


def _remask_scores(
    confidence: torch.Tensor,
    call: _Call,
    iteration: int,
    iterations: int,
    active: torch.Tensor | None = None,
) -> torch.Tensor:
    """The scores :func:`remask` ranks after iteration ``iteration`` (0-based): the confidence
    itself, or with ``remask_noise`` t > 0 its log plus Gumbel noise of scale
    ``t (1 - (i + 1) / I)`` from each sample's own generator (MaskGIT's randomised re-masking:
    early iterations keep some codes other than the most confident ones; docs/decisions.md:
    sampler.remask_noise)."""
    scale = call.settings.remask_noise * (1 - (iteration + 1) / iterations)
    if scale == 0:
        return confidence
    noise = _gumbel(confidence, call.lengths_in_steps, call.generators, active, time_dim=-1)
    return confidence.log() + scale * noise


def reference_draw(
    filtered: torch.Tensor, generator: torch.Generator, temperature: float
) -> torch.Tensor:
    """The reference's draw: ``Categorical(softmax(filtered) / temperature).sample()`` over every
    position of the batch, in order, from one generator (the temperature is normalised away)."""
    probs = filtered.float().softmax(-1) / temperature
    probs = probs / probs.sum(-1, keepdim=True)
    flat = probs.reshape(-1, probs.shape[-1])
    return torch.multinomial(flat, 1, True, generator=generator).reshape(probs.shape[:-1])


def remask(
    confidence: torch.Tensor,
    undecided: torch.Tensor,
    n_generated: torch.Tensor,
    iteration: int,
    iterations: int,
    schedule: str,
) -> torch.Tensor:
    """After iteration ``iteration`` (0-based) of ``iterations``: the least confident of the
    ``undecided`` (B, ...) positions just sampled stay undecided, ``ceil(gamma((i + 1) / I) n)``
    of them (paper) or ``max(1, round(gamma((i + 1) / (I - 1)) n))`` (reference; none after the
    last iteration). A kept token never returns."""
    if schedule == "reference":
        if iteration == iterations - 1:
            return torch.zeros_like(undecided)
        # in float32 from torch.linspace, as the reference computes it: there gamma(2/3) is
        # 0.49999997, so an odd count (a reaction's, one person) rounds down where float64 rounds up
        tau = torch.linspace(0, 1, iterations)[iteration + 1]
        ratio = torch.cos(tau * math.pi * 0.5)
        count = torch.round(ratio * n_generated.to(ratio.device)).clamp(min=1)
        # ranked as the reference ranks: torch's default (unstable) sort over every position,
        # the ones that cannot be re-masked at 1e5. Its ties fall in another order than a stable
        # sort's, and ties are common: while both persons are all [MASK] their positions share
        # their logits, so a code sampled at both has the same confidence twice.
        flat = confidence.masked_fill(~undecided, 1e5).flatten(1)
        ranks = flat.argsort(dim=1).argsort(dim=1).reshape(undecided.shape)
        return (ranks < count.to(ranks.device).view(-1, *[1] * (ranks.ndim - 1))) & undecided
    else:
        count = scheduled_count(cosine_schedule((iteration + 1) / iterations), n_generated)
    scores = confidence.masked_fill(~undecided, math.inf)
    return lowest_ranks(scores, count) & undecided


def _collaborative_logits(
    model: InterMTransformer, tokens: torch.Tensor, partner: torch.Tensor | None, call: _Call
) -> torch.Tensor:
    """One guided pass over both persons; with ``partner`` (B, 2, rows, T') codes, partner
    guidance hides them in one more copy of the batch."""
    settings = call.settings
    if partner is not None:
        return partner_guided_logits(
            model,
            tokens,
            partner,
            call.condition,
            call.null,
            call.lengths_in_steps,
            settings.cfg_scale,
            settings.partner_scale,
            forward=call.forward,
        )
    return guided_logits(
        model,
        tokens,
        call.condition,
        call.null,
        call.lengths_in_steps,
        settings.cfg_scale,
        forward=call.forward,
    )


def _decode_collaborative(
    model: InterMTransformer,
    tokens: torch.Tensor,
    undecided: torch.Tensor,
    call: _Call,
    partner_person: int | None = None,
) -> torch.Tensor:
    """Both persons in every pass (section 3.3): (B, 2, rows, T') -> (B, 2, rows, T').

    ``partner_person``: the person whose fixed codes the partner-guidance pass hides
    (:func:`partner_guided_logits`), when ``partner_scale`` is not 0; None: no such pass.
    """
    iterations, schedule = call.settings.iterations, call.settings.schedule
    n_generated = undecided.flatten(1).sum(1)  # (B,)
    partner = None
    if partner_person is not None and call.settings.partner_scale != 0:
        partner = _partner(tokens, partner_person, model)
        partner = partner if bool(partner.any()) else None
    for i in range(iterations):
        logits = _collaborative_logits(model, tokens, partner, call)
        sampled, confidence = _sample(logits, call)
        tokens = torch.where(undecided, sampled, tokens)
        scores = _remask_scores(confidence, call, i, iterations)
        undecided = remask(scores, undecided, n_generated, i, iterations, schedule)
        tokens = tokens.masked_fill(undecided, model.vocabulary.mask_id)
    return tokens


def _decode_in_turn(
    model: InterMTransformer, tokens: torch.Tensor, undecided: torch.Tensor, call: _Call
) -> torch.Tensor:
    """Person A, then B given A, then ``revisits`` more turns, each a collaborative decoding of
    one person beside the other: (B, 2, rows, T') -> same. B's undecided tokens stay [MASK]
    while A is decoded; a revisit masks one person's generated tokens again and decodes them
    given the other's."""
    for turn in range(2 + call.settings.revisits):
        own = undecided.clone()
        own[:, 1 - turn % 2] = False
        if bool(own.any()):
            tokens = tokens.masked_fill(own, model.vocabulary.mask_id)
            tokens = _decode_collaborative(model, tokens, own, call, partner_person=1 - turn % 2)
    return tokens


def _decode_alternative(
    model: InterMTransformer,
    tokens: torch.Tensor,
    undecided: torch.Tensor,
    call: _Call,
) -> torch.Tensor:
    """One person per pass, A then B in each round (appendix E): (B, 2, rows, T') -> same."""
    iterations, schedule = call.settings.iterations, call.settings.schedule
    n_generated = undecided.flatten(2).sum(2)  # (B, 2)
    persons = [tokens[:, 0], tokens[:, 1]]
    pending = [undecided[:, 0], undecided[:, 1]]
    for i in range(iterations):
        for person in (0, 1):
            todo = pending[person]  # (B, rows, T')
            if not bool(todo.any()):
                continue  # nothing of this person left anywhere in the batch: skip the pass
            logits = guided_person_logits(
                model,
                torch.stack(persons, dim=1),
                person,
                call.condition,
                call.null,
                call.lengths_in_steps,
                call.settings.cfg_scale,
            )
            # a sample with nothing of this person left draws no noise, so that its result does
            # not depend on whether other samples of the batch forced this pass
            active = todo.flatten(1).any(1)
            sampled, confidence = _sample(logits, call, active=active)
            own = torch.where(todo, sampled, persons[person])
            scores = _remask_scores(confidence, call, i, iterations, active)
            pending[person] = remask(scores, todo, n_generated[:, person], i, iterations, schedule)
            persons[person] = own.masked_fill(pending[person], model.vocabulary.mask_id)
    return torch.stack(persons, dim=1)


def _decode(
    model: InterMTransformer,
    tokens: torch.Tensor,
    undecided: torch.Tensor,
    call: _Call,
    reaction: bool,
) -> torch.Tensor:
    """The decoding the model and settings ask for: alternate persons (alternative modeling),
    in turn, or both persons together (``reaction``: B beside the fixed A)."""
    if model.modeling == "alternative":
        return _decode_alternative(model, tokens, undecided, call)
    if call.settings.persons == "in_turn":
        return _decode_in_turn(model, tokens, undecided, call)
    return _decode_collaborative(model, tokens, undecided, call, 0 if reaction else None)


@torch.no_grad()
def generate(
    model: InterMTransformer,
    text: TextFeatures | tuple | None,
    lengths_in_steps: torch.Tensor,
    *,
    settings: Decoding | None = None,
    steps: int | None = None,
    seeds: torch.Tensor | Sequence[int] | None = None,
    reference_tokens: torch.Tensor | None = None,
    edit: Edit | None = None,
    forward: Forward | None = None,
    **changes: Any,
) -> torch.Tensor:
    """Text (and optionally fixed tokens) -> (B, 2, rows, T') generated codes, -1 on padding.

    Args:
        text: :class:`TextFeatures` or ``(features, eot_index)`` of B texts; None generates
            from the null condition only (no guidance), e.g. reaction without text.
        lengths_in_steps: (B,) clip lengths in token steps; ``steps`` (T') defaults to the
            longest (or the width of the given tokens).
        settings: the :class:`Decoding` settings (None: the paper's); ``changes`` replace
            single ones (``iterations=6``), checked as the whole is.
        seeds: (B,) one seed per sample; a sample's result depends only on its own seed,
            text, length and fixed tokens, not on the other samples of the batch (unless
            ``noise="reference"``).
        reference_tokens: (B, rows, T') person A's codes for reaction generation; A stays
            fixed and only person B is generated (alternative modeling: B's passes only).
        edit: :class:`Edit` for inpainting: only ``edit.region`` changes.
        forward: what runs the collaborative passes in place of ``model.forward_with_condition``
            (same arguments and result), e.g. a :class:`~intermask.interm.graphs.GraphedForward`
            that keeps its CUDA graphs from one call to the next. Alternative modeling's passes
            stay eager.

    The confidence of a sampled code is its probability under the guided logits before top-k
    and temperature (as in the reference).
    """
    settings = replace(settings or Decoding(), **changes)
    reaction = reference_tokens is not None
    settings.check_for(modeling=model.modeling, reaction=reaction)
    for given in (reference_tokens, None if edit is None else edit.tokens):
        if given is not None and steps is None:
            steps = given.shape[-1]
    batch, device = lengths_in_steps.shape[0], lengths_in_steps.device
    steps = int(lengths_in_steps.max()) if steps is None else steps
    valid = ~step_padding_mask(lengths_in_steps, steps)[:, None, None, :]  # (B, 1, 1, T')
    valid = valid.expand(batch, 2, model.rows, steps)
    tokens, undecided = _start(model, valid, reference_tokens, edit)
    drawn = settings.temperature > 0 or settings.remask_noise > 0
    generators = _generators(seeds, batch, device) if drawn else []

    was_training = model.training
    model.eval()
    try:
        condition = None if text is None else model.encode_condition(text)
        null = null_condition(model, batch, device)
        call = _Call(settings, condition, null, lengths_in_steps, generators, forward)
        tokens = _decode(model, tokens, undecided, call, reaction)
    finally:
        model.train(was_training)
    return tokens.masked_fill(~valid, -1)
