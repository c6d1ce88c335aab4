"""MoMask training draws: scheduled base masks, 80/10/10 corruption, residual layers, drops."""

from __future__ import annotations

import math

import pytest
import torch

from intermask.momask.masking import (
    BERT_MASK_PROB,
    BERT_RANDOM_PROB,
    base_corruption,
    base_mask,
    condition_drops,
    draw_layers,
    valid_steps,
)


def _codes(lengths: list[int], steps: int, codes: int = 512, seed: int = 0) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    tokens = torch.randint(0, codes, (len(lengths), steps), generator=generator)
    for row, length in enumerate(lengths):
        tokens[row, length:] = -1
    return tokens


@pytest.mark.parametrize("tau", [0.0, 0.2, 0.5, 0.9, 1.0])
def test_base_mask_hides_the_scheduled_count_of_valid_steps(tau):
    lengths = [49, 30, 7, 1]
    tokens = _codes(lengths, 49)
    taus = torch.full((4,), tau, dtype=torch.float64)
    mask, returned = base_mask(tokens, torch.tensor(lengths), tau=taus)
    assert torch.equal(returned, taus)
    for row, length in enumerate(lengths):
        expected = max(1, math.ceil(math.cos(math.pi * tau / 2) * length - 1e-9))
        assert int(mask[row].sum()) == expected
        assert not mask[row, length:].any()  # padding is never masked


def test_tau_zero_masks_everything_and_tau_one_a_single_step():
    lengths = torch.tensor([12, 5])
    tokens = _codes([12, 5], 12)
    mask, _ = base_mask(tokens, lengths, tau=torch.zeros(2, dtype=torch.float64))
    assert torch.equal(mask, valid_steps(tokens, lengths))
    mask, _ = base_mask(tokens, lengths, tau=torch.ones(2, dtype=torch.float64))
    assert mask.sum(1).tolist() == [1, 1]


def test_drawn_ratios_follow_the_cosine_schedule():
    # E[cos(pi tau / 2)] over tau ~ U(0, 1) is 2 / pi
    tokens = _codes([40] * 4000, 40)
    mask, tau = base_mask(
        tokens, torch.full((4000,), 40), generator=torch.Generator().manual_seed(1)
    )
    assert 0.0 <= float(tau.min()) and float(tau.max()) < 1.0
    ratio = mask.float().mean()
    assert abs(float(ratio) - 2 / math.pi) < 0.02


def test_bert_corruption_is_80_10_10_on_a_large_draw():
    codes = 512
    lengths = [64, 40] * 1000
    tokens = _codes(lengths, 64, codes)
    out = base_corruption(
        tokens, torch.tensor(lengths), codes, generator=torch.Generator().manual_seed(2)
    )
    masked = out.mask
    n = int(masked.sum())
    assert n > 40_000
    to_mask = (out.tokens[masked] == codes).float().mean()  # [MASK] = K
    kept = (out.tokens[masked] == tokens[masked]).float().mean()
    replaced = 1 - to_mask - kept  # a random code different from the true one
    # a random code equals the true one with probability 1 / K
    assert abs(float(to_mask) - 0.8) < 0.006
    assert abs(float(kept) - (0.1 + 0.1 / codes)) < 0.006
    assert abs(float(replaced) - 0.1 * (1 - 1 / codes)) < 0.006
    assert BERT_RANDOM_PROB == 0.1 and BERT_MASK_PROB * 0.9 == pytest.approx(0.8)
    assert torch.equal(out.tokens[~masked], tokens[~masked])  # padding (-1) included
    assert int(out.tokens.max()) <= codes and int(out.tokens[tokens < 0].max()) == -1


def test_corruption_is_reproducible_with_a_seeded_generator():
    tokens = _codes([20, 9], 20)
    draws = [
        base_corruption(
            tokens, torch.tensor([20, 9]), 512, generator=torch.Generator().manual_seed(5)
        )
        for _ in range(2)
    ]
    assert torch.equal(draws[0].tokens, draws[1].tokens) and torch.equal(
        draws[0].mask, draws[1].mask
    )


def test_uniform_layer_draw_covers_the_residual_layers_evenly():
    layers = draw_layers(60_000, 6, generator=torch.Generator().manual_seed(3))
    counts = torch.bincount(layers, minlength=6)
    assert counts[0] == 0 and int(layers.max()) == 5
    assert torch.allclose(counts[1:].float() / 60_000, torch.full((5,), 0.2), atol=0.01)


def test_reference_layer_draw_is_its_cosine_skew():
    generator = torch.Generator().manual_seed(4)
    layers = draw_layers(1000, 6, draw="reference", generator=generator)
    u = torch.rand(1000, generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    expected = torch.round((1 - torch.cos(math.pi * u / 2)) * 4).long() + 1
    assert torch.equal(layers, expected)
    counts = torch.bincount(layers, minlength=6)
    assert counts[1] > counts[5] and int(layers.min()) >= 1 and int(layers.max()) <= 5


def test_condition_drops_have_the_given_rate():
    drops = condition_drops(50_000, 0.1, generator=torch.Generator().manual_seed(6))
    assert drops.dtype == torch.bool and abs(float(drops.float().mean()) - 0.1) < 0.005
    assert not condition_drops(10, 0.0).any() and condition_drops(10, 1.0).all()


def test_errors_name_the_problem():
    with pytest.raises(ValueError, match=r"num_quantizers must be >= 2 .* got 1"):
        draw_layers(4, 1)
    with pytest.raises(ValueError, match="draw must be one of"):
        draw_layers(4, 6, draw="cosine")
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\], got 1.5"):
        condition_drops(4, 1.5)
    with pytest.raises(ValueError, match=r"tokens must be \(B, T'\), got \(2, 1, 8\)"):
        valid_steps(torch.zeros(2, 1, 8, dtype=torch.long), torch.tensor([8, 8]))
    with pytest.raises(ValueError, match=r"lengths_in_steps must lie in \[0, 8\]"):
        base_mask(torch.zeros(2, 8, dtype=torch.long), torch.tensor([8, 9]))
    with pytest.raises(ValueError, match=r"mask_prob must lie in \[0, 1\]"):
        base_corruption(torch.zeros(1, 4, dtype=torch.long), torch.tensor([4]), 8, mask_prob=2.0)
