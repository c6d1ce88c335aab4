"""Fixtures shared by the convert-reference tests."""

from __future__ import annotations

from pathlib import Path

import pytest
from fixtures_io import build_state, load_fixture
from intermask_release import CASES, write_release


@pytest.fixture(scope="module")
def release(tmp_path_factory) -> dict[str, Path]:
    """An Inter-X release: the tokenizer and the 6-head generator of the parity fixture."""
    fixture = load_fixture("intermask_models")
    root = tmp_path_factory.mktemp("release") / "checkpoints" / "interx"
    paths = {}
    for name, entry in (("vq_interx", "vq_model"), ("generator", "t2m_transformer")):
        state = build_state(fixture[name]["recipe"], seed=fixture["seed"])
        paths[name] = write_release(root / name, entry, state, CASES[name]["options"])
    return paths
