"""Every documented InterHuman data error names the file and the problem."""

import json

import numpy as np
import pytest
from builders import write_interhuman

from intermask.data.errors import DataError
from intermask.data.interhuman import InterHumanDataset


@pytest.fixture
def root(tmp_path):
    write_interhuman(tmp_path, splits={"train": (20, 25), "val": (20,), "test": (20,)}, meta=True)
    return tmp_path


def load(root, split="train"):
    return InterHumanDataset(root=root, split=split)


def test_missing_root(tmp_path):
    with pytest.raises(DataError, match=r"nowhere: dataset root not found"):
        load(tmp_path / "nowhere")


def test_missing_split_file(root):
    (root / "split" / "val.txt").unlink()
    with pytest.raises(DataError, match=r"split/val.txt: val split file not found"):
        load(root, "val")


def test_empty_split(root):
    (root / "split" / "test.txt").write_text("\n  \n")
    with pytest.raises(DataError, match=r"split/test.txt: split resolves to zero clips \(0 listed"):
        load(root, "test")


def test_split_of_ignored_clips_is_empty(root):
    (root / "ignore_list.txt").write_text("2\n")
    with pytest.raises(
        DataError, match=r"split/val.txt: split resolves to zero clips \(1 listed, 1 skipped"
    ):
        load(root, "val")


def test_wrong_shape(root):
    np.save(root / "motions_processed/person1/1.npy", np.zeros((25, 491), dtype=np.float32))
    with pytest.raises(
        DataError, match=r"person1/1.npy: expected shape \(T, 492\), got \(25, 491\)"
    ):
        load(root)


def test_nan_values(root):
    raw = np.load(root / "motions_processed/person2/0.npy")
    raw[3, 5] = np.nan
    raw[7, 200] = np.inf
    np.save(root / "motions_processed/person2/0.npy", raw)
    with pytest.raises(
        DataError,
        match=r"person2/0.npy: 2 NaN/Inf values in the body columns \(first bad frames \[3, 7\]\)",
    ):
        load(root)


def test_unreadable_npy(root):
    (root / "motions_processed/person1/0.npy").write_bytes(b"garbage")
    with pytest.raises(DataError, match=r"person1/0.npy: cannot read as .npy"):
        load(root)


def test_integer_dtype(root):
    np.save(root / "motions_processed/person1/0.npy", np.zeros((20, 492), dtype=np.int32))
    with pytest.raises(DataError, match=r"person1/0.npy: expected a float array, got dtype int32"):
        load(root)


def test_missing_person2(root):
    (root / "motions_processed/person2/1.npy").unlink()
    with pytest.raises(DataError, match=r"person2/1.npy: motion file not found"):
        load(root)


def test_frame_count_mismatch(root):
    raw = np.load(root / "motions_processed/person2/1.npy")
    np.save(root / "motions_processed/person2/1.npy", raw[:-2])
    with pytest.raises(DataError, match=r"person2/1.npy: expected 25 frames like person1, got 23"):
        load(root)


def test_missing_caption_file(root):
    (root / "annots/0.txt").unlink()
    with pytest.raises(DataError, match=r"annots/0.txt: caption file not found"):
        load(root)


def test_empty_caption_file(root):
    (root / "annots/1.txt").write_text("\n \n")
    with pytest.raises(DataError, match=r"annots/1.txt: caption file is empty"):
        load(root)


def test_meta_without_the_clip(root):
    meta = json.loads((root / "interaction_meta.json").read_text())
    del meta["clips"]["1"]
    (root / "interaction_meta.json").write_text(json.dumps(meta))
    with pytest.raises(DataError, match=r"interaction_meta.json: no entry for clip '1'"):
        load(root)


def test_malformed_meta(root):
    (root / "interaction_meta.json").write_text('{"clips": [1, 2]}')
    with pytest.raises(DataError, match=r"interaction_meta.json: malformed interaction meta"):
        load(root)
