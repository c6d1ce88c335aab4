"""The readers on the embedded synthetic dataset (runs once helper S's generator is present)."""

import importlib

import pytest
import torch

from intermask.data.datamodule import InteractionDataModule
from intermask.data.interhuman import InterHumanDataset
from intermask.data.interx import InterXDataset
from intermask.data.validation import check_dataset
from intermask.motion.skeleton import FACE_JOINTS

generate_dataset = getattr(
    importlib.import_module("intermask.data.synthetic"), "generate_dataset", None
)
pytestmark = pytest.mark.skipif(
    generate_dataset is None, reason="synthetic generator not available"
)


@pytest.fixture(scope="module")
def ih_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("synthetic") / "interhuman"
    generate_dataset(root, format="interhuman", clips=20, seed=0)
    return root


@pytest.fixture(scope="module")
def ix_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("synthetic") / "interx"
    generate_dataset(root, format="interx", clips=20, seed=0)
    return root


def test_synthetic_interhuman_is_valid_and_canonical(ih_root):
    assert check_dataset(ih_root, "interhuman") == []
    ds = InterHumanDataset(root=ih_root, split="train", swap_persons=False)
    for index in range(len(ds)):
        item = ds[index]
        length = item["length"]
        assert item["motion"].shape == (2, 300, 262) and 14 <= length <= 299
        feats = item["motion"][:, :length]
        pos = feats[..., :66].reshape(2, length, 22, 3)
        vel = feats[..., 66:132].reshape(2, length, 22, 3)
        assert pos[0, 0, 0, [0, 2]].abs().max() < 1e-5
        across = pos[0, 0, FACE_JOINTS[0]] - pos[0, 0, FACE_JOINTS[1]]
        assert across[0] < 0 and abs(across[2]) < 1e-5  # facing +Z
        assert pos[..., 1].amin(dim=(1, 2)).abs().max() < 0.05  # both on the floor
        assert torch.allclose(vel[:, :-1], pos[:, 1:] - pos[:, :-1], atol=1e-5)
        assert {"action", "action_id", "actor"} <= item.keys() and item["actor"] in (1, 2)


def test_synthetic_interhuman_datamodule(ih_root):
    dm = InteractionDataModule(dataset="interhuman", root=str(ih_root), batch_size=4)
    dm.prepare_data()
    dm.setup("fit")
    batch = next(iter(dm.train_dataloader()))
    assert batch["motion"].shape == (4, 2, 300, 262)
    assert len(set(dm.datasets["train"].captions[0])) == 3
    window = InteractionDataModule(
        dataset="interhuman", root=str(ih_root), batch_size=4, mode="window"
    )
    assert next(iter(window.train_dataloader()))["motion"].shape == (4, 64, 262)


def test_synthetic_interx(ix_root):
    assert check_dataset(ix_root, "interx") == []
    ds = InterXDataset(root=ix_root, split="train")
    for index in range(len(ds)):
        item = ds[index]
        assert item["motion"].shape == (2, 150, 56, 6)
        assert item["length"] % 4 == 0 and 20 <= item["length"] <= 148
        assert item["actor"] in (1, 2) and 0 <= item["action_id"]
