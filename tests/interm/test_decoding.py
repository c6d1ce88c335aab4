import math

import pytest
import torch

from intermask.interm.decoding import (
    Edit,
    generate,
    guided_logits,
    null_condition,
    partner_guided_logits,
)
from intermask.interm.model import TextFeatures

K, ROWS, STEPS = 16, 5, 6
LENGTHS = torch.tensor([6, 3, 5])
ITERATIONS = 4


def _valid(lengths: torch.Tensor = LENGTHS, steps: int = STEPS) -> torch.Tensor:
    return (torch.arange(steps) < lengths[:, None])[:, None, None, :].expand(-1, 2, ROWS, -1)


def _run(model, text, lengths=LENGTHS, **kwargs):
    kwargs = {"iterations": ITERATIONS, "seeds": list(range(len(lengths))), **kwargs}
    return generate(model, text, lengths, **kwargs)


def _subset(text: TextFeatures, index: list[int]) -> TextFeatures:
    return TextFeatures(text.features[index], text.eot_index[index])


def _masked_counts(monkeypatch, model, text, **kwargs) -> list[list[int]]:
    """[MASK] tokens per sample seen by each guided pass of one :func:`_run`."""
    from intermask.interm import decoding

    seen = []
    original = decoding.guided_logits

    def recording(model, tokens, *args, **kwargs):
        seen.append((tokens == model.vocabulary.mask_id).flatten(1).sum(1).tolist())
        return original(model, tokens, *args, **kwargs)

    with monkeypatch.context() as patch:
        patch.setattr(decoding, "guided_logits", recording)
        _run(model, text, **kwargs)
    return seen


@pytest.fixture
def tiny(build):
    return build.model(), build.text(3)


def test_output_is_codes_in_the_clip_and_minus_one_outside(tiny):
    model, text = tiny
    tokens = _run(model, text)
    valid = _valid()
    assert tokens.shape == (3, 2, ROWS, STEPS)
    assert ((tokens[valid] >= 0) & (tokens[valid] < K)).all()  # no MASK, PAD or SEP
    assert (tokens[~valid] == -1).all()


def test_one_forward_pass_per_iteration(tiny):
    model, text = tiny
    calls = []
    handle = model.head.register_forward_hook(lambda *_: calls.append(1))
    try:
        _run(model, text, iterations=5)
        assert len(calls) == 5
        calls.clear()
        _run(model, None, iterations=3)
        assert len(calls) == 3
    finally:
        handle.remove()


def test_a_sample_does_not_depend_on_the_rest_of_the_batch(tiny):
    model, text = tiny
    together = _run(model, text, steps=STEPS, seeds=[11, 12, 13])
    alone = _run(model, _subset(text, [0]), LENGTHS[:1], steps=STEPS, seeds=[11])
    assert torch.equal(alone[0], together[0])
    reordered = _run(model, _subset(text, [2, 0]), LENGTHS[[2, 0]], steps=STEPS, seeds=[13, 11])
    assert torch.equal(reordered[0], together[2]) and torch.equal(reordered[1], together[0])
    assert not torch.equal(_run(model, text, seeds=[99, 12, 13])[0], together[0])


def test_same_seed_gives_the_same_result_and_training_mode_is_restored(tiny):
    model, text = tiny
    model.train()
    first, second = _run(model, text), _run(model, text)
    assert torch.equal(first, second) and model.training


def test_cfg_scale_one_is_plain_conditional_sampling(tiny, monkeypatch):
    model, text = tiny
    plain = _run(model, text, cfg_scale=1.0)
    # With the null condition replaced by the conditional one, uncond + s * (cond - uncond)
    # is exactly cond for any s: the guided path must then give the same tokens.
    condition = model.encode_condition(text)
    monkeypatch.setattr(
        "intermask.interm.decoding.null_condition", lambda *_: condition.detach().clone()
    )
    assert torch.equal(_run(model, text, cfg_scale=2.0), plain)


def test_guidance_combines_conditional_and_null_logits(tiny):
    model, text = tiny
    tokens = torch.full((3, 2, ROWS, STEPS), model.vocabulary.mask_id)
    with torch.no_grad():
        cond, null = model.encode_condition(text), null_condition(model, 3, torch.device("cpu"))
        c = guided_logits(model, tokens, cond, null, LENGTHS, 1.0)
        u = guided_logits(model, tokens, None, null, LENGTHS, 2.0)
        g = guided_logits(model, tokens, cond, null, LENGTHS, 3.0)
    torch.testing.assert_close(g, u + 3.0 * (c - u), atol=1e-5, rtol=1e-5)


def test_low_temperature_approaches_greedy_decoding(tiny):
    model, text = tiny
    with torch.no_grad():  # sharpen the logits so that greedy has no near-ties
        model.head.logits.weight.mul_(50)
    greedy = _run(model, text, temperature=0.0)
    assert torch.equal(_run(model, text, temperature=0.0, seeds=[5, 6, 7]), greedy)
    assert torch.equal(_run(model, text, temperature=1e-4, seeds=[5, 6, 7]), greedy)
    assert not torch.equal(_run(model, text, temperature=5.0, top_k_ratio=1.0), greedy)


def test_reaction_keeps_the_reference_person(tiny, build):
    model, text = tiny
    reference = torch.randint(0, K, (3, ROWS, STEPS), generator=torch.Generator().manual_seed(8))
    valid = _valid()
    for condition in (text, None):
        tokens = _run(model, condition, reference_tokens=reference)
        assert torch.equal(tokens[:, 0][valid[:, 0]], reference[valid[:, 0]])
        assert (tokens[:, 0][~valid[:, 0]] == -1).all()
        assert ((tokens[:, 1][valid[:, 1]] >= 0) & (tokens[:, 1][valid[:, 1]] < K)).all()


def test_inpainting_changes_only_the_region(tiny):
    model, text = tiny
    fixed = torch.randint(0, K, (3, 2, ROWS, STEPS), generator=torch.Generator().manual_seed(9))
    region = torch.zeros(3, 2, ROWS, STEPS, dtype=torch.bool)
    region[:, :, :, 1:3] = True  # a middle stretch of both persons
    region[0, 1] = True  # and all of person B in sample 0
    tokens = _run(model, text, edit=Edit(fixed, region))
    valid = _valid()
    outside = valid & ~region
    assert torch.equal(tokens[outside], fixed[outside])
    assert ((tokens[valid & region] >= 0) & (tokens[valid & region] < K)).all()
    assert (tokens[~valid] == -1).all()


def test_errors_are_reported(tiny):
    model, text = tiny
    reference = torch.zeros(3, ROWS, STEPS, dtype=torch.long)
    edit = Edit(torch.zeros(3, 2, ROWS, STEPS, dtype=torch.long), torch.ones(3, 2, ROWS, STEPS))
    with pytest.raises(ValueError, match="exclusive"):
        _run(model, text, reference_tokens=reference, edit=edit)
    with pytest.raises(ValueError, match="reference_tokens must be"):
        _run(model, text, steps=STEPS, reference_tokens=reference[:, :, :4])
    with pytest.raises(ValueError, match="fixed tokens inside the clip"):
        _run(model, text, reference_tokens=reference - 1)
    with pytest.raises(ValueError, match="expected 3 seeds"):
        _run(model, text, seeds=[1])
    with pytest.raises(ValueError, match="iterations must be"):
        _run(model, text, iterations=0)


@pytest.mark.parametrize("schedule", ["paper", "reference"])
def test_each_iteration_masks_the_count_of_its_schedule(tiny, monkeypatch, schedule):
    """paper: ceil(gamma(i / I) n) masked before iteration i > 0; reference (MoMask's code):
    max(1, round(gamma(k / (I - 1)) n)), so its last pass re-predicts one token."""
    import math

    model, text = tiny
    seen = _masked_counts(monkeypatch, model, text, iterations=ITERATIONS, schedule=schedule)
    n = [2 * ROWS * int(length) for length in LENGTHS]  # both persons' tokens
    gamma = [math.cos(math.pi / 2 * tau) for tau in (0.0, 1 / 3, 2 / 3, 1.0, 0.25, 0.5, 0.75)]
    if schedule == "paper":  # iteration i sees ceil(gamma(i / 4) n)
        expected = [[math.ceil(g * m - 1e-9) for m in n] for g in [1.0, *gamma[4:]]]
    else:  # iteration k sees max(1, round(gamma(k / 3) n))
        expected = [[max(1, round(g * m)) for m in n] for g in gamma[:4]]
    assert seen == expected
    assert schedule == "paper" or seen[-1] == [1, 1, 1]


def test_the_reference_schedule_changes_the_result_and_is_checked(tiny):
    model, text = tiny
    assert not torch.equal(_run(model, text), _run(model, text, schedule="reference"))
    with pytest.raises(
        ValueError, match=r"schedule must be one of \('paper', 'reference'\), got 'x'"
    ):
        _run(model, text, schedule="x")


def test_reference_noise_is_the_references_multinomial_draw_over_the_batch(tiny):
    """noise="reference": one generator (seeds[0]) draws every position with torch.multinomial,
    as the reference's Categorical sampling does; the codes then depend on the batch."""
    from intermask.interm import decoding

    logits = torch.randn(2, 2, ROWS, STEPS, K, generator=torch.Generator().manual_seed(4))
    filtered = decoding.top_k_filter(logits, 0.5)
    drawn = decoding.reference_draw(filtered, torch.Generator().manual_seed(9), 1.0)
    probs = filtered.softmax(-1)
    expected = torch.multinomial(
        (probs / probs.sum(-1, keepdim=True)).reshape(-1, K), 1, True,
        generator=torch.Generator().manual_seed(9),
    ).reshape(drawn.shape)  # fmt: skip
    assert torch.equal(drawn, expected)
    assert bool((filtered.gather(-1, drawn[..., None]) > -math.inf).all())  # inside the top-k
    model, text = tiny
    together = _run(model, text, seeds=[5, 5, 5], schedule="reference", noise="reference")
    again = _run(model, text, seeds=[5, 5, 5], schedule="reference", noise="reference")
    assert torch.equal(together, again)
    alone = _run(
        model, _subset(text, [0]), LENGTHS[:1], steps=STEPS, seeds=[5],
        schedule="reference", noise="reference",
    )  # fmt: skip
    assert not torch.equal(alone[0], together[0])  # the batch changes the draws
    with pytest.raises(ValueError, match=r"noise must be one of \('per_sample', 'reference'\)"):
        _run(model, text, noise="global")


def test_in_turn_decodes_person_a_with_b_masked_then_b_given_a(tiny, monkeypatch):
    """persons="in_turn": I passes in which B is all [MASK] and only A's tokens are committed,
    then I passes in which A is final and only B's are; the paper's schedule within each."""
    from intermask.interm import decoding

    model, text = tiny
    mask = model.vocabulary.mask_id
    seen = []
    original = decoding.guided_logits

    def recording(model, tokens, *args, **kwargs):
        seen.append(((tokens[:, 0] == mask).flatten(1).sum(1), (tokens[:, 1] == mask).flatten(1)))
        return original(model, tokens, *args, **kwargs)

    monkeypatch.setattr(decoding, "guided_logits", recording)
    tokens = _run(model, text, persons="in_turn")
    per_person = [ROWS * int(length) for length in LENGTHS]
    assert len(seen) == 2 * ITERATIONS
    for i, (masked_a, masked_b) in enumerate(seen[:ITERATIONS]):  # person A's turn
        gamma = 1.0 if i == 0 else math.cos(math.pi / 2 * i / ITERATIONS)
        assert masked_a.tolist() == [math.ceil(gamma * n - 1e-9) for n in per_person]
        assert masked_b.sum(1).tolist() == per_person  # B waits, all [MASK]
    for i, (masked_a, masked_b) in enumerate(seen[ITERATIONS:]):  # person B's turn, A final
        gamma = 1.0 if i == 0 else math.cos(math.pi / 2 * i / ITERATIONS)
        assert masked_a.tolist() == [0, 0, 0]
        assert masked_b.sum(1).tolist() == [math.ceil(gamma * n - 1e-9) for n in per_person]
    valid = _valid()
    assert ((tokens[valid] >= 0) & (tokens[valid] < K)).all() and (tokens[~valid] == -1).all()
    assert not torch.equal(tokens, _run(model, text))  # a different decoding from "together"


def test_revisits_decode_a_again_given_b_then_b_given_the_new_a(tiny, monkeypatch):
    """revisits=2: after A's and B's turns, A's tokens are all [MASK] again and decoded beside
    B's finished ones, then B's beside the new A's; each turn on the paper's schedule."""
    from intermask.interm import decoding

    model, text = tiny
    mask = model.vocabulary.mask_id
    seen = []
    original = decoding.guided_logits

    def recording(model, tokens, *args, **kwargs):
        seen.append(tuple((tokens[:, p] == mask).flatten(1).sum(1).tolist() for p in (0, 1)))
        return original(model, tokens, *args, **kwargs)

    monkeypatch.setattr(decoding, "guided_logits", recording)
    plain = _run(model, text, persons="in_turn")
    seen.clear()
    tokens = _run(model, text, persons="in_turn", revisits=2)
    per_person = [ROWS * int(length) for length in LENGTHS]
    assert len(seen) == 4 * ITERATIONS
    for turn in range(4):
        person = turn % 2
        for i, counts in enumerate(seen[turn * ITERATIONS : (turn + 1) * ITERATIONS]):
            gamma = 1.0 if i == 0 else math.cos(math.pi / 2 * i / ITERATIONS)
            assert list(counts[person]) == [math.ceil(gamma * n - 1e-9) for n in per_person]
            # the other person: all [MASK] while A's first turn runs, finished afterwards
            assert list(counts[1 - person]) == (per_person if turn == 0 else [0, 0, 0])
    valid = _valid()
    assert ((tokens[valid] >= 0) & (tokens[valid] < K)).all() and (tokens[~valid] == -1).all()
    assert not torch.equal(tokens, plain)  # the revisits change the result
    # a reaction's fixed person A is never revisited
    reference = torch.randint(0, K, (3, ROWS, STEPS), generator=torch.Generator().manual_seed(8))
    reaction = _run(model, text, reference_tokens=reference, persons="in_turn", revisits=1)
    assert torch.equal(reaction[:, 0][valid[:, 0]], reference[valid[:, 0]])
    for bad, persons in ((-1, "in_turn"), (1, "together")):
        with pytest.raises(
            ValueError,
            match=f"revisits must be >= 0 and needs persons='in_turn', got {bad} with '{persons}'",
        ):
            _run(model, text, persons=persons, revisits=bad)


def test_in_turn_keeps_fixed_tokens_and_is_checked(tiny):
    model, text = tiny
    reference = torch.randint(0, K, (3, ROWS, STEPS), generator=torch.Generator().manual_seed(8))
    valid = _valid()
    # a reaction has only B to decode: in turn is the same decoding as together
    together = _run(model, text, reference_tokens=reference)
    assert torch.equal(_run(model, text, reference_tokens=reference, persons="in_turn"), together)
    fixed = torch.randint(0, K, (3, 2, ROWS, STEPS), generator=torch.Generator().manual_seed(9))
    region = torch.zeros(3, 2, ROWS, STEPS, dtype=torch.bool)
    region[:, :, :, 1:3] = True
    tokens = _run(model, text, edit=Edit(fixed, region), persons="in_turn")
    assert torch.equal(tokens[valid & ~region], fixed[valid & ~region])
    with pytest.raises(
        ValueError, match=r"persons must be one of \('together', 'in_turn'\), got 'alone'"
    ):
        _run(model, text, persons="alone")


@pytest.fixture
def coupled(build):
    """A tiny model whose persons see each other: every weight moved off its initialisation
    (at init a person's logits hardly depend on its partner, ~1e-4)."""
    model = build.model()
    generator = torch.Generator().manual_seed(5)
    with torch.no_grad():
        for parameter in model.parameters():
            parameter.add_(torch.randn(parameter.shape, generator=generator) * 0.2)
    return model, build.text(3)


def test_partner_guidance_follows_what_the_partner_adds(coupled):
    """uncond + s (cond - uncond) + g (cond - cond with the partner's tokens [MASK]ed)."""
    model, text = coupled
    mask = model.vocabulary.mask_id
    codes = torch.randint(0, K, (3, 2, ROWS, STEPS), generator=torch.Generator().manual_seed(4))
    tokens = codes.clone()
    tokens[:, 1] = mask  # B to decode beside A's codes
    partner = torch.zeros_like(tokens, dtype=torch.bool)
    partner[:, 0] = _valid()[:, 0]
    hidden = tokens.masked_fill(partner, mask)
    with torch.no_grad():
        cond, null = model.encode_condition(text), null_condition(model, 3, torch.device("cpu"))
        c = guided_logits(model, tokens, cond, null, LENGTHS, 1.0)
        u = guided_logits(model, tokens, None, null, LENGTHS, 1.0)
        h = guided_logits(model, hidden, cond, null, LENGTHS, 1.0)
        both = partner_guided_logits(model, tokens, partner, cond, null, LENGTHS, 1.5, 2.0)
        no_text = partner_guided_logits(model, tokens, partner, None, null, LENGTHS, 1.5, 2.0)
        h_null = guided_logits(model, hidden, None, null, LENGTHS, 1.0)
        plain = partner_guided_logits(model, tokens, partner, cond, null, LENGTHS, 1.5, 0.0)
    assert (c - h).abs().max() > 0.5  # hiding A changes B's prediction
    torch.testing.assert_close(both, u + 1.5 * (c - u) + 2.0 * (c - h), atol=1e-4, rtol=1e-4)
    torch.testing.assert_close(no_text, u + 2.0 * (u - h_null), atol=1e-4, rtol=1e-4)
    torch.testing.assert_close(
        plain, guided_logits(model, tokens, cond, null, LENGTHS, 1.5), atol=1e-4, rtol=1e-4
    )


def test_partner_guidance_runs_where_one_person_is_decoded_beside_the_other(coupled, monkeypatch):
    """In turn: not in A's first turn (B is all [MASK]), in B's turn and every revisit, each
    pass with one more copy of the batch; a reaction: every pass. 0 is the plain decoding."""
    from intermask.interm import decoding

    model, text = coupled
    mask = model.vocabulary.mask_id
    batches, hidden_persons = [], []
    forward = model.forward_with_condition

    def recording(a, b, condition, lengths):
        batches.append(a.shape[0])
        return forward(a, b, condition, lengths)

    original = decoding.partner_guided_logits

    def partnered(model, tokens, partner, *args, **kwargs):
        hidden_persons.append(tuple(bool(partner[:, p].any()) for p in (0, 1)))
        assert not bool((tokens[partner] == mask).any())  # only finished codes are hidden
        return original(model, tokens, partner, *args, **kwargs)

    monkeypatch.setattr(model, "forward_with_condition", recording)
    monkeypatch.setattr(decoding, "partner_guided_logits", partnered)
    plain = _run(model, text, persons="in_turn", revisits=1)
    batches.clear()
    assert torch.equal(_run(model, text, persons="in_turn", revisits=1, partner_scale=0.0), plain)
    assert batches == [6] * (3 * ITERATIONS) and hidden_persons == []
    batches.clear()
    guided = _run(model, text, persons="in_turn", revisits=1, partner_scale=2.0)
    # A's turn: doubled (text guidance); B's turn hides A, the revisit of A hides B: tripled
    assert batches == [6] * ITERATIONS + [9] * (2 * ITERATIONS)
    assert hidden_persons == [(True, False)] * ITERATIONS + [(False, True)] * ITERATIONS
    valid = _valid()
    assert ((guided[valid] >= 0) & (guided[valid] < K)).all() and (guided[~valid] == -1).all()
    assert not torch.equal(guided, plain)
    # a reaction: B beside the fixed A in every pass; without text, no null copy
    reference = torch.randint(0, K, (3, ROWS, STEPS), generator=torch.Generator().manual_seed(8))
    batches.clear()
    hidden_persons.clear()
    reaction = _run(model, None, reference_tokens=reference, partner_scale=1.0)
    assert batches == [6] * ITERATIONS and hidden_persons == [(True, False)] * ITERATIONS
    assert torch.equal(reaction[:, 0][valid[:, 0]], reference[valid[:, 0]])
    assert not torch.equal(reaction, _run(model, None, reference_tokens=reference))


def test_partner_guidance_is_refused_where_no_person_has_a_fixed_partner(tiny, build):
    model, text = tiny
    with pytest.raises(
        ValueError,
        match=r"partner_scale \(1.0\) needs one person decoded beside the other's fixed tokens: "
        r"persons='in_turn' or reference_tokens, got persons='together'",
    ):
        _run(model, text, partner_scale=1.0)
    alternative = build.model(modeling="alternative")
    with pytest.raises(
        ValueError, match=r"partner_scale \(0.5\) guides a collaborative model's passes"
    ):
        _run(alternative, text, persons="in_turn", partner_scale=0.5)


def test_remask_noise_keeps_the_schedule_and_each_sample_its_own_draws(tiny, monkeypatch):
    """Gumbel noise on the re-masking ranks changes which codes are kept, not how many; each
    sample's noise comes from its own seed; 0 is the paper's ranking, bit for bit."""
    model, text = tiny
    plain = _run(model, text)
    assert torch.equal(_run(model, text, remask_noise=0.0), plain)
    noisy = _run(model, text, steps=STEPS, seeds=[0, 1, 2], remask_noise=3.0)
    assert not torch.equal(noisy, plain)
    alone = _run(model, _subset(text, [1]), LENGTHS[1:2], steps=STEPS, seeds=[1], remask_noise=3.0)
    assert torch.equal(alone[0], noisy[1])
    assert torch.equal(_run(model, text, remask_noise=3.0), noisy)  # reproducible
    counts = _masked_counts(monkeypatch, model, text)
    assert _masked_counts(monkeypatch, model, text, remask_noise=3.0) == counts


def test_remask_noise_ranks_by_log_confidence_plus_fading_gumbel_noise():
    """Iteration i of I adds t (1 - (i + 1) / I) g to log p, g drawn from the sample's own
    generator over its own steps: no noise after the last iteration."""
    from intermask.interm.decoding import Decoding, _Call, _remask_scores

    confidence = torch.tensor([[0.5, 0.25, 0.125]])
    settings = _Call(
        settings=Decoding(cfg_scale=1.0, top_k_ratio=1.0, temperature=1.0, remask_noise=2.0),
        condition=None,
        null=torch.zeros(1, 4),
        lengths_in_steps=torch.tensor([3]),
        generators=[torch.Generator().manual_seed(7)],
    )
    scores = _remask_scores(confidence, settings, 0, 4)
    uniform = torch.rand(1, 3, generator=torch.Generator().manual_seed(7))
    gumbel = -torch.log(-torch.log(uniform))
    assert torch.allclose(scores, confidence.log() + 2.0 * 0.75 * gumbel)
    assert torch.equal(_remask_scores(confidence, settings, 3, 4), confidence)
    short = settings._replace(lengths_in_steps=torch.tensor([2]))
    short = short._replace(generators=[torch.Generator().manual_seed(7)])
    padded = _remask_scores(confidence, short, 1, 4)
    first_two = -torch.log(-torch.log(uniform[0, :2]))
    assert torch.allclose(padded[0, :2], confidence[0, :2].log() + 2.0 * 0.5 * first_two)


def test_remask_noise_is_checked(tiny):
    model, text = tiny
    with pytest.raises(ValueError, match=r"remask_noise must be >= 0, got -1.0"):
        _run(model, text, remask_noise=-1.0)
    with pytest.raises(ValueError, match=r"remask_noise must be >= 0, got nan"):
        _run(model, text, remask_noise=math.nan)
    with pytest.raises(
        ValueError, match=r"remask_noise \(1.0\) draws each sample's noise from its own seed"
    ):
        _run(model, text, remask_noise=1.0, noise="reference")


def test_the_reference_schedule_counts_and_ranks_as_the_reference_code():
    """Its re-masking count comes from float32 (gamma(2/3) = 0.49999997: of 3 generated tokens
    1 is re-masked where a float64 schedule re-masks 2) and its ties fall as torch's default sort
    puts them, not by position."""
    from intermask.interm.decoding import remask

    undecided = torch.ones(1, 3, dtype=torch.bool)
    confidence = torch.tensor([[0.2, 0.1, 0.3]])
    # iteration 5 of 10 re-masks round(cos(pi/2 * 6/9) * 3) = round(1.4999999) = 1 token
    remasked = remask(confidence, undecided, torch.tensor([3]), 5, 10, "reference")
    assert remasked.tolist() == [[False, True, False]]
    assert round(math.cos(math.pi / 2 * 6 / 9) * 3) == 2  # what a float64 schedule would keep
    ties = torch.tensor([[0.5, 0.1, 0.3, 0.1, 0.9, 0.1, 0.3] * 6])
    everything = torch.ones_like(ties, dtype=torch.bool)
    # iteration 7 of 10 re-masks round(cos(pi/2 * 8/9) * 42) = 7 of the 42
    reference = ties.argsort(dim=1).argsort(dim=1) < 7  # the reference's own ranking
    remasked = remask(ties, everything, torch.tensor([42]), 7, 10, "reference")
    assert int(remasked.sum()) == 7 and torch.equal(remasked, reference)
    assert not torch.equal(remasked, ties.argsort(dim=1, stable=True).argsort(dim=1) < 7)
