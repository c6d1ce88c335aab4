import math

import pytest
import torch

from intermask.interm.masking import (
    INTERACTION_TAU,
    bert_corruption,
    cosine_schedule,
    interaction_masking,
    inverse_cosine_schedule,
    partner_masking,
    random_masking,
    solo_masking,
    step_unroll_mask,
    training_mask,
    valid_tokens,
)
from intermask.interm.tokens import Vocabulary

K, ROWS, STEPS = 16, 5, 8
VOCAB = Vocabulary(K)


def _tokens(batch: int, lengths: torch.Tensor, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    a = torch.randint(0, K, (batch, ROWS, STEPS), generator=g)
    b = torch.randint(0, K, (batch, ROWS, STEPS), generator=g)
    pad = torch.arange(STEPS) >= lengths[:, None]
    return a.masked_fill(pad[:, None], -1), b.masked_fill(pad[:, None], -1)


def test_cosine_schedule_endpoints_and_inverse():
    assert cosine_schedule(0.0).item() == 1.0
    assert cosine_schedule(1.0).item() == 0.0  # exactly, not 6e-17
    assert cosine_schedule(0.5).item() == pytest.approx(math.cos(math.pi / 4))
    tau = torch.linspace(0, 1, 11, dtype=torch.float64)
    torch.testing.assert_close(inverse_cosine_schedule(cosine_schedule(tau)), tau)
    assert cosine_schedule(INTERACTION_TAU).item() == pytest.approx(0.5)


def test_random_masking_follows_the_schedule_with_given_tau():
    lengths = torch.tensor([8, 5, 1, 3])
    a, b = _tokens(4, lengths)
    tau = torch.tensor([0.0, 0.5, 0.9, 1.0], dtype=torch.float64)
    mask = random_masking(a, b, lengths, tau=tau, generator=torch.Generator().manual_seed(0))
    n_valid = 2 * ROWS * lengths
    expected = [
        max(1, math.ceil(math.cos(math.pi * t / 2) * n - 1e-9))
        for t, n in zip(tau.tolist(), n_valid.tolist(), strict=True)
    ]
    expected[3] = 1  # gamma(1) = 0: still at least one token
    assert mask.flatten(1).sum(1).tolist() == expected


def test_random_masking_ratio_averages_to_the_schedule_and_never_masks_pads():
    batch = 4000
    lengths = torch.randint(1, STEPS + 1, (batch,), generator=torch.Generator().manual_seed(3))
    a, b = _tokens(batch, lengths)
    mask = random_masking(a, b, lengths, generator=torch.Generator().manual_seed(1))
    valid = valid_tokens(torch.stack([a, b], 1), lengths)
    assert not (mask & ~valid).any()
    assert (mask.flatten(1).sum(1) >= 1).all()
    ratio = mask.flatten(1).sum(1).double() / valid.flatten(1).sum(1)
    # E[cos(pi tau / 2)] = 2 / pi for tau ~ U(0, 1); ceil adds < 1 / n per sample
    assert 2 / math.pi - 0.01 < ratio.mean().item() < 2 / math.pi + 0.04


def test_random_masking_is_uniform_over_valid_positions():
    batch = 3000
    lengths = torch.full((batch,), STEPS)
    a, b = _tokens(batch, lengths)
    tau = torch.full((batch,), 2 / 3, dtype=torch.float64)  # ratio 0.5
    mask = random_masking(a, b, lengths, tau=tau, generator=torch.Generator().manual_seed(2))
    frequency = mask.double().mean(0)
    assert (frequency - 0.5).abs().max() < 0.05


def test_interaction_masking_masks_exactly_one_persons_valid_tokens():
    batch = 200
    lengths = torch.randint(0, STEPS + 1, (batch,), generator=torch.Generator().manual_seed(4))
    a, b = _tokens(batch, lengths)
    mask = interaction_masking(a, b, lengths, generator=torch.Generator().manual_seed(0))
    valid = valid_tokens(torch.stack([a, b], 1), lengths)
    masked_a, masked_b = mask[:, 0].flatten(1).any(1), mask[:, 1].flatten(1).any(1)
    nonempty = lengths > 0
    assert not (masked_a & masked_b).any()
    assert (masked_a | masked_b)[nonempty].all()
    person = masked_b.long()
    chosen = mask[torch.arange(batch), person]
    assert torch.equal(chosen[nonempty], valid[torch.arange(batch), person][nonempty])
    assert 0.35 < masked_a[nonempty].double().mean() < 0.65


def test_training_mask_mixes_with_p_random_and_reports_tau():
    batch = 2000
    lengths = torch.full((batch,), STEPS)
    a, b = _tokens(batch, lengths)
    out = training_mask(a, b, lengths, p_random=0.8, generator=torch.Generator().manual_seed(5))
    assert 0.77 < out.is_random.double().mean() < 0.83
    interaction = ~out.is_random
    assert (out.tau[interaction] == INTERACTION_TAU).all()
    one_person = out.mask[interaction].flatten(2).all(2).sum(1)
    assert (one_person == 1).all()
    assert ((out.tau[out.is_random] >= 0) & (out.tau[out.is_random] <= 1)).all()
    with pytest.raises(ValueError, match="p_random must lie in"):
        training_mask(a, b, lengths, p_random=1.5)


def _scheduled_one_person(masking, batch: int = 400):
    """A one-person masking at random lengths and progress -> (mask, valid, tau, lengths)."""
    lengths = torch.randint(1, STEPS + 1, (batch,), generator=torch.Generator().manual_seed(1))
    a, b = _tokens(batch, lengths)
    tau = torch.rand(batch, generator=torch.Generator().manual_seed(2)).double()
    mask = masking(a, b, lengths, tau=tau, generator=torch.Generator().manual_seed(3))
    valid = valid_tokens(torch.stack([a, b], 1), lengths)
    assert not (mask & ~valid).any()  # padding is never masked
    return mask, valid, tau, lengths


def test_solo_masking_hides_one_person_and_masks_the_other_on_the_schedule():
    batch = 400
    mask, valid, tau, _ = _scheduled_one_person(solo_masking, batch)
    whole = (mask | ~valid).flatten(2).all(2)  # (B, 2) persons wholly masked
    absent = whole[:, 1].long()  # person B when both are (a one-token person), else the whole one
    assert whole.any(1).all()
    present = 1 - absent
    count = mask[torch.arange(batch), present].flatten(1).sum(1)
    n = valid[torch.arange(batch), present].flatten(1).sum(1)
    expected = torch.ceil(cosine_schedule(tau) * n.double() - 1e-9).clamp(min=1)
    assert torch.equal(count.double(), torch.minimum(expected, n.double()))
    one = whole.sum(1) == 1  # the absent person is known where the other is not wholly masked
    assert one.sum() > batch // 2 and 0.4 < absent[one].double().mean() < 0.6


def test_training_mask_with_p_solo_mixes_three_kinds_and_keeps_the_paper_stream():
    batch = 2000
    lengths = torch.full((batch,), STEPS)
    a, b = _tokens(batch, lengths)
    paper = training_mask(a, b, lengths, generator=torch.Generator().manual_seed(5))
    same = training_mask(a, b, lengths, p_solo=0.0, generator=torch.Generator().manual_seed(5))
    assert torch.equal(paper.mask, same.mask) and torch.equal(paper.tau, same.tau)
    out = training_mask(
        a, b, lengths, p_random=0.5, p_solo=0.5, generator=torch.Generator().manual_seed(5)
    )
    assert torch.equal(
        out.is_random,
        training_mask(
            a, b, lengths, p_random=0.5, generator=torch.Generator().manual_seed(5)
        ).is_random,
    )  # the same random-masking draw
    hidden = out.mask.flatten(2).all(2)  # (B, 2) persons wholly masked
    per_person = out.mask.flatten(2).sum(2)  # (B, 2)
    n = ROWS * STEPS
    other = per_person.sum(1) - n  # tokens masked in the other person of a one-person sample
    interaction = ~out.is_random & hidden.any(1) & (other == 0)
    solo = ~out.is_random & ~interaction
    assert 0.2 < solo.double().mean() < 0.3 and 0.2 < interaction.double().mean() < 0.3
    assert (hidden[solo].sum(1) >= 1).all() and (other[solo] >= 1).all()
    share = out.mask[solo].flatten(1).sum(1).double() / (2 * n)
    torch.testing.assert_close(out.tau[solo], inverse_cosine_schedule(share))
    assert (out.tau[interaction] == INTERACTION_TAU).all()
    with pytest.raises(ValueError, match="p_solo must lie in \\[0, 1\\], got -0.1"):
        training_mask(a, b, lengths, p_solo=-0.1)


def test_partner_masking_shows_one_person_whole_and_masks_the_other_on_the_schedule():
    batch = 400
    mask, valid, tau, lengths = _scheduled_one_person(partner_masking, batch)
    per_person = mask.flatten(2).sum(2)  # (B, 2)
    assert ((per_person == 0).sum(1) == 1).all()  # exactly one person, the partner, is whole
    masked = (per_person[:, 1] > 0).long()
    n = valid[torch.arange(batch), masked].flatten(1).sum(1)
    expected = torch.ceil(cosine_schedule(tau) * n.double() - 1e-9).clamp(min=1)
    assert torch.equal(per_person.sum(1).double(), expected)
    assert 0.4 < masked.double().mean() < 0.6  # either person may be the masked one
    # tau = 0 is interaction masking: the masked person is hidden wholly
    a, b = _tokens(batch, lengths)
    zero = partner_masking(
        a, b, lengths, tau=torch.zeros(batch, dtype=torch.float64), generator=torch.Generator()
    )
    assert torch.equal(zero.flatten(2).sum(2).max(1).values, valid[:, 0].flatten(1).sum(1))


def test_training_mask_with_p_partner_replaces_interaction_masking_and_keeps_the_stream():
    batch = 2000
    lengths = torch.full((batch,), STEPS)
    a, b = _tokens(batch, lengths)

    def demo_mask(**partner):  # gen_demo's mix, the same generator seed each time
        generator = torch.Generator().manual_seed(5)
        return training_mask(
            a, b, lengths, p_random=0.5, p_solo=0.5, generator=generator, **partner
        )

    without, same, out = demo_mask(), demo_mask(p_partner=0.0), demo_mask(p_partner=1.0)
    assert torch.equal(without.mask, same.mask) and torch.equal(without.tau, same.tau)
    assert torch.equal(out.is_random, without.is_random)
    n = ROWS * STEPS
    per_person = out.mask.flatten(2).sum(2)  # (B, 2)
    whole = (per_person == n).any(1)
    partner = ~out.is_random & (per_person == 0).any(1)  # one person wholly visible
    solo = ~out.is_random & whole & (per_person > 0).all(1)
    # p_partner 1: no sample is left to interaction masking, and solo samples stay solo
    interaction = ~out.is_random & whole & (per_person.sum(1) == n)
    assert not (interaction & ~partner).any()
    assert torch.equal(solo | partner, ~out.is_random)
    assert 0.2 < partner.double().mean() < 0.3 and 0.2 < solo.double().mean() < 0.3
    masked = per_person[partner].sum(1)
    # partial unless gamma(tau) > 39/40, i.e. tau < 2 / pi * acos(39 / 40) = 0.143
    assert (masked >= 1).all() and 0.8 < (masked < n).double().mean() < 0.9
    share = masked.double() / (2 * n)
    torch.testing.assert_close(out.tau[partner], inverse_cosine_schedule(share))
    with pytest.raises(ValueError, match="p_partner must lie in \\[0, 1\\], got 1.5"):
        training_mask(a, b, lengths, p_partner=1.5)


def test_bert_corruption_proportions():
    batch = 500
    lengths = torch.full((batch,), STEPS)
    a, b = _tokens(batch, lengths)
    tokens = torch.stack([a, b], 1)
    mask = torch.rand(tokens.shape, generator=torch.Generator().manual_seed(0)) < 0.5
    out = bert_corruption(tokens, mask, VOCAB, generator=torch.Generator().manual_seed(1))
    n = mask.sum().item()
    assert not (out.is_random & out.is_mask).any()
    assert torch.equal(out.tokens[~mask], tokens[~mask])
    assert (out.tokens[out.is_mask] == VOCAB.mask_id).all()
    assert ((out.tokens[out.is_random] >= 0) & (out.tokens[out.is_random] < K)).all()
    kept = mask & ~out.is_random & ~out.is_mask
    assert torch.equal(out.tokens[kept], tokens[kept])
    assert out.is_random.sum().item() / n == pytest.approx(0.1, abs=0.01)
    assert out.is_mask.sum().item() / n == pytest.approx(0.9 * 0.88, abs=0.01)
    assert kept.sum().item() / n == pytest.approx(0.9 * 0.12, abs=0.01)
    momask = bert_corruption(tokens, mask, VOCAB, mask_prob=8 / 9)
    assert momask.is_mask.sum().item() / n == pytest.approx(0.8, abs=0.01)
    with pytest.raises(ValueError, match="mask_prob must lie in"):
        bert_corruption(tokens, mask, VOCAB, mask_prob=2.0)


def test_step_unroll_keeps_the_confident_predictions():
    lengths = torch.tensor([8, 4])
    a, b = _tokens(2, lengths)
    tokens = torch.stack([a, b], 1)
    valid = valid_tokens(tokens, lengths)
    mask = valid.clone()  # everything masked
    corrupted = tokens.masked_fill(mask, VOCAB.mask_id)
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(*tokens.shape, K, generator=g) * 3
    tau = torch.tensor([0.0, 0.0], dtype=torch.float64)
    out = step_unroll_mask(logits, corrupted, mask, tau, lengths, VOCAB, tau_step=0.5)
    confidence, prediction = logits.softmax(-1).max(-1)
    assert torch.allclose(out.tau, torch.full((2,), 0.5, dtype=torch.float64))
    for i, n in enumerate((2 * ROWS * lengths).tolist()):
        remasked = out.remasked[i]
        assert remasked.sum().item() == math.ceil(math.cos(math.pi / 4) * n)
        retained = valid[i] & ~remasked
        # every retained prediction is at least as confident as every re-masked one
        assert confidence[i][retained].min() >= confidence[i][remasked].max()
        assert torch.equal(out.tokens[i][retained], prediction[i][retained])
        assert (out.tokens[i][remasked] == VOCAB.mask_id).all()
        assert torch.equal(out.mask[i], remasked)
        assert (out.tokens[i][~valid[i]] == -1).all()


def test_step_unroll_only_touches_mask_token_inputs_and_keeps_bert_positions_as_targets():
    lengths = torch.tensor([8])
    a, b = _tokens(1, lengths)
    tokens = torch.stack([a, b], 1)
    mask = valid_tokens(tokens, lengths)
    corruption = bert_corruption(tokens, mask, VOCAB, generator=torch.Generator().manual_seed(3))
    logits = torch.randn(*tokens.shape, K, generator=torch.Generator().manual_seed(4))
    tau = torch.tensor([0.99], dtype=torch.float64)  # tau_next = 1: gamma 0 -> one token
    out = step_unroll_mask(logits, corruption.tokens, mask, tau, lengths, VOCAB)
    assert out.remasked.sum().item() == 1
    not_mask_input = ~corruption.is_mask
    assert torch.equal(out.tokens[not_mask_input], corruption.tokens[not_mask_input])
    assert out.mask[not_mask_input & mask].all()  # random/kept positions stay loss targets
    assert torch.equal(out.mask & corruption.is_mask, out.remasked)
