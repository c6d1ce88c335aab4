"""The graphed forward off a GPU, the ``forward`` hook of the decoding, and the token checks a
CUDA graph capture skips (the capture itself: tests/test_gpu.py)."""

from __future__ import annotations

import pytest
import torch

from intermask.interm.decoding import generate
from intermask.interm.graphs import GraphedForward
from intermask.interm.tokens import build_sequence, step_padding_mask, unchecked_tokens

LENGTHS = torch.tensor([6, 3, 5])


def test_off_a_gpu_the_graphed_forward_is_the_eager_one_and_captures_nothing(build):
    model, text = build.model(), build.text(3)
    graphed = GraphedForward(model)
    tokens_a, tokens_b = build.tokens(3, 6)
    condition = model.encode_condition(text)
    with torch.no_grad():
        eager = model.forward_with_condition(tokens_a, tokens_b, condition, LENGTHS)
        out = graphed(tokens_a, tokens_b, condition, LENGTHS)
    assert all(torch.equal(x, y) for x, y in zip(out, eager, strict=True))
    assert graphed.captured == 0 and graphed.failure is None
    plain = generate(model, text, LENGTHS, iterations=3, seeds=[0, 1, 2])
    graphed_tokens = generate(model, text, LENGTHS, iterations=3, seeds=[0, 1, 2], forward=graphed)
    assert torch.equal(graphed_tokens, plain)


def test_generate_runs_every_collaborative_pass_through_the_given_forward(build):
    model, text = build.model(), build.text(3)
    calls = []

    def forward(a, b, condition, lengths):
        calls.append(a.shape[0])
        return model.forward_with_condition(a, b, condition, lengths)

    kwargs = {"iterations": 3, "seeds": [0, 1, 2]}
    plain = generate(model, text, LENGTHS, **kwargs)
    assert torch.equal(generate(model, text, LENGTHS, forward=forward, **kwargs), plain)
    assert calls == [6] * 3  # conditional and null stacked: 2B a pass
    calls.clear()
    # in turn with partner guidance: A's turn doubled, B's turn and A's revisit tripled
    turns = {"persons": "in_turn", "revisits": 1, "partner_scale": 1.0}
    plain = generate(model, text, LENGTHS, **turns, **kwargs)
    assert torch.equal(generate(model, text, LENGTHS, forward=forward, **turns, **kwargs), plain)
    assert calls == [6] * 3 + [9] * 6


def test_unchecked_tokens_skips_the_value_checks_only_inside_the_block():
    bad = torch.full((1, 5, 2), 99)
    with pytest.raises(ValueError, match=r"tokens must be -1, a code in \[0, 16\)"):
        build_sequence(bad, bad, codebook_size=16)
    with pytest.raises(ValueError, match=r"lengths_in_steps must lie in \[0, 2\], got \[3\]"):
        step_padding_mask(torch.tensor([3]), 2)
    with unchecked_tokens():
        assert build_sequence(bad, bad, codebook_size=16).shape == (1, 21)
        assert step_padding_mask(torch.tensor([3]), 2).tolist() == [[False, False]]
        with pytest.raises(ValueError, match="must both be"):  # shapes are still checked
            build_sequence(bad, bad[:, :4], codebook_size=16)
    with pytest.raises(RuntimeError, match="boom"), unchecked_tokens():
        raise RuntimeError("boom")
    with pytest.raises(ValueError, match="tokens must be -1"):  # restored after an error too
        build_sequence(bad, bad, codebook_size=16)
