import json
import logging
import pickle

import h5py
import numpy as np
import pytest
import torch
from builders import CAPTIONS, write_interx
from payloads import ExecPayload

from intermask.data.errors import DataError
from intermask.data.interx import InterXDataset
from intermask.data.normalization import Normalizer
from intermask.data.validation import check_dataset
from intermask.data.windows import window_count
from intermask.motion.rotations import axis_angle_to_rot6d

SPLITS = {"train": (23, 24, 60, 200, 999, 1000), "val": (30, 44), "test": (40,)}


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("interx")
    write_interx(root, splits=SPLITS)
    return root


@pytest.fixture(scope="module")
def train(root):
    return InterXDataset(root=root, split="train")


def raw_clip(root, split, name):
    with h5py.File(root / "motions" / f"{split}.h5", "r") as f:
        return f[name][()]


def test_length_filter_and_skip_list(train, root, caplog):
    assert list(train.frames) == [24, 60, 200, 999]
    assert [s.reason for s in train.skipped] == [
        "23 frames, outside [24, 1000)",
        "1000 frames, outside [24, 1000)",
    ]
    with caplog.at_level(logging.INFO, logger="intermask.data"):
        InterXDataset(root=root, split="train")
    assert "skipped 2 clips" in caplog.text


def test_shapes_and_lengths(train):
    expected = {24: {20, 24}, 60: {56, 60}, 200: {148}, 999: {148}}
    for clip, frames in enumerate(train.frames):
        seen = set()
        for epoch in range(30):
            item = train[(clip, epoch)]
            length = item["length"]
            assert item["motion"].shape == (2, 150, 56, 6)
            assert length % 4 == 0 and 20 <= length <= 148
            assert torch.all(item["motion"][:, length:] == 0)
            seen.add(length)
        assert seen == expected[int(frames)]


def test_no_length_jitter(root):
    ds = InterXDataset(root=root, split="train", length_jitter=False)
    assert {ds[(1, e)]["length"] for e in range(20)} == {60}
    assert {ds[(0, e)]["length"] for e in range(20)} == {24}


def test_representation_matches_the_raw_crop(root, train):
    clip = train.clip_ids.index(train.clip_ids[1])  # 60 frames
    raw = torch.from_numpy(raw_clip(root, "train", train.clip_ids[clip]))
    item = train[(clip, 0)]
    length = item["length"]
    motion = item["motion"][:, :length]
    starts = [
        s
        for s in range(0, 60 - length + 1)
        if torch.allclose(motion[0, :, 55, :3], raw[s : s + length, 55, :3])
    ]
    assert len(starts) == 1
    crop = raw[starts[0] : starts[0] + length]
    for p in range(2):
        rows = crop[:, :55, 3 * p : 3 * p + 3]
        assert torch.allclose(motion[p, :, :55], axis_angle_to_rot6d(rows), atol=1e-6)
        trans = crop[:, 55, 3 * p : 3 * p + 3]
        assert torch.allclose(motion[p, :, 55, :3], trans)
        assert torch.allclose(motion[p, :-1, 55, 3:], trans[1:] - trans[:-1], atol=1e-6)
        assert torch.all(motion[p, -1, 55, 3:] == 0)  # last frame velocity is 0


def test_random_crop_vs_reference_start_crop(root):
    random_crop = InterXDataset(root=root, split="train", length_jitter=False)
    start_crop = InterXDataset(root=root, split="train", length_jitter=False, crop="start")
    clip = 3  # 999 frames -> 148
    raw = torch.from_numpy(raw_clip(root, "train", random_crop.clip_ids[clip]))

    def start_of(item):
        trans = item["motion"][0, :148, 55, :3]
        return next(
            s for s in range(999 - 148 + 1) if torch.allclose(trans, raw[s : s + 148, 55, :3])
        )

    random_starts = {start_of(random_crop[(clip, e)]) for e in range(10)}
    reference_starts = {start_of(start_crop[(clip, e)]) for e in range(10)}
    assert len(random_starts) > 5 and max(random_starts) > 100
    assert reference_starts <= {0, 1, 2, 3}  # reference: the beginning of the clip


def test_captions_tokens_and_reproducibility(root, train):
    items = [train[(2, e)] for e in range(30)]
    assert {it["caption"] for it in items} == set(CAPTIONS)
    for it in items:
        words = it["caption"].split()
        assert it["tokens"] == " ".join(f"{w}/NOUN" for w in words)
    again = InterXDataset(root=root, split="train")
    assert torch.equal(again[(2, 5)]["motion"], train[(2, 5)]["motion"])


def test_action_and_actor(root, train):
    for clip, name in enumerate(train.clip_ids):
        item = train[clip]
        assert item["action_id"] == int(name[9:12]) and item["action"] == name[8:12]
        assert item["persons"].tolist() == [1, 2]  # no person swap by default for Inter-X
    order = pickle.loads((root / "annots" / "interaction_order.pkl").read_bytes())
    swapping = InterXDataset(root=root, split="train", swap_persons=True)
    seen = set()
    for epoch in range(20):
        item = swapping[(1, epoch)]
        persons = item["persons"].tolist()
        seen.add(tuple(persons))
        assert item["actor"] == persons.index(order[item["id"]] + 1) + 1
    assert seen == {(1, 2), (2, 1)}


def test_swap_exchanges_persons(root):
    plain = InterXDataset(root=root, split="val", length_jitter=False)
    swapping = InterXDataset(root=root, split="val", length_jitter=False, swap_persons=True)
    seen = set()
    for epoch in range(8):
        seen.add(tuple(swapping[(1, epoch)]["persons"].tolist()))
        a, b = plain[(1, epoch)], swapping[(1, epoch)]
        expected = a["motion"].flip(0) if b["persons"].tolist() == [2, 1] else a["motion"]
        assert b["length"] == a["length"] and torch.equal(b["motion"], expected)
    assert seen == {(1, 2), (2, 1)}


def test_meta_file_overrides_names(tmp_path):
    write_interx(
        tmp_path, splits={"train": (40,), "val": (40,), "test": (40,)}, meta=True, order=False
    )
    item = InterXDataset(root=tmp_path, split="val")[0]
    meta = json.loads((tmp_path / "interaction_meta.json").read_text())["clips"][item["id"]]
    assert (item["action"], item["action_id"], item["actor"]) == (
        meta["action"],
        meta["action_id"],
        meta["actor"],
    )


def test_no_side_files_no_actor(tmp_path):
    write_interx(tmp_path, splits={"train": (40,), "val": (40,), "test": (40,)}, order=False)
    item = InterXDataset(root=tmp_path, split="train")[0]
    assert "actor" not in item and item["action_id"] == 0


def test_normalizer(root, train):
    rng = np.random.default_rng(0)
    norm = Normalizer(rng.normal(size=(56, 6)), rng.uniform(0.5, 2.0, size=(56, 6)))
    ds = InterXDataset(root=root, split="train", normalizer=norm)
    a, b = train[(1, 2)], ds[(1, 2)]
    length = a["length"]
    assert torch.allclose(
        norm.denormalize(b["motion"][:, :length]), a["motion"][:, :length], atol=1e-5
    )
    assert torch.all(b["motion"][:, length:] == 0)


def test_window_mode(root, train):
    ds = InterXDataset(root=root, split="train", mode="window")
    assert len(ds) == 2 * sum(window_count(int(n), window=64, stride=10) for n in train.frames)
    item = ds[len(ds) - 1]
    assert item["motion"].shape == (64, 56, 6) and item["person"] == 2
    clip = train.clip_ids.index(item["id"])
    expected = train.clip_features(clip, start=item["start"], frames=64)[1]
    assert torch.equal(item["motion"], expected)
    assert torch.all(item["motion"][-1, 55, 3:] == 0)


@pytest.fixture
def small(tmp_path):
    write_interx(tmp_path, splits={"train": (30, 40), "val": (30,), "test": (30,)})
    return tmp_path


def first_name(root, split="train"):
    return (root / "splits" / f"{split}.txt").read_text().split()[0]


def test_error_missing_root(tmp_path):
    with pytest.raises(DataError, match=r"nope: dataset root not found"):
        InterXDataset(root=tmp_path / "nope", split="train")


def test_error_missing_split(small):
    (small / "splits" / "val.txt").unlink()
    with pytest.raises(DataError, match=r"splits/val.txt: val split file not found"):
        InterXDataset(root=small, split="val")


def test_error_empty_split(small):
    (small / "splits" / "val.txt").write_text("")
    with pytest.raises(DataError, match=r"splits/val.txt: split resolves to zero clips"):
        InterXDataset(root=small, split="val")


def test_error_missing_h5(small):
    (small / "motions" / "test.h5").unlink()
    with pytest.raises(DataError, match=r"motions/test.h5: motion file not found"):
        InterXDataset(root=small, split="test")


def test_error_unreadable_h5(small):
    (small / "motions" / "test.h5").write_bytes(b"not hdf5")
    with pytest.raises(DataError, match=r"motions/test.h5: cannot open as HDF5"):
        InterXDataset(root=small, split="test")


def test_error_missing_h5_key(small):
    (small / "splits" / "train.txt").write_text("G999T999A001R000\n")
    with pytest.raises(DataError, match=r"motions/train.h5: no dataset named 'G999T999A001R000'"):
        InterXDataset(root=small, split="train")


@pytest.mark.parametrize(
    ("data", "match"),
    [
        (
            np.zeros((30, 55, 6), np.float32),
            r"train.h5\[{name}\]: expected shape \(T, 56, 6\), got \(30, 55, 6\)",
        ),
        (np.full((30, 56, 6), np.nan, np.float32), r"train.h5\[{name}\]: 10080 NaN/Inf values"),
    ],
)
def test_error_bad_clip(small, data, match):
    name = first_name(small)
    with h5py.File(small / "motions" / "train.h5", "a") as f:
        del f[name]
        f.create_dataset(name, data=data)
    with pytest.raises(DataError, match=match.format(name=name)):
        InterXDataset(root=small, split="train")


def test_error_captions(small):
    name = first_name(small)
    (small / "texts_processed" / f"{name}.txt").unlink()
    with pytest.raises(DataError, match=rf"texts_processed/{name}.txt: caption file not found"):
        InterXDataset(root=small, split="train")
    (small / "texts_processed" / f"{name}.txt").write_text("\n")
    with pytest.raises(DataError, match=rf"{name}.txt: caption file is empty"):
        InterXDataset(root=small, split="train")
    (small / "texts_processed" / f"{name}.txt").write_text("a caption without tokens\n")
    with pytest.raises(DataError, match=rf"{name}.txt: line 1: expected 'caption#tok/POS"):
        InterXDataset(root=small, split="train")
    (small / "texts_processed" / f"{name}.txt").write_text("a b#a/DET b/NOUN#1.5#3.0\n")
    with pytest.raises(
        DataError, match=rf"{name}.txt: line 1: time-tagged captions are not supported"
    ):
        InterXDataset(root=small, split="train")


def test_error_bad_order_file(small):
    (small / "annots" / "interaction_order.pkl").write_bytes(b"nonsense")
    with pytest.raises(DataError, match=r"interaction_order.pkl: expected a pickled dict"):
        InterXDataset(root=small, split="train")


def test_invalid_arguments(small):
    with pytest.raises(ValueError, match="crop must be"):
        InterXDataset(root=small, split="train", crop="middle")
    with pytest.raises(ValueError, match=r"normalizer must have shape \(56, 6\)"):
        InterXDataset(root=small, split="train", normalizer=Normalizer.identity((262,)))


def test_a_payload_in_the_order_file_is_refused_without_running(small, tmp_path_factory):
    marker = tmp_path_factory.mktemp("payload") / "marker"
    order_file = small / "annots" / "interaction_order.pkl"
    order_file.write_bytes(pickle.dumps({"G001T000A000R000": ExecPayload(marker)}))
    with pytest.raises(DataError) as refused:
        InterXDataset(root=small, split="train")
    assert str(order_file) in str(refused.value)
    assert "refusing to load builtins.exec" in str(refused.value)
    problems = [str(p) for p in check_dataset(small, "interx")]  # `intermask data check`
    assert any(str(order_file) in p and "builtins.exec" in p for p in problems), problems
    assert not marker.exists()


def test_numpy_values_in_the_order_file_still_read(small):
    order_file = small / "annots" / "interaction_order.pkl"
    order = pickle.loads(order_file.read_bytes())
    order_file.write_bytes(pickle.dumps({k: np.int64(v) for k, v in order.items()}))
    dataset = InterXDataset(root=small, split="train")
    assert len(dataset) > 0
