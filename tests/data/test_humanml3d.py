"""HumanML3D reader: hand-made clips in the official layout, read back through the reader.

The 263-d vectors are built from joint positions by
``intermask.motion.humanml3d.features_from_positions`` (the reference processing's conventions).
"""

import logging
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from intermask.data.errors import DataError
from intermask.data.humanml3d import HumanML3DDataset, read_tagged_captions, subclip_tag
from intermask.motion.humanml3d import features_from_positions, recover_from_ric
from intermask.motion.rotations import rotation_about_axis
from intermask.motion.skeleton import rest_pose_positions

WHOLE = "a person walks forward.#a/DET person/NOUN walk/VERB forward/ADV#0.0#0.0"


def turning_walk(frames: int) -> torch.Tensor:
    """(frames, 22, 3) float64 Y-up positions: a wiggling body that walks and turns about +Y at
    known speeds, facing +Z with the root at the XZ origin in frame 0 (as the release is)."""
    t = torch.arange(frames, dtype=torch.float64)
    body = rest_pose_positions().double().expand(frames, 22, 3).clone()
    joints = torch.arange(22, dtype=torch.float64)
    # Joints 3..21 wiggle; the hips stay put, so the facing (from the hips) is the yaw.
    body[:, 3:] += 0.03 * torch.sin(
        0.2 * t[:, None, None] + joints[None, 3:, None] + torch.arange(3)
    )
    yaw = 0.04 * t + 0.3 * torch.sin(0.07 * t)  # yaw(0) = 0
    root = torch.stack(
        (0.02 * t + 0.1 * torch.sin(0.05 * t), 0.9 + 0.02 * torch.sin(0.3 * t), 0.03 * t), -1
    )
    return torch.einsum("tij,tkj->tki", rotation_about_axis(yaw, "y"), body) + root[:, None]


def random_clip(frames: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).normal(size=(frames, 263)).astype(np.float32)


def write_dataset(
    root: Path,
    clips: dict[str, tuple[np.ndarray, list[str]]],
    splits: dict[str, list[str]],
    joints: dict[str, np.ndarray] | None = None,
) -> Path:
    """The official layout: new_joint_vecs, new_joints, texts, Mean/Std, split files."""
    for folder in ("new_joint_vecs", "new_joints", "texts"):
        (root / folder).mkdir(parents=True, exist_ok=True)
    for clip_id, (motion, lines) in clips.items():
        np.save(root / "new_joint_vecs" / f"{clip_id}.npy", motion)
        (root / "texts" / f"{clip_id}.txt").write_text("\n".join(lines) + "\n")
    for clip_id, positions in (joints or {}).items():
        np.save(root / "new_joints" / f"{clip_id}.npy", positions)
    stacked = np.concatenate([m for m, _ in clips.values()])
    np.save(root / "Mean.npy", stacked.mean(0).astype(np.float32))
    np.save(root / "Std.npy", (stacked.std(0) + 0.5).astype(np.float32))
    for split, ids in splits.items():
        (root / f"{split}.txt").write_text("".join(f"{i}\n" for i in ids))
    return root


# ---------------------------------------------------------------------- (a) round trip


@pytest.fixture(scope="module")
def walk():
    positions = turning_walk(81)
    motion = features_from_positions(positions)
    # The canonical joints are the walk moved rigidly (turned about +Y, shifted, floored).
    distances = torch.cdist(positions[:80].flatten(0, 1), positions[:80].flatten(0, 1))
    moved = motion.joints.flatten(0, 1)
    torch.testing.assert_close(torch.cdist(moved, moved), distances)
    assert float(motion.joints[..., 1].min()) == 0.0
    return motion.joints, motion.features


def test_hand_made_clip_round_trips_through_the_reader(tmp_path, walk):
    positions, features = walk
    root = write_dataset(
        tmp_path,
        {"000007": (features.float().numpy(), [WHOLE])},
        {"train": ["000007"]},
        joints={"000007": positions.float().numpy()},
    )
    ds = HumanML3DDataset(root=root, split="train", length_jitter=False)
    assert len(ds) == 1 and ds.clip_ids == ["000007"] and list(ds.frames) == [80]
    read = ds.features(0)
    assert read.dtype == torch.float32 and read.shape == (80, 263)
    recovered = recover_from_ric(read)
    torch.testing.assert_close(recovered.double(), positions, atol=1e-5, rtol=0)
    torch.testing.assert_close(ds.joints(0), recovered, atol=1e-5, rtol=0)
    # The motion turned through more than a right angle and walked about 2 m.
    assert float(torch.linalg.vector_norm(positions[79, 0, [0, 2]])) > 2.0


def test_item_is_the_z_scored_crop_padded_with_zeros(tmp_path, walk):
    _, features = walk
    root = write_dataset(
        tmp_path, {"000007": (features.float().numpy(), [WHOLE])}, {"train": ["000007"]}
    )
    ds = HumanML3DDataset(root=root, split="train", length_jitter=False)
    item = ds[0]
    mean, std = np.load(root / "Mean.npy"), np.load(root / "Std.npy")
    assert item["length"] == 80 and item["start"] == 0 and item["motion"].shape == (196, 263)
    expected = (features.float().numpy() - mean) / std
    np.testing.assert_allclose(item["motion"][:80].numpy(), expected, atol=1e-5)
    assert torch.all(item["motion"][80:] == 0)
    assert item["caption"] == "a person walks forward."
    assert item["tokens"] == "a/DET person/NOUN walk/VERB forward/ADV"
    assert (item["id"], item["clip_id"]) == ("000007", "000007")
    torch.testing.assert_close(
        ds.normalizer.denormalize(item["motion"][:80]), features.float(), atol=1e-5, rtol=0
    )
    raw = HumanML3DDataset(root=root, split="train", length_jitter=False, normalize=False)
    torch.testing.assert_close(raw[0]["motion"][:80], features.float())


# ---------------------------------------------------------------------- (b) sub-clips

SUBCLIP_LINES = [
    WHOLE,
    "the person jumps.#the/DET person/NOUN jump/VERB#1.0#4.0",  # A: frames 20..80
    "a short hop.#a/DET short/ADJ hop/NOUN#0.5#2.0",  # B: 30 frames, too short
    "then sits down.#then/ADV sit/VERB down/ADV#5.0#9.0",  # C: 100..180 cut to 100..150
    "someone waves.#someone/PRON wave/VERB#nan#nan",  # NaN tags: whole clip
]


@pytest.fixture
def subclips(tmp_path):
    clips = {
        "000001": (random_clip(150, 1), SUBCLIP_LINES),
        "000002": (random_clip(120, 2), ["a person bows.#a/DET person/NOUN bow/VERB#0.0#3.0"]),
        "M000003": (random_clip(60, 3), [WHOLE]),
    }
    return write_dataset(tmp_path, clips, {"train": list(clips)}), clips


def test_subclip_captions_become_their_own_items(subclips, caplog):
    root, clips = subclips
    with caplog.at_level(logging.INFO, logger="intermask.data"):
        ds = HumanML3DDataset(root=root, split="train", length_jitter=False, normalize=False)
    spans = [(s.item_id, ds.clip_ids[s.clip], s.start, s.stop) for s in ds.items]
    assert spans == [
        ("000001", "000001", 0, 150),
        ("A_000001", "000001", 20, 80),
        ("C_000001", "000001", 100, 150),
        ("A_000002", "000002", 0, 60),
        ("M000003", "M000003", 0, 60),
    ]
    assert [c.text for c in ds.items[0].captions] == ["a person walks forward.", "someone waves."]
    assert [c.text for c in ds.items[1].captions] == ["the person jumps."]
    item = ds[1]
    assert (item["id"], item["clip_id"], item["length"], item["start"]) == (
        "A_000001",
        "000001",
        60,
        20,
    )
    np.testing.assert_array_equal(item["motion"][:60].numpy(), clips["000001"][0][20:80])
    assert (
        item["caption"] == "the person jumps." and item["tokens"] == "the/DET person/NOUN jump/VERB"
    )
    np.testing.assert_array_equal(ds.features(2).numpy(), clips["000001"][0][100:150])
    assert [(s.clip_id, s.reason) for s in ds.skipped] == [
        ("B_000001", "sub-clip [0.5, 2.0) s of 000001: 30 frames, outside [40, 200)"),
        ("000002", "no whole-clip caption (every caption is time-tagged)"),
    ]
    assert "skipped 2 clips" in caplog.text


def test_subclip_tags_follow_the_file_order():
    assert [subclip_tag(k) for k in (0, 1, 22, 23, 24, 46)] == ["A", "B", "W", "A1", "B1", "A2"]


def test_tagged_caption_parsing(tmp_path):
    path = tmp_path / "c.txt"
    path.write_text("\n" + SUBCLIP_LINES[1] + "\n\n" + SUBCLIP_LINES[4] + "\n")
    first, second = read_tagged_captions(path)
    assert first.tokens == ("the/DET", "person/NOUN", "jump/VERB")
    assert (first.start, first.end, first.whole) == (1.0, 4.0, False)
    assert (second.start, second.end, second.whole) == (0.0, 0.0, True)


# ---------------------------------------------------------------------- (c) lengths


@pytest.fixture
def lengths_root(tmp_path):
    clips = {f"{t:06d}": (random_clip(t, t), [WHOLE]) for t in (39, 40, 150, 199, 200)}
    return write_dataset(tmp_path, clips, {"train": list(clips)})


def test_length_rule_and_skip_list(lengths_root):
    ds = HumanML3DDataset(root=lengths_root, split="train")
    assert ds.clip_ids == ["000040", "000150", "000199"] and list(ds.frames) == [40, 150, 199]
    assert [(s.clip_id, s.reason) for s in ds.skipped] == [
        ("000039", "39 frames, outside [40, 200)"),
        ("000200", "200 frames, outside [40, 200)"),
    ]


def test_lengths_are_cropped_to_multiples_of_4(lengths_root):
    fixed = HumanML3DDataset(root=lengths_root, split="train", length_jitter=False)
    assert [fixed[i]["length"] for i in range(3)] == [40, 148, 196]
    jittered = HumanML3DDataset(root=lengths_root, split="train")
    seen = [{jittered[(i, e)]["length"] for e in range(40)} for i in range(3)]
    assert seen == [{36, 40}, {144, 148}, {192, 196}]
    capped = HumanML3DDataset(root=lengths_root, split="train", length_jitter=False, max_length=98)
    assert [capped[i]["length"] for i in range(3)] == [40, 96, 96]
    assert capped[1]["motion"].shape == (98, 263)


def test_crop_is_a_window_of_the_clip_and_items_replay(lengths_root):
    ds = HumanML3DDataset(root=lengths_root, split="train", normalize=False)
    raw = np.load(lengths_root / "new_joint_vecs" / "000199.npy")
    starts = set()
    for epoch in range(10):
        item = ds[(2, epoch)]
        length, start = item["length"], item["start"]
        np.testing.assert_array_equal(item["motion"][:length].numpy(), raw[start : start + length])
        assert torch.all(item["motion"][length:] == 0)
        starts.add(start)
        torch.testing.assert_close(ds[(2, epoch)]["motion"], item["motion"])
    assert len(starts) > 1


# ---------------------------------------------------------------------- (d) bad files


@pytest.fixture
def good_root(tmp_path):
    clips = {"000001": (random_clip(60, 1), [WHOLE]), "000002": (random_clip(48, 2), [WHOLE])}
    return write_dataset(tmp_path, clips, {"train": list(clips), "val": ["000002"]})


def expect_error(root: Path, where: str, problem: str, split: str = "train") -> None:
    with pytest.raises(DataError, match=re.escape(str(root / where)) + ": " + problem):
        HumanML3DDataset(root=root, split=split)


@pytest.mark.parametrize(
    ("array", "problem"),
    [
        (np.zeros((60, 262), np.float32), r"expected shape \(T, 263\), got \(60, 262\)"),
        (np.zeros((60, 22, 3), np.float32), r"expected shape \(T, 263\), got \(60, 22, 3\)"),
        (np.zeros((60, 263), np.int64), "expected a float array, got dtype int64"),
        (np.full((60, 263), np.nan, np.float32), r"15780 NaN/Inf values \(first bad frames \[0, 1"),
    ],
)
def test_bad_motion_arrays(good_root, array, problem):
    np.save(good_root / "new_joint_vecs" / "000002.npy", array)
    expect_error(good_root, "new_joint_vecs/000002.npy", problem)


def test_inf_in_one_frame(good_root):
    motion = random_clip(48, 2)
    motion[17, 5] = np.inf
    np.save(good_root / "new_joint_vecs" / "000002.npy", motion)
    expect_error(
        good_root, "new_joint_vecs/000002.npy", r"1 NaN/Inf values \(first bad frames \[17\]\)"
    )


def test_unreadable_motion_file(good_root):
    (good_root / "new_joint_vecs" / "000001.npy").write_text("not an array")
    expect_error(good_root, "new_joint_vecs/000001.npy", r"cannot read as \.npy")


def test_split_id_without_motion_file(good_root):
    (good_root / "train.txt").write_text("000001\n000404\n")
    expect_error(
        good_root, "new_joint_vecs/000404.npy", r"motion \(listed in train\.txt\) file not found"
    )


def test_missing_split_file(good_root):
    expect_error(good_root, "test.txt", "test split file not found", split="test")


def test_missing_caption_file(good_root):
    (good_root / "texts" / "000002.txt").unlink()
    expect_error(good_root, "texts/000002.txt", "caption file not found")


def test_empty_caption_file(good_root):
    (good_root / "texts" / "000002.txt").write_text("\n  \n")
    expect_error(good_root, "texts/000002.txt", "caption file is empty")


@pytest.mark.parametrize(
    ("line", "problem"),
    [
        (
            "a person walks.#a/DET person/NOUN#0.0",
            r"line 2: expected 'caption#word/POS \.\.\.#start#end' \(4 fields\), got 3",
        ),
        ("#a/DET person/NOUN#0.0#0.0", "line 2: expected 'caption#word/POS"),
        ("a person walks.##0.0#0.0", "line 2: expected tokens 'word/POS ...', got ''"),
        (
            "a person walks.#a/DET person#0.0#0.0",
            "line 2: expected tokens 'word/POS ...', got 'a/DET person'",
        ),
        (
            "a person walks.#a/DET#zero#0.0",
            r"line 2: time tags must be numbers \(seconds\), got 'zero'",
        ),
        ("a person walks.#a/DET#-1.0#2.0", "line 2: time tag must be finite and >= 0, got -1.0"),
        ("a person walks.#a/DET#0.0#inf", "line 2: time tag must be finite and >= 0, got inf"),
    ],
)
def test_malformed_caption_lines(good_root, line, problem):
    (good_root / "texts" / "000002.txt").write_text(WHOLE + "\n" + line + "\n")
    expect_error(good_root, "texts/000002.txt", problem)


def test_missing_statistics(good_root):
    (good_root / "Mean.npy").unlink()
    expect_error(good_root, "Mean.npy", "statistics file not found")
    HumanML3DDataset(root=good_root, split="train", normalize=False)  # raw items need no Mean.npy


def test_statistics_of_the_wrong_shape(good_root):
    np.save(good_root / "Std.npy", np.ones(262, np.float32))
    expect_error(good_root, "Std.npy", r"expected shape \(263,\), got \(262,\)")


def test_zero_std(good_root):
    std = np.ones(263, np.float32)
    std[[5, 260]] = 0.0
    np.save(good_root / "Std.npy", std)
    with pytest.raises(
        DataError,
        match=re.escape(str(good_root / "Std.npy")) + r".*std must be > 0 everywhere.*\[5, 260\]",
    ):
        HumanML3DDataset(root=good_root, split="train")


def test_split_with_no_usable_item(good_root):
    np.save(good_root / "new_joint_vecs" / "000002.npy", random_clip(30, 2))
    expect_error(
        good_root, "val.txt", r"split resolves to zero items \(1 listed, 1 skipped", split="val"
    )


def test_missing_root(tmp_path):
    with pytest.raises(
        DataError, match=re.escape(str(tmp_path / "nope")) + ": dataset root not found"
    ):
        HumanML3DDataset(root=tmp_path / "nope", split="train")


def test_bad_joints_file(good_root):
    ds = HumanML3DDataset(root=good_root, split="train")
    with pytest.raises(
        DataError,
        match=re.escape(str(good_root / "new_joints" / "000001.npy")) + ": joints file not found",
    ):
        ds.joints(0)
    np.save(good_root / "new_joints" / "000001.npy", np.zeros((59, 22, 3), np.float32))
    with pytest.raises(
        DataError,
        match=r"new_joints/000001\.npy: expected 60 frames like .*new_joint_vecs/000001\.npy, got 59",
    ):
        ds.joints(0)
    np.save(good_root / "new_joints" / "000001.npy", np.zeros((60, 21, 3), np.float32))
    with pytest.raises(
        DataError, match=r"new_joints/000001\.npy: expected shape \(T, 22, 3\), got \(60, 21, 3\)"
    ):
        ds.joints(0)


def test_bad_arguments(good_root):
    with pytest.raises(ValueError, match="2 \\* unit_length <= min_length"):
        HumanML3DDataset(root=good_root, split="train", min_length=6)
    with pytest.raises(IndexError, match="index 2 out of range for 2 items"):
        HumanML3DDataset(root=good_root, split="train")[2]
