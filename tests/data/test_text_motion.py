"""The tokenizer's windows over a HumanML3D-layout folder, and the single-person DataModule."""

import numpy as np
import pytest
import torch

from intermask.data.errors import DataError
from intermask.data.humanml3d import HumanML3DDataset, HumanML3DWindows
from intermask.data.text_motion import TextMotionDataModule
from tests.data.test_humanml3d import WHOLE, random_clip, write_dataset


@pytest.fixture
def folder(tmp_path):
    clips = {
        "000001": (random_clip(70, 1), [WHOLE]),  # 6 windows of 64 at stride 1
        "000002": (random_clip(64, 2), [WHOLE]),  # exactly 64 frames: none (the reference's rule)
        "000003": (random_clip(100, 3), [WHOLE]),  # 36 windows
        "000004": (random_clip(90, 4), [WHOLE]),
    }
    return write_dataset(
        tmp_path, clips, {"train": ["000001", "000002", "000003"], "val": ["000004"]}
    )


def test_windows_follow_the_reference_count_and_are_z_scored_slices(folder):
    windows = HumanML3DWindows(root=folder, split="train")
    assert len(windows) == 6 + 36 and windows.clip_ids == ["000001", "000003"]
    assert [(s.clip_id, s.reason) for s in windows.skipped] == [
        ("000002", "64 frames, no 64-frame window (needs 65)")
    ]
    mean, std = np.load(folder / "Mean.npy"), np.load(folder / "Std.npy")
    raw = np.load(folder / "new_joint_vecs" / "000003.npy")
    item = windows[6 + 35]  # the last window of the second clip: frames 35..99
    assert (item["id"], item["start"], item["length"]) == ("000003", 35, 64)
    np.testing.assert_allclose(item["motion"].numpy(), (raw[35:99] - mean) / std, atol=1e-5)
    assert windows[(0, 7)]["start"] == 0  # sampler keys (index, epoch) work; windows are fixed
    strided = HumanML3DWindows(root=folder, split="train", stride=4)
    assert len(strided) == 2 + 9 and [strided[i]["start"] for i in range(3)] == [0, 4, 0]
    with pytest.raises(IndexError, match="index 42 out of range for 42 windows"):
        windows[42]


def test_windows_errors_name_the_folder_and_the_rule(folder, tmp_path):
    with pytest.raises(DataError, match="no clip has a 128-frame window"):
        HumanML3DWindows(root=folder, split="train", window=128)
    with pytest.raises(DataError, match="dataset root not found"):
        HumanML3DWindows(root=tmp_path / "missing", split="train")
    with pytest.raises(ValueError, match="window and stride must be >= 1, got 64 and 0"):
        HumanML3DWindows(root=folder, split="train", stride=0)


def test_datamodule_serves_windows_or_items_with_the_release_statistics(folder):
    windows = TextMotionDataModule(root=str(folder), mode="window", batch_size=4)
    windows.setup("fit")
    assert isinstance(windows.datasets["train"], HumanML3DWindows)
    np.testing.assert_array_equal(windows.normalizer.mean.numpy(), np.load(folder / "Mean.npy"))
    batch = next(iter(windows.train_dataloader()))
    assert batch["motion"].shape == (4, 64, 263) and batch["length"].tolist() == [64] * 4
    items = TextMotionDataModule(root=str(folder), mode="item", batch_size=2)
    items.setup("fit")
    assert isinstance(items.datasets["val"], HumanML3DDataset)
    batch = next(iter(items.val_dataloader()))
    assert batch["motion"].shape == (1, 196, 263) and batch["caption"] == [
        "a person walks forward."
    ]
    # the same seed and epoch give the same pass
    first = next(iter(items.eval_dataloader("train", batch_size=2)))
    again = next(iter(items.eval_dataloader("train", batch_size=2)))
    assert first["id"] == again["id"]
    torch.testing.assert_close(first["motion"], again["motion"])


def test_datamodule_rejects_bad_settings(tmp_path):
    with pytest.raises(ValueError, match="mode must be 'window' or 'item', got 'interaction'"):
        TextMotionDataModule(root=str(tmp_path), mode="interaction")
    with pytest.raises(ValueError, match="dataset must be 'humanml3d', got 'kit'"):
        TextMotionDataModule(root=str(tmp_path), dataset="kit")
    missing = TextMotionDataModule(root=str(tmp_path / "nothing"))
    with pytest.raises(DataError, match="nothing: dataset root not found"):
        missing.setup("fit")
