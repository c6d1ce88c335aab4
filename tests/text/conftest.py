"""A tiny random CLIP text tower, built once: nothing here downloads weights."""

from __future__ import annotations

import pytest

from intermask.text import TINY_MODEL_NAME, FrozenCLIPTextEncoder


@pytest.fixture(scope="session")
def tiny_encoder() -> FrozenCLIPTextEncoder:
    return FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=None, seed=0)
