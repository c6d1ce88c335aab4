"""export_item (``intermask data item``): one clip, augmentation off, both formats."""

import numpy as np
import pytest
import torch
from builders import CAPTIONS, write_interhuman, write_interx

from intermask.data.errors import DataError
from intermask.data.interhuman import InterHumanDataset
from intermask.data.item import export_item
from intermask.motion.interx import interx_joint_positions


@pytest.fixture(scope="module")
def ih_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("item_ih")
    write_interhuman(root, splits={"train": (40, 350), "val": (30,), "test": (30,)})
    return root


def test_export_interhuman_item(ih_root, tmp_path):
    out = export_item(ih_root, "interhuman", "train", "1", tmp_path / "clip1")
    assert out.path == tmp_path / "clip1.npz" and out.path.is_file()
    data = np.load(out.path)
    assert data["features"].shape == (2, 349, 262)  # whole clip, no crop
    assert data["joints"].shape == (349, 2, 22, 3)
    assert (
        int(data["length"]) == 349
        and str(data["id"]) == "1"
        and str(data["format"]) == "interhuman"
    )
    assert data["captions"].tolist() == list(CAPTIONS)
    # Same features the dataset computes with augmentation off; joints are the position block.
    ds = InterHumanDataset(root=ih_root, split="train", swap_persons=False)
    expected = ds.clip_features(1).transpose(0, 1).numpy()
    assert np.allclose(data["features"], expected, atol=1e-6)
    assert np.allclose(data["joints"][:, 0], expected[0, :, :66].reshape(-1, 22, 3))
    assert np.abs(data["joints"][0, 0, 0, [0, 2]]).max() < 1e-5  # person 1 canonical


def test_export_interhuman_item_cropped(ih_root, tmp_path):
    out = export_item(ih_root, "interhuman", "train", "1", tmp_path / "c.npz", max_length=300)
    assert out.features.shape == (2, 299, 262) and out.length == 299


def test_export_errors(ih_root, tmp_path):
    with pytest.raises(DataError, match=r"split/val.txt: clip '1' is not in the val split"):
        export_item(ih_root, "interhuman", "val", "1", tmp_path / "x.npz")
    with pytest.raises(DataError, match=r"missing: dataset root not found"):
        export_item(tmp_path / "missing", "interhuman", "train", "1", tmp_path / "x.npz")
    with pytest.raises(ValueError, match="format must be"):
        export_item(ih_root, "amass", "train", "1", tmp_path / "x.npz")


def test_export_interx_item(tmp_path):
    ids = write_interx(tmp_path / "ix", splits={"train": (30,), "val": (30,), "test": (57,)})
    name = ids["test"][0]
    out = export_item(tmp_path / "ix", "interx", "test", name, tmp_path / "ix_item.npz")
    data = np.load(out.path)
    assert data["features"].shape == (2, 57, 56, 6)
    assert data["joints"].shape == (57, 2, 22, 3)
    assert data["captions"].tolist() == list(CAPTIONS)  # caption text only, no tokens
    expected = interx_joint_positions(torch.from_numpy(data["features"]))
    assert np.allclose(data["joints"], expected.numpy(), atol=1e-6)
