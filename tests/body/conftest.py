"""A stand-in SMPL-X and SMPL-H model for the session (the licensed files are not available)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from intermask.body.model import BodyModel, load_body_model
from intermask.body.standin import write_standin_model


@pytest.fixture(scope="session")
def model_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("body_models")
    write_standin_model(folder, "smplx")
    write_standin_model(folder, "smplh")
    return folder


@pytest.fixture(scope="session")
def smplx_model(model_folder: Path) -> BodyModel:
    return load_body_model(model_folder / "SMPLX_NEUTRAL.npz", dtype=torch.float64)


@pytest.fixture(scope="session")
def smplh_model(model_folder: Path) -> BodyModel:
    return load_body_model(model_folder / "smplh" / "neutral" / "model.npz", dtype=torch.float64)
