"""The fused and shortcut paths of the Inter-M forward give the plain formulas' results: the
forward within 1e-5 in fp32, and a seeded generation the same tokens (issue: speed without
changing results)."""

from __future__ import annotations

import pytest
import torch

from intermask.interm import blocks, model
from intermask.interm.decoding import generate


def _plain_modulate(x, shift, scale):
    return x * (1 + scale[:, None, :]) + shift[:, None, :]


def _plain_gated(x, gate, h):
    return x + gate[:, None, :] * h


@pytest.fixture
def plain(monkeypatch):
    """Switch the block's fused elementwise helpers to the plain formulas."""

    def switch() -> None:
        monkeypatch.setattr(blocks, "modulate", _plain_modulate)
        monkeypatch.setattr(model, "modulate", _plain_modulate)  # the output head's
        monkeypatch.setattr(blocks, "gated", _plain_gated)

    return switch


def test_fused_helpers_equal_the_formulas():
    generator = torch.Generator().manual_seed(0)
    x, h = torch.randn(2, 2, 7, 8, generator=generator)
    shift, scale, gate = torch.randn(3, 2, 8, generator=generator)
    torch.testing.assert_close(blocks.modulate(x, shift, scale), _plain_modulate(x, shift, scale))
    torch.testing.assert_close(blocks.gated(x, gate, h), _plain_gated(x, gate, h))


@pytest.mark.parametrize("lengths", [[6, 6, 6], [6, 3, 5]], ids=["full", "padded"])
def test_the_forward_equals_the_plain_one(build, plain, lengths):
    net = build.model()
    text = build.text(3)
    tokens_a, tokens_b = build.tokens(3, 6)
    steps = torch.tensor(lengths)
    fast = net(tokens_a, tokens_b, text, steps)
    plain()
    reference = net(tokens_a, tokens_b, text, steps)
    for ours, theirs in zip(fast, reference, strict=True):
        torch.testing.assert_close(ours, theirs, rtol=1e-5, atol=1e-5)


def test_a_seeded_generation_returns_the_same_tokens(build, plain):
    net, text, lengths = build.model(), build.text(3), torch.tensor([6, 3, 5])
    fast = generate(net, text, lengths, iterations=4, seeds=[0, 1, 2])
    plain()
    reference = generate(net, text, lengths, iterations=4, seeds=[0, 1, 2])
    assert torch.equal(fast, reference)
