"""Shared fixtures: small synthetic datasets in both official layouts (built once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

SMALL_DATASET_CLIPS = 48


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if torch.cuda.is_available():
        return
    skip_gpu = pytest.mark.skip(reason="needs a CUDA device")
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip_gpu)


@pytest.fixture(scope="session")
def synthetic_interhuman_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from intermask.data.synthetic import generate_dataset

    root = tmp_path_factory.mktemp("synthetic") / "interhuman"
    generate_dataset(root, format="interhuman", clips=SMALL_DATASET_CLIPS, seed=7)
    return root


@pytest.fixture(scope="session")
def synthetic_interx_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from intermask.data.synthetic import generate_dataset

    root = tmp_path_factory.mktemp("synthetic") / "interx"
    generate_dataset(root, format="interx", clips=SMALL_DATASET_CLIPS, seed=7)
    return root
