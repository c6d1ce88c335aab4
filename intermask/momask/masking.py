"""Training-time draws of MoMask's transformers (sections 3.2-3.4).

Base layer (masked transformer): per sample ``tau ~ U(0, 1)`` and ``ceil(gamma(tau) * n)``
(at least one) of its ``n`` valid steps masked, uniformly, with the cosine schedule
``gamma(tau) = cos(pi * tau / 2)``; the masked steps are then corrupted BERT-style: 80%
[MASK], 10% a random code, 10% unchanged ("replacing and remasking"). The schedule, the
scheduled choice and the corruption are Inter-M's (:mod:`intermask.interm.masking`), applied to
``(B, T')`` token maps. The reference code instead rounds the ratio times the padded length and
then drops the padded positions, so short clips get fewer masked tokens than scheduled; its
corruption gives 10% random, 79.2% [MASK], 10.8% unchanged (``mask_prob = 0.88``).

Residual layers: one layer per sample in ``1..Q-1``, uniformly (the paper: "randomly select");
``layer_draw="reference"`` is the reference code's skew towards low layers,
``round((1 - cos(pi u / 2)) * (Q - 2)) + 1``, ``u ~ U(0, 1)``.

Every draw takes an optional ``torch.Generator`` (None: torch's global one).
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from intermask.interm.masking import Corruption, bert_corruption, cosine_schedule, scheduled_mask
from intermask.interm.tokens import Vocabulary, step_padding_mask

BERT_RANDOM_PROB = 0.1  # "a random token 10% of the time" (section 3.2)
BERT_MASK_PROB = 8 / 9  # of the other 90%, [MASK] 80% of the time overall (section 3.2)
LAYER_DRAWS = ("uniform", "reference")


class BaseMasking(NamedTuple):
    tokens: torch.Tensor  # (B, T') model input: codes, [MASK], -1 on padding
    # (B, T') bool, the loss positions: every selected step, whatever its corruption (BERT's
    # and the reference's choice; eq. 3 writes the sum over the [MASK] inputs only)
    mask: torch.Tensor
    tau: torch.Tensor  # (B,) float64 schedule progress of each sample


def valid_steps(tokens: torch.Tensor, lengths_in_steps: torch.Tensor) -> torch.Tensor:
    """(B, T') tokens, (B,) lengths -> (B, T') bool, True inside the clip and not -1."""
    if tokens.ndim != 2:
        raise ValueError(f"tokens must be (B, T'), got {tuple(tokens.shape)}")
    inside = ~step_padding_mask(lengths_in_steps.to(tokens.device), tokens.shape[1])
    return inside & (tokens >= 0)


def base_mask(
    tokens: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    *,
    tau: torch.Tensor | None = None,
    generator: torch.Generator | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """(B, T') base-layer codes (-1 on padding) -> ((B, T') bool mask, (B,) float64 tau).

    ``ceil(gamma(tau) * n)`` (at least one) of each sample's ``n`` valid steps, chosen
    uniformly; ``tau`` (B,) is drawn from U(0, 1) unless given. Padding is never masked.
    """
    valid = valid_steps(tokens, lengths_in_steps)
    if tau is None:
        tau = torch.rand(tokens.shape[0], generator=generator, device=tokens.device).double()
    return scheduled_mask(valid, tau, generator), tau


def base_corruption(
    tokens: torch.Tensor,
    lengths_in_steps: torch.Tensor,
    codebook_size: int,
    *,
    random_prob: float = BERT_RANDOM_PROB,
    mask_prob: float = BERT_MASK_PROB,
    generator: torch.Generator | None = None,
) -> BaseMasking:
    """The masked transformer's training input: :func:`base_mask`, then each masked step
    independently gets a random code with probability ``random_prob``, else [MASK] with
    probability ``mask_prob``, else keeps its code (:func:`bert_corruption`)."""
    mask, tau = base_mask(tokens, lengths_in_steps, generator=generator)
    corrupted: Corruption = bert_corruption(
        tokens,
        mask,
        Vocabulary(codebook_size),
        generator=generator,
        random_prob=random_prob,
        mask_prob=mask_prob,
    )
    return BaseMasking(corrupted.tokens, mask, tau)


def draw_layers(
    batch: int,
    num_quantizers: int,
    *,
    draw: str = "uniform",
    generator: torch.Generator | None = None,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """(B,) int64 residual layer to learn per sample, in ``1..num_quantizers - 1``
    (``draw``: "uniform", the paper, or "reference", see the module docstring)."""
    if num_quantizers < 2:
        raise ValueError(
            f"num_quantizers must be >= 2 to draw a residual layer, got {num_quantizers}"
        )
    if draw not in LAYER_DRAWS:
        raise ValueError(f"draw must be one of {LAYER_DRAWS}, got {draw!r}")
    if draw == "uniform":
        return torch.randint(1, num_quantizers, (batch,), generator=generator, device=device)
    u = torch.rand(batch, generator=generator, device=device, dtype=torch.float64)
    skew = 1 - cosine_schedule(u).to(u.device)
    return torch.round(skew * (num_quantizers - 2)).long() + 1


def condition_drops(
    batch: int,
    probability: float,
    *,
    generator: torch.Generator | None = None,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """(B,) bool, True where the caption is replaced by the null condition (probability
    ``probability``, 0.1 in the paper, section 3.4)."""
    if not 0.0 <= probability <= 1.0:
        raise ValueError(f"the condition-drop probability must lie in [0, 1], got {probability}")
    return torch.rand(batch, generator=generator, device=device) < probability
