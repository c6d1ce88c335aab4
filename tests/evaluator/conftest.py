"""Fixtures of the evaluator tests (helpers live in evaluator_builders)."""

from __future__ import annotations

import pytest
from evaluator_builders import tiny_gru, tiny_interclip

from intermask.evaluator import GRUMatcher, InterCLIP
from intermask.text import TINY_MODEL_NAME


@pytest.fixture
def interclip() -> InterCLIP:
    return tiny_interclip()


@pytest.fixture
def gru() -> GRUMatcher:
    return tiny_gru()


@pytest.fixture(scope="session")
def tiny_text_encoder():
    from intermask.text import FrozenCLIPTextEncoder

    return FrozenCLIPTextEncoder(model_name=TINY_MODEL_NAME, pretrained=None, seed=0)
