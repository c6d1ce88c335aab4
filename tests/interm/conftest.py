"""Tiny Inter-M configuration and a helper that makes AdaLN-Zero blocks non-trivial."""

from __future__ import annotations

import pytest
import torch

from intermask.interm.blocks import AdaLNModulation
from intermask.interm.model import InterMTransformer, TextFeatures

TINY = {
    "codebook_size": 16,
    "width": 32,
    "heads": 4,
    "depth": 2,
    "ff": 48,
    "dropout": 0.0,
    "token_embed_dim": 24,
    "text_dim": 40,
    "text_layers": 1,
    "text_heads": 4,
    "text_ff": 56,
    "text_dropout": 0.0,
    "rows": 5,
}


def randomize_modulation(model: torch.nn.Module, seed: int = 0) -> None:
    """Give every AdaLN regressor random weights; at zero init every block is the identity and
    most invariance tests would pass trivially."""
    generator = torch.Generator().manual_seed(seed)
    for module in model.modules():
        if isinstance(module, AdaLNModulation):
            with torch.no_grad():
                weight = module.linear.weight
                weight.copy_(torch.randn(weight.shape, generator=generator) * 0.3)
                module.linear.bias.copy_(
                    torch.randn(module.linear.bias.shape, generator=generator) * 0.3
                )


def make_model(seed: int = 0, **overrides: object) -> InterMTransformer:
    torch.manual_seed(seed)
    model = InterMTransformer(**{**TINY, **overrides})
    randomize_modulation(model, seed)
    return model.eval()


def make_text(batch: int, length: int = 7, seed: int = 1) -> TextFeatures:
    generator = torch.Generator().manual_seed(seed)
    features = torch.randn(batch, length, TINY["text_dim"], generator=generator)
    eot = torch.randint(1, length, (batch,), generator=generator)
    return TextFeatures(features, eot)


def make_tokens(batch: int, steps: int, seed: int = 2) -> tuple[torch.Tensor, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    high = TINY["codebook_size"] + 1  # codes and [MASK]
    shape = (batch, TINY["rows"], steps)
    return (
        torch.randint(0, high, shape, generator=generator),
        torch.randint(0, high, shape, generator=generator),
    )


@pytest.fixture
def model() -> InterMTransformer:
    return make_model()


@pytest.fixture
def randomize():
    return randomize_modulation


@pytest.fixture
def build():
    """Factories for tiny models and inputs: ``build.model``, ``build.text``, ``build.tokens``."""

    class Factories:
        config = TINY
        model = staticmethod(make_model)
        text = staticmethod(make_text)
        tokens = staticmethod(make_tokens)

    return Factories
