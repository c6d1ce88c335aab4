import pytest
import torch

from intermask.interm.model import InterMTransformer, TextFeatures, count_parameters

STEPS = 6
LENGTHS = torch.tensor([6, 3, 0])


def _valid(lengths: torch.Tensor = LENGTHS) -> torch.Tensor:
    """(B, rows, T') True where a token is inside the clip."""
    return (torch.arange(STEPS) < lengths[:, None])[:, None, :].expand(-1, 5, -1)


def test_paper_configuration_has_about_54m_parameters():
    model = InterMTransformer()
    total, text = count_parameters(model), count_parameters(model.text_encoder)
    print(f"Inter-M paper configuration: {total:,} parameters, text encoder {text:,}")
    # paper appendix / model-facts: ~54M without CLIP, ~11M of it the trainable text layers
    assert abs(total - 54e6) / 54e6 < 0.01 and abs(text - 11e6) / 11e6 < 0.01
    assert (total, text) == (54_272_896, 11_027_968)


def test_paper_configuration_runs_a_300_frame_pair():
    """T = 300 frames -> 75 token steps x 5 rows per person: a 2 x 375 + [SEP] = 751-token
    sequence, with one clip of the batch shorter (padding)."""
    torch.manual_seed(0)
    model = InterMTransformer().eval()
    tokens = torch.randint(0, 1024, (2, 2, 5, 75))
    text = TextFeatures(torch.randn(2, 9, 768), torch.tensor([8, 5]))
    with torch.no_grad():
        out = model(tokens[:, 0], tokens[:, 1], text, torch.tensor([75, 60]))
    assert out.logits_a.shape == out.logits_b.shape == (2, 5, 75, 1024)
    assert torch.isfinite(out.logits_a).all() and torch.isfinite(out.logits_b).all()


def test_logits_have_per_person_shapes_and_no_nan_with_padding(build):
    model = build.model()
    a, b = build.tokens(3, STEPS)
    a[1, :, 3:] = -1  # VQ padding
    out = model(a, b, build.text(3), LENGTHS)
    assert out.logits_a.shape == out.logits_b.shape == (3, 5, STEPS, 16)
    assert torch.isfinite(out.logits_a).all() and torch.isfinite(out.logits_b).all()


def test_padded_steps_do_not_influence_valid_outputs(build):
    model, text = build.model(), build.text(3)
    a, b = build.tokens(3, STEPS)
    out = model(a, b, text, LENGTHS)
    a2, b2 = build.tokens(3, STEPS, seed=9)
    valid = _valid()
    a2, b2 = torch.where(valid, a, a2), torch.where(valid, b, b2)
    a2[1, :, 3:] = -1
    changed = model(a2, b2, text, LENGTHS)
    assert not torch.equal(a, a2)
    torch.testing.assert_close(changed.logits_a[valid], out.logits_a[valid], atol=1e-5, rtol=0)
    torch.testing.assert_close(changed.logits_b[valid], out.logits_b[valid], atol=1e-5, rtol=0)


def test_swapping_persons_swaps_the_logits(build):
    model, text = build.model(), build.text(3)
    a, b = build.tokens(3, STEPS)
    out = model(a, b, text, LENGTHS)
    swapped = model(b, a, text, LENGTHS)
    torch.testing.assert_close(swapped.logits_a, out.logits_b, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(swapped.logits_b, out.logits_a, atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize(
    ("flag", "layer"),
    [
        ("use_self_attention", "self_attention"),
        ("use_spatio_temporal_attention", "spatio_temporal"),
        ("use_cross_attention", "cross_attention"),
    ],
)
def test_each_ablation_removes_its_module(build, flag: str, layer: str):
    full = build.model()
    ablated = build.model(**{flag: False})
    removed = sum(count_parameters(getattr(block, layer)) for block in full.blocks)
    assert removed > 0 and all(getattr(block, layer) is None for block in ablated.blocks)
    assert count_parameters(full) - count_parameters(ablated) == removed
    missing, unexpected = ablated.load_state_dict(full.state_dict(), strict=False)
    assert not missing and unexpected and all(f".{layer}." in key for key in unexpected)
    a, b = build.tokens(3, STEPS)
    text = build.text(3)
    assert not torch.allclose(
        full(a, b, text, LENGTHS).logits_a, ablated(a, b, text, LENGTHS).logits_a
    )


def test_every_block_is_the_identity_at_initialisation(build):
    torch.manual_seed(0)
    model = InterMTransformer(**build.config).eval()
    seen = []
    for block in model.blocks:
        block.register_forward_hook(lambda _m, args, out: seen.append(torch.equal(args[0], out)))
    a, b = build.tokens(3, STEPS)
    model(a, b, build.text(3), LENGTHS)
    assert seen == [True] * len(model.blocks)


def test_dropped_condition_is_the_learned_projection_bias(build):
    model = build.model()
    a, b = build.tokens(3, STEPS)
    drop = torch.ones(3, dtype=torch.bool)
    first = model(a, b, build.text(3, seed=1), LENGTHS, drop_condition=drop)
    second = model(a, b, build.text(3, seed=5), LENGTHS, drop_condition=drop)
    null = model.condition_projection.bias.expand(3, -1)
    expected = model.forward_with_condition(a, b, null, LENGTHS)
    for x, y, z in zip(first, second, expected, strict=True):
        torch.testing.assert_close(x, y)
        torch.testing.assert_close(x, z)


def test_condition_drop_acts_per_sample_and_only_through_c(build):
    model, text = build.model(), build.text(3)
    a, b = build.tokens(3, STEPS)
    drop = torch.tensor([True, False, False])
    kept = model(a, b, text, LENGTHS)
    dropped = model(a, b, text, LENGTHS, drop_condition=drop)
    via_c = model.forward_with_condition(a, b, model.encode_condition(text, drop), LENGTHS)
    torch.testing.assert_close(dropped.logits_a, via_c.logits_a)
    torch.testing.assert_close(dropped.logits_a[1:], kept.logits_a[1:])
    assert not torch.allclose(dropped.logits_a[0], kept.logits_a[0])


def test_text_feature_at_the_eot_token_drives_the_condition(build):
    model = build.model()
    text = build.text(2)._replace(eot_index=torch.tensor([3, 5]))
    padding = torch.zeros(2, 7, dtype=torch.bool)
    padding[:, 6] = True
    c = model.encode_condition(TextFeatures(text.features, text.eot_index, padding))
    changed = text.features.clone()
    changed[:, 6] += 5.0  # a padded text token
    assert torch.allclose(c, model.encode_condition(TextFeatures(changed, text.eot_index, padding)))
    other_eot = model.encode_condition(
        TextFeatures(text.features, (text.eot_index + 1) % 6, padding)
    )
    assert not torch.allclose(c, other_eot)


def test_gradients_reach_every_parameter(build):
    model = build.model().train()
    a, b = build.tokens(3, STEPS)
    out = model(a, b, build.text(3), LENGTHS)
    (out.logits_a.logsumexp(-1).mean() + out.logits_b.logsumexp(-1).mean()).backward()
    for name, parameter in model.named_parameters():
        assert parameter.grad is not None and torch.isfinite(parameter.grad).all(), name


def test_one_row_token_maps_work_for_the_1d_ablation(build):
    model = build.model(rows=1)
    tokens = torch.randint(0, 16, (2, 1, STEPS))
    out = model(tokens, tokens.flip(0), build.text(2), torch.tensor([6, 2]))
    assert out.logits_a.shape == (2, 1, STEPS, 16)


def test_invalid_inputs_raise_with_evidence(build):
    model = build.model()
    a, b = build.tokens(3, STEPS)
    text = build.text(3)
    with pytest.raises(ValueError, match=r"\(B, 5, T'\), got \(3, 4, 6\)"):
        model(a[:, :4], b[:, :4], text, LENGTHS)
    with pytest.raises(ValueError, match=r"\(B, L, 40\), got \(3, 7, 39\)"):
        model(a, b, (text.features[..., :39], text.eot_index), LENGTHS)
    with pytest.raises(ValueError, match=r"drop_condition must be \(3,\)"):
        model(a, b, text, LENGTHS, drop_condition=torch.ones(2, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"lengths_in_steps must lie in \[0, 6\]"):
        model(a, b, text, torch.tensor([7, 1, 1]))
    with pytest.raises(ValueError, match="divisible by 4"):
        InterMTransformer(**{**build.config, "width": 30, "heads": 3})


def test_text_attends_padding_is_the_references_switch(build):
    """Default (paper reading): the positions after end-of-text are masked in the text layers,
    so changing them changes nothing; with the reference's switch they change the condition."""
    from intermask.text.clip_encoder import padding_mask_from_eot

    base = build.text(2)
    padding = padding_mask_from_eot(base.eot_index, base.features.shape[1])
    text = TextFeatures(base.features, base.eot_index, padding)
    changed = base.features.clone()
    changed[padding] += 1.0  # only what lies after [EOT]
    other = TextFeatures(changed, base.eot_index, padding)
    paper = build.model()
    reference = build.model(text_attends_padding=True)
    assert not paper.text_attends_padding and reference.text_attends_padding
    torch.testing.assert_close(paper.encode_condition(text), paper.encode_condition(other))
    assert not torch.allclose(reference.encode_condition(text), reference.encode_condition(other))


def test_code_vectors_add_each_codes_codebook_vector_to_its_input(build):
    plain = build.model()
    assert plain.code_dim is None and plain.code_projection is None
    assert "code_vectors" not in plain.state_dict()
    model = build.model(code_dim=6)
    codebook = torch.randn(16, 6, generator=torch.Generator().manual_seed(3)) * 4.0
    model.set_code_vectors(codebook)
    rms = codebook.pow(2).mean().sqrt()
    torch.testing.assert_close(model.code_vectors[:16], codebook / rms)
    assert float(model.code_vectors[:16].pow(2).mean()) == pytest.approx(1.0, rel=1e-5)
    assert not model.code_vectors[16:].any()  # [MASK], [PAD], [SEP] carry no vector
    assert "code_vectors" in model.state_dict()  # saved with the weights, loaded strictly
    a, b = build.tokens(2, 3)
    text, lengths = build.text(2), torch.tensor([3, 2])
    before = model(a, b, text, lengths).logits_a
    model.set_code_vectors(codebook.flip(0))  # other vectors for the same codes: other logits
    after = model(a, b, text, lengths).logits_a
    assert not torch.allclose(before, after, atol=1e-4)
    # an all-[MASK] input sees no code vector at all
    masked = torch.full_like(a, 16)
    first = model(masked, masked, text, lengths).logits_a
    model.set_code_vectors(codebook)
    torch.testing.assert_close(model(masked, masked, text, lengths).logits_a, first)


def test_code_vectors_refuse_what_they_cannot_use(build):
    with pytest.raises(ValueError, match="code_dim must be None or positive, got 0"):
        build.model(code_dim=0)
    with pytest.raises(ValueError, match="set_code_vectors needs a network built with code_dim"):
        build.model().set_code_vectors(torch.ones(16, 6))
    model = build.model(code_dim=6)
    with pytest.raises(ValueError, match=r"must be \(16, 6\) \(codes x code_dim\), got \(16, 5\)"):
        model.set_code_vectors(torch.ones(16, 5))
    with pytest.raises(ValueError, match=r"the codebook has no usable scale \(RMS 0.0\)"):
        model.set_code_vectors(torch.zeros(16, 6))
