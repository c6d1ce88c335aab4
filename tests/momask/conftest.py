"""Fixtures of the MoMask tests (builders in momask_tiny.py)."""

from __future__ import annotations

from functools import partial

import pytest
import torch


@pytest.fixture(scope="session")
def text_cache():
    """The tiny random text tower of configs/text/tiny_random.yaml, memory cache only."""
    from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder
    from intermask.text.cache import TextFeatureCache

    encoder = FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=None, seed=0)
    return TextFeatureCache(encoder=encoder, cache_dir=None)


@pytest.fixture
def optimizer():
    return partial(torch.optim.AdamW, lr=2e-4, betas=(0.9, 0.99))
