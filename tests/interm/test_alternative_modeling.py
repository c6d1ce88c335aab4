"""Alternative modeling (InterMask appendix E, Table 3): one person per pass, the other person's
input embeddings as a fixed cross-attention context; decoding alternates A and B."""

import pytest
import torch

from intermask.interm.blocks import InterMBlock
from intermask.interm.decoding import Edit, generate, guided_person_logits, null_condition
from intermask.interm.model import InterMTransformer, TextFeatures, count_parameters

K, ROWS, STEPS = 16, 5, 6
LENGTHS = torch.tensor([6, 3, 5])
ITERATIONS = 3


def _valid(lengths: torch.Tensor = LENGTHS, steps: int = STEPS) -> torch.Tensor:
    """(B, 2, rows, T') True inside the clip."""
    return (torch.arange(steps) < lengths[:, None])[:, None, None, :].expand(-1, 2, ROWS, -1)


def _run(model, text, lengths=LENGTHS, **kwargs):
    kwargs = {"iterations": ITERATIONS, "seeds": list(range(len(lengths))), **kwargs}
    return generate(model, text, lengths, **kwargs)


@pytest.fixture
def alternative(build) -> InterMTransformer:
    return build.model(modeling="alternative")


def test_alternative_modeling_builds_the_same_parameters(build):
    # the collaborative paper setting has 54,272,896 (test_interm_model); nothing is added
    assert count_parameters(InterMTransformer(modeling="alternative")) == 54_272_896
    tiny_collaborative, tiny_alternative = build.model(), build.model(modeling="alternative")
    assert tiny_alternative.state_dict().keys() == tiny_collaborative.state_dict().keys()


def test_invalid_modeling_combinations_are_rejected_at_construction(build):
    with pytest.raises(ValueError, match=r"modeling must be one of .*got 'sequential'"):
        build.model(modeling="sequential")
    with pytest.raises(
        ValueError, match="only through cross attention; .* use_cross_attention=False"
    ):
        build.model(modeling="alternative", use_cross_attention=False)
    with pytest.raises(ValueError, match="cross_context_quirk has no effect"):
        build.model(modeling="alternative", cross_context_quirk=True)
    with pytest.raises(ValueError, match="forward_person predicts one person"):
        a, b = build.tokens(3, STEPS)
        build.model().forward_person(a, b, torch.zeros(3, 32), LENGTHS)
    block = InterMBlock(width=16, heads=4, ff=24, dropout=0.0, use_cross_attention=False)
    x = torch.zeros(1, ROWS, 16)
    padding = torch.zeros(1, ROWS, dtype=torch.bool)
    with pytest.raises(RuntimeError, match="needs the cross-attention sub-layer"):
        block.forward_alternative(x, x, torch.zeros(1, 16), padding, padding, rows=ROWS)


def test_every_block_reads_the_same_unchanged_partner_embeddings(alternative, build):
    a, b = build.tokens(3, STEPS)
    contexts = []
    for block in alternative.blocks:
        block.cross_attention.register_forward_hook(
            lambda _m, args, _out: contexts.append(args[1].clone())
        )
    condition = alternative.encode_condition(build.text(3))
    alternative.forward_person(a, b, condition, LENGTHS)
    embedded, _ = alternative._embed(a, b, LENGTHS)
    partner = embedded[:, ROWS * STEPS + 1 :]  # B's input process output, after [SEP]
    assert len(contexts) == len(alternative.blocks) == 2
    assert all(torch.equal(context, partner) for context in contexts)


def _close_cross_attention(model: InterMTransformer) -> None:
    """Zero the cross attention output projections: the sub-layer becomes the identity."""
    with torch.no_grad():
        for block in model.blocks:
            block.cross_attention.attention.out.weight.zero_()
            block.cross_attention.attention.out.bias.zero_()


def test_the_partner_reaches_the_predicted_person_only_through_cross_attention(build):
    a, b = build.tokens(3, STEPS)
    _, other_b = build.tokens(3, STEPS, seed=7)
    text = build.text(3)
    alternative = build.model(modeling="alternative")
    assert not torch.allclose(
        alternative(a, b, text, LENGTHS).logits_a, alternative(a, other_b, text, LENGTHS).logits_a
    )
    _close_cross_attention(alternative)
    torch.testing.assert_close(
        alternative(a, b, text, LENGTHS).logits_a,
        alternative(a, other_b, text, LENGTHS).logits_a,
        atol=0,
        rtol=0,
    )
    # collaborative modeling also mixes the persons in self attention
    collaborative = build.model()
    _close_cross_attention(collaborative)
    assert not torch.allclose(
        collaborative(a, b, text, LENGTHS).logits_a,
        collaborative(a, other_b, text, LENGTHS).logits_a,
    )


def test_forward_gives_both_directions_and_swapping_persons_swaps_them(alternative, build):
    a, b = build.tokens(3, STEPS)
    text = build.text(3)
    out = alternative(a, b, text, LENGTHS)
    condition = alternative.encode_condition(text)
    torch.testing.assert_close(
        alternative.forward_person(a, b, condition, LENGTHS), out.logits_a, atol=1e-5, rtol=1e-5
    )
    torch.testing.assert_close(
        alternative.forward_person(b, a, condition, LENGTHS), out.logits_b, atol=1e-5, rtol=1e-5
    )
    swapped = alternative(b, a, text, LENGTHS)
    torch.testing.assert_close(swapped.logits_a, out.logits_b, atol=1e-5, rtol=1e-5)
    assert out.logits_a.shape == (3, ROWS, STEPS, K)


def test_padded_partner_steps_do_not_influence_valid_outputs(alternative, build):
    a, b = build.tokens(3, STEPS)
    _, noise = build.tokens(3, STEPS, seed=9)
    valid = _valid()[:, 0]
    condition = alternative.encode_condition(build.text(3))
    out = alternative.forward_person(a, b, condition, LENGTHS)
    changed = alternative.forward_person(a, torch.where(valid, b, noise), condition, LENGTHS)
    torch.testing.assert_close(changed[valid], out[valid], atol=1e-5, rtol=0)


def test_gradients_reach_every_parameter(build):
    model = build.model(modeling="alternative").train()
    a, b = build.tokens(3, STEPS)
    out = model(a, b, build.text(3), LENGTHS)
    (out.logits_a.logsumexp(-1).mean() + out.logits_b.logsumexp(-1).mean()).backward()
    for name, parameter in model.named_parameters():
        assert parameter.grad is not None and torch.isfinite(parameter.grad).all(), name


def test_decoding_returns_codes_with_one_person_per_pass(alternative, build):
    text = build.text(3)
    shapes = []
    handle = alternative.head.register_forward_hook(
        lambda _m, args, _o: shapes.append(args[0].shape)
    )
    try:
        tokens = _run(alternative, text)
    finally:
        handle.remove()
    valid = _valid()
    assert tokens.shape == (3, 2, ROWS, STEPS)
    assert ((tokens[valid] >= 0) & (tokens[valid] < K)).all() and (tokens[~valid] == -1).all()
    # guidance doubles the batch; each pass holds one person's N tokens; A and B each round
    assert shapes == [(6, ROWS * STEPS, 32)] * (2 * ITERATIONS)


def test_revisits_are_refused_rather_than_ignored(alternative, build):
    with pytest.raises(ValueError, match=r"revisits \(1\) re-decode a collaborative model's turns"):
        _run(alternative, build.text(3), persons="in_turn", revisits=1)


def test_persons_alternate_and_b_sees_what_a_kept(alternative, build, monkeypatch):
    calls = []
    forward = alternative.forward_person

    def recording(tokens, partner, condition, lengths):
        calls.append((tokens.clone(), partner.clone()))
        return forward(tokens, partner, condition, lengths)

    monkeypatch.setattr(alternative, "forward_person", recording)
    final = _run(alternative, None, LENGTHS[:1], iterations=2)  # no guidance: one call per pass
    mask_id = alternative.vocabulary.mask_id
    assert len(calls) == 4
    (own0, partner0), (own1, partner1) = calls[0], calls[1]
    assert (own0 == mask_id).all() and (partner0 == mask_id).all()  # round 1: A, both masked
    assert (own1 == mask_id).all()  # then B, still fully masked ...
    kept = partner1 != mask_id  # ... conditioned on A's retained tokens
    n = ROWS * STEPS
    assert int(kept.sum()) == n - int(torch.ceil(torch.tensor(0.5**0.5 * n) - 1e-9))
    assert torch.equal(partner1[kept], final[:, 0][kept])  # a kept token never changes
    assert torch.equal(calls[2][0][kept], partner1[kept])  # A's round 2 starts from them


def test_reaction_runs_only_the_generated_persons_passes(alternative, build):
    reference = torch.randint(0, K, (3, ROWS, STEPS), generator=torch.Generator().manual_seed(8))
    calls = []
    handle = alternative.head.register_forward_hook(lambda *_: calls.append(1))
    try:
        tokens = _run(alternative, build.text(3), reference_tokens=reference)
    finally:
        handle.remove()
    valid = _valid()
    assert len(calls) == ITERATIONS
    assert torch.equal(tokens[:, 0][valid[:, 0]], reference[valid[:, 0]])
    assert ((tokens[:, 1][valid[:, 1]] >= 0) & (tokens[:, 1][valid[:, 1]] < K)).all()


def test_seeds_make_each_sample_reproducible_and_batch_independent(alternative, build):
    text = build.text(3)
    fixed = torch.randint(0, K, (3, 2, ROWS, STEPS), generator=torch.Generator().manual_seed(9))
    region = torch.zeros(3, 2, ROWS, STEPS, dtype=torch.bool)
    region[0, 1] = True  # sample 0: only person B is generated (A's passes do nothing for it)
    region[1:] = True
    edit = Edit(fixed, region)
    together = _run(alternative, text, edit=edit, seeds=[11, 12, 13])
    assert torch.equal(together, _run(alternative, text, edit=edit, seeds=[11, 12, 13]))
    alone = _run(
        alternative,
        TextFeatures(text.features[:1], text.eot_index[:1]),
        LENGTHS[:1],
        edit=Edit(fixed[:1], region[:1]),
        seeds=[11],
    )
    assert torch.equal(alone[0], together[0])
    assert torch.equal(together[0, 0][_valid()[0, 0]], fixed[0, 0][_valid()[0, 0]])
    assert not torch.equal(_run(alternative, text, edit=edit, seeds=[11, 99, 13])[1], together[1])


def test_person_guidance_combines_conditional_and_null_logits(alternative, build):
    text = build.text(3)
    tokens = torch.full((3, 2, ROWS, STEPS), alternative.vocabulary.mask_id)
    tokens[:, 0, :, :2] = 3
    with torch.no_grad():
        cond = alternative.encode_condition(text)
        null = null_condition(alternative, 3, torch.device("cpu"))
        c = guided_person_logits(alternative, tokens, 1, cond, null, LENGTHS, 1.0)
        u = guided_person_logits(alternative, tokens, 1, None, null, LENGTHS, 2.0)
        g = guided_person_logits(alternative, tokens, 1, cond, null, LENGTHS, 3.0)
        direct = alternative.forward_person(tokens[:, 1], tokens[:, 0], cond, LENGTHS)
    torch.testing.assert_close(c, direct)
    torch.testing.assert_close(g, u + 3.0 * (c - u), atol=1e-5, rtol=1e-5)
