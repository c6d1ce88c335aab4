import logging

import numpy as np
import pytest
import torch
from builders import CAPTIONS, write_interhuman
from torch.utils.data import DataLoader

from intermask.data.captions import swap_left_right
from intermask.data.interhuman import InterHumanDataset
from intermask.data.normalization import Normalizer
from intermask.data.windows import window_count
from intermask.motion.interhuman import mirror_features, zup_to_yup
from intermask.motion.skeleton import FACE_JOINTS

SPLITS = {"train": (14, 15, 40, 300, 301, 420), "val": (30, 60), "test": (50,)}


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    root = tmp_path_factory.mktemp("interhuman")
    write_interhuman(root, splits=SPLITS, meta=True)
    return root


@pytest.fixture(scope="module")
def train(root):
    return InterHumanDataset(root=root, split="train", swap_persons=False)


def test_shapes_lengths_and_skip_list(train, caplog):
    # Clip "0" has 14 frames: below min_length 15, skipped explicitly.
    assert train.clip_ids == ["1", "2", "3", "4", "5"]
    assert [(s.clip_id, s.reason) for s in train.skipped] == [("0", "shorter than 15 frames")]
    lengths = [train[i]["length"] for i in range(len(train))]
    assert lengths == [14, 39, 299, 299, 299]
    for i in range(len(train)):
        item = train[i]
        assert item["motion"].shape == (2, 300, 262) and item["motion"].dtype == torch.float32
        assert torch.all(item["motion"][:, item["length"] :] == 0)
        assert item["motion"][:, : item["length"]].abs().sum(-1).min() > 0


def test_skip_list_is_logged(root, caplog):
    with caplog.at_level(logging.INFO, logger="intermask.data"):
        InterHumanDataset(root=root, split="train")
    assert "skipped 1 clips (1 x shorter than 15 frames)" in caplog.text


def test_canonical_properties_and_velocities(train):
    for i in range(len(train)):
        item = train[i]
        feats = item["motion"][:, : item["length"]]  # (2, L, 262), un-normalized
        pos = feats[..., :66].reshape(2, -1, 22, 3)
        vel = feats[..., 66:132].reshape(2, -1, 22, 3)
        # Person 1: frame-0 root at the origin in x and z, facing +Z (hips along -x), on the floor.
        assert pos[0, 0, 0, [0, 2]].abs().max() < 1e-5
        across = pos[0, 0, FACE_JOINTS[0]] - pos[0, 0, FACE_JOINTS[1]]
        assert across[0] < 0 and abs(across[2]) < 1e-5
        for p in range(2):
            assert -1e-5 < pos[p, ..., 1].min() < 0.1
        # Velocities are one-frame position differences, for both persons.
        assert torch.allclose(vel[:, :-1], pos[:, 1:] - pos[:, :-1], atol=1e-5)


def test_person2_relation_keeps_world_distances(root, train):
    # Horizontal root distance between the persons is the same as in the raw (world) data.
    clip = train.clip_ids.index("3")
    item = train[clip]
    pos = item["motion"][:, : item["length"], :66].reshape(2, -1, 22, 3)
    raw = [np.load(root / "motions_processed" / f"person{p}" / "3.npy") for p in (1, 2)]
    world = [zup_to_yup(torch.from_numpy(r[: item["length"], :66].reshape(-1, 22, 3))) for r in raw]
    dist_item = (pos[0, :, 0, [0, 2]] - pos[1, :, 0, [0, 2]]).norm(dim=-1)
    dist_world = (world[0][:, 0, [0, 2]] - world[1][:, 0, [0, 2]]).norm(dim=-1)
    assert torch.allclose(dist_item, dist_world, atol=1e-4)


def test_random_crop_and_captions_vary_by_epoch_and_are_reproducible(root):
    ds = InterHumanDataset(root=root, split="train", swap_persons=False)
    clip = ds.clip_ids.index("5")  # 420 frames: cropped to 300
    items = [ds[(clip, epoch)] for epoch in range(30)]
    assert {it["caption"] for it in items} == set(CAPTIONS)
    first_frames = {tuple(it["motion"][1, 0, :3].tolist()) for it in items}
    assert len(first_frames) > 5  # different crops -> different person-2 start positions
    again = InterHumanDataset(root=root, split="train", swap_persons=False)
    for epoch in (0, 7):
        a, b = ds[(clip, epoch)], again[(clip, epoch)]
        assert torch.equal(a["motion"], b["motion"]) and a["caption"] == b["caption"]
    assert torch.equal(ds[clip]["motion"], ds[(clip, 0)]["motion"])  # plain index = epoch 0


def test_crop_is_a_window_of_the_clip(train):
    clip = train.clip_ids.index("5")
    full = train.clip_features(clip)  # (419, 2, 262)
    item = train[(clip, 3)]
    crop = item["motion"][0, :299]
    # Positions are re-canonicalized on the crop; contacts and rotations are not: find the offset.
    rot = full[:, 0, 132:258]
    starts = [s for s in range(0, 121) if torch.allclose(rot[s : s + 299], crop[:, 132:258])]
    assert len(starts) == 1


def test_person_swaps_track_reference_and_actor(root):
    ds = InterHumanDataset(root=root, split="train", swap_persons=True)
    clip = ds.clip_ids.index("2")
    seen = set()
    for epoch in range(40):
        item = ds[(clip, epoch)]
        persons = tuple(item["persons"].tolist())
        seen.add(persons)
        # Whoever was canonicalized first (either slot) sits at the origin at frame 0.
        at_origin = item["motion"][:, 0, [0, 2]].abs().amax(-1) < 1e-5
        assert at_origin.sum() == 1
        meta_actor = ds.meta[clip].actor
        assert item["actor"] == persons.index(meta_actor) + 1
    assert seen == {(1, 2), (2, 1)}


def test_swapped_reference_matches_swapped_features(train):
    clip = train.clip_ids.index("2")
    swapped = train.clip_features(clip, swap=True)
    plain = train.clip_features(clip, swap=False)
    assert swapped[0, 0, [0, 2]].abs().max() < 1e-5  # person 2 now canonical
    assert torch.allclose(
        swapped[:, 0, 132:], plain[:, 1, 132:]
    )  # rotations/contacts follow the person


def test_mirror_doubles_items_and_swaps_caption_words(root):
    ds = InterHumanDataset(root=root, split="train", mirror=True, swap_persons=False)
    n = len(ds.clip_ids)
    assert len(ds) == 2 * n
    for clip in range(n):
        original, mirrored = ds[(clip, 1)], ds[(clip + n, 1)]
        assert not original["mirrored"] and mirrored["mirrored"]
        assert mirrored["id"] == original["id"]
        assert mirrored["caption"] in {swap_left_right(c) for c in CAPTIONS}
        assert mirrored["caption"] not in CAPTIONS
    clip = ds.clip_ids.index("2")
    expected = mirror_features(ds.clip_features(clip))
    got = ds[clip + n]["motion"][:, :39].transpose(0, 1)
    assert torch.allclose(got, expected, atol=1e-5)


def test_a_batch_is_its_items_computed_one_at_a_time(root):
    """``__getitems__`` (what a DataLoader calls) groups the crops of a batch by length and mirror
    state and computes each group's features in one pass: bit for bit the items of ``ds[key]``,
    and those are the clip's features over the item's own crop and reference person."""
    rng = np.random.default_rng(1)
    norm = Normalizer(rng.normal(size=262), rng.uniform(0.5, 2, size=262))
    ds = InterHumanDataset(root=root, split="train", mirror=True, normalizer=norm)
    keys = [(index, epoch) for epoch in (0, 5) for index in range(len(ds))]
    batch = ds.__getitems__(keys)
    assert len({(it["length"], it["mirrored"]) for it in batch}) >= 6  # several groups
    assert {it["reference"] for it in batch} == {1, 2}
    for key, item in zip(keys, batch, strict=True):
        alone = ds[key]
        assert item.keys() == alone.keys()
        for field, value in item.items():
            same = (
                torch.equal(value, alone[field])
                if torch.is_tensor(value)
                else value == alone[field]
            )
            assert same, (key, field)
        clip = ds.clip_ids.index(item["id"])
        crop = ds.clip_features(
            clip,
            mirror=item["mirrored"],
            swap=item["reference"] == 2,
            start=item["start"],
            frames=item["length"] + 1,
        )
        if item["persons"][0] != item["reference"]:  # the item's first person is not the reference
            crop = crop.flip(1)
        expected = norm.normalize(crop).transpose(0, 1)
        assert torch.equal(item["motion"][:, : item["length"]], expected), key
    loader = DataLoader(ds, batch_size=len(keys), sampler=keys)  # fetched through __getitems__
    collated = next(iter(loader))
    assert torch.equal(collated["motion"], torch.stack([it["motion"] for it in batch]))
    with pytest.raises(IndexError, match=f"index {len(ds)} out of range for {len(ds)} items"):
        ds.__getitems__([0, len(ds)])


def test_normalized_items(root, train):
    rng = np.random.default_rng(0)
    norm = Normalizer(rng.normal(size=262), rng.uniform(0.5, 2, size=262))
    ds = InterHumanDataset(root=root, split="train", swap_persons=False, normalizer=norm)
    a, b = train[2], ds[2]
    length = a["length"]
    assert torch.allclose(
        norm.denormalize(b["motion"][:, :length]), a["motion"][:, :length], atol=1e-4
    )
    assert torch.all(b["motion"][:, length:] == 0)  # padding is zero in normalized space
    with pytest.raises(ValueError, match=r"normalizer must have shape \(262,\)"):
        InterHumanDataset(root=root, split="train", normalizer=Normalizer.identity((56, 6)))


def test_split_without_trailing_newline_and_ignore_lists(tmp_path):
    ids = write_interhuman(
        tmp_path, splits={"train": (20, 20, 20)}, ignore=["1"], trailing_newline=False
    )
    assert not (tmp_path / "split" / "train.txt").read_text().endswith("\n")
    ds = InterHumanDataset(root=tmp_path, split="train")
    assert ds.clip_ids == [ids["train"][0], ids["train"][2]]  # last line kept, "1" ignored
    assert ds.skipped[0].reason == "on ignore_list.txt"
    (tmp_path / "ignore_list.txt").unlink()
    (tmp_path / "split" / "ignore_list.txt").write_text("0\n2")
    ds = InterHumanDataset(root=tmp_path, split="train")
    assert ds.clip_ids == ["1"]


def test_interaction_meta_in_items(train):
    item = train[0]
    assert {"action", "action_id", "actor"} <= item.keys()
    assert item["action"] == f"act{item['action_id']}"


def test_window_mode(root, train):
    ds = InterHumanDataset(root=root, split="train", mode="window", mirror=True)
    lengths = train.frames - 1
    per_sequence = sum(window_count(int(n), window=64, stride=10) for n in lengths)
    assert len(ds) == 4 * per_sequence  # 2 persons x (original + mirrored)
    item = ds[len(ds) - 1]
    assert item["motion"].shape == (64, 262)
    assert item["mirrored"] and item["person"] == 2
    clip = train.clip_ids.index(ds[0]["id"])
    first = ds[0]
    assert first["start"] == 0 and first["person"] == 1 and not first["mirrored"]
    assert torch.allclose(first["motion"], train.clip_features(clip)[:64, 0])
    # Person 2 windows are in person 1's frame.
    p2 = next(ds[i] for i in range(len(ds)) if ds[i]["person"] == 2 and ds[i]["id"] == first["id"])
    assert torch.allclose(
        p2["motion"], train.clip_features(clip)[p2["start"] : p2["start"] + 64, 1]
    )
    plain = InterHumanDataset(root=root, split="train", mode="window")
    assert len(plain) == 2 * per_sequence


def test_window_mode_needs_a_long_clip(root):
    from intermask.data.errors import DataError

    with pytest.raises(
        DataError, match=r"split/val.txt: no clip is long enough for a 64-frame window"
    ):
        InterHumanDataset(root=root, split="val", mode="window")


def test_invalid_arguments(root):
    with pytest.raises(ValueError, match="mode must be"):
        InterHumanDataset(root=root, split="train", mode="windows")
    with pytest.raises(ValueError, match="min_length <= max_length"):
        InterHumanDataset(root=root, split="train", min_length=20, max_length=10)
    ds = InterHumanDataset(root=root, split="test")
    with pytest.raises(IndexError):
        ds[len(ds)]
