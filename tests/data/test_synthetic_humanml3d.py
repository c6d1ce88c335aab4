"""The synthetic dataset in the HumanML3D layout, read back through the real reader."""

import re
from pathlib import Path

import numpy as np
import pytest
import torch

from intermask.data.humanml3d import HumanML3DDataset, read_tagged_captions
from intermask.data.synthetic import generate_clip, generate_humanml3d
from intermask.data.synthetic.humanml3d import MOVING_SPEED, STD_GROUPS
from intermask.motion.humanml3d import recover_from_ric

SEED, CLIPS = 3, 12
UNIVERSAL_POS = {"DET", "NOUN", "PRON", "ADJ", "ADV", "ADP", "CCONJ", "SCONJ", "VERB", "PART"}


@pytest.fixture(scope="module")
def root(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("hml") / "synth"
    summary = generate_humanml3d(out, clips=CLIPS, seed=SEED)
    assert summary.split_sizes == {"train": 10, "val": 1, "test": 1}
    assert summary.subclips >= 1 and summary.outside_length_rule == 0
    return out


def ids(root: Path, split: str) -> list[str]:
    return (root / f"{split}.txt").read_text().split()


def test_every_split_reads_back(root):
    assert sorted(ids(root, "all")) == [f"{i:06d}" for i in range(CLIPS)]
    assert ids(root, "train_val") == ids(root, "train") + ids(root, "val")
    for split in ("train", "val", "test"):
        ds = HumanML3DDataset(root=root, split=split, length_jitter=False)
        assert ds.clip_ids == ids(root, split) and ds.skipped == []
        item = ds[0]
        assert item["motion"].shape == (196, 263) and 40 <= item["length"] <= 196
        assert torch.isfinite(item["motion"]).all()


def test_stored_vectors_recover_the_stored_joints(root):
    for clip_id in ids(root, "all"):
        features = np.load(root / "new_joint_vecs" / f"{clip_id}.npy")
        joints = np.load(root / "new_joints" / f"{clip_id}.npy")
        assert features.dtype == joints.dtype == np.float32
        assert 40 <= len(features) < 200 and joints.shape == (len(features), 22, 3)
        recovered = recover_from_ric(torch.from_numpy(features).double())
        np.testing.assert_allclose(recovered.numpy(), joints, atol=1e-4)
        # Canonical place: floored, frame-0 root above the origin.
        assert abs(float(joints[..., 1].min())) < 1e-6
        np.testing.assert_allclose(joints[0, 0, [0, 2]], 0.0, atol=1e-6)
        # 6D rotations are unit columns, not a constant filler.
        columns = features[:, 67:193].reshape(-1, 21, 2, 3)
        np.testing.assert_allclose(np.linalg.norm(columns, axis=-1), 1.0, atol=1e-5)
    assert np.load(root / "new_joint_vecs" / "000000.npy")[:, 67:193].std(0).max() > 0.05


def test_clips_are_20_fps_resamplings_of_the_actor(root):
    meta = __import__("json").loads((root / "interaction_meta.json").read_text())["clips"]
    for index in (0, 5):
        entry = meta[f"{index:06d}"]
        clip = generate_clip(seed=SEED, index=index, action=entry["action"], vary_bodies=False)
        source = clip.positions[entry["source_person"] - 1].numpy()  # 30 fps
        stored = np.load(root / "new_joints" / f"{index:06d}.npy")  # 20 fps
        # Frame 2m at 20 fps is frame 3m at 30 fps; the clip was only moved rigidly.
        frames = np.arange(0, len(stored), 2)
        ours = np.linalg.norm(stored[frames] - stored[0, 0], axis=-1)
        theirs = np.linalg.norm(source[frames * 3 // 2] - source[0, 0], axis=-1)
        np.testing.assert_allclose(ours, theirs, atol=1e-4)
        # Hence the same speed in m/s: mean root speed over the clip.
        speed20 = np.linalg.norm(np.diff(stored[frames, 0], axis=0), axis=-1).sum() / (
            frames[-1] / 20
        )
        speed30 = np.linalg.norm(np.diff(source[frames * 3 // 2, 0], axis=0), axis=-1).sum() / (
            frames[-1] * 3 // 2 / 30
        )
        assert speed20 == pytest.approx(speed30, rel=1e-4)
    walker = np.load(root / "new_joints" / "000000.npy")
    assert np.linalg.norm(np.diff(walker[:, 0, [0, 2]], axis=0), axis=-1).max() * 20 > 0.8


def test_captions_carry_pos_tags(root):
    for clip_id in ids(root, "all"):
        captions = read_tagged_captions(root / "texts" / f"{clip_id}.txt")
        whole = [c for c in captions if c.whole]
        assert len(whole) == 3 and len({c.text for c in whole}) == 3
        for caption in captions:
            assert (
                re.search(r"\b(a|the) person\b", caption.text.lower()) and caption.text[-1] == "."
            )
            assert len(caption.tokens) == len(re.findall(r"[a-z]+", caption.text.lower()))
            assert {token.split("/")[1] for token in caption.tokens} <= UNIVERSAL_POS
            pairs = set(zip(caption.tokens, caption.tokens[1:], strict=False))
            assert pairs & {("a/DET", "person/NOUN"), ("the/DET", "person/NOUN")}


def test_subclip_items_cover_a_moving_span(root):
    ds = HumanML3DDataset(root=root, split="train", length_jitter=False)
    subclips = [s for s in ds.items if s.item_id != ds.clip_ids[s.clip]]
    assert subclips, "no time-tagged caption became an item"
    for span in subclips:
        clip_id = ds.clip_ids[span.clip]
        assert span.item_id.endswith(f"_{clip_id}") and span.stop - span.start >= 40
        assert [c.text.split()[-2:] for c in span.captions] in (
            [["walks", "forward."]],
            [["runs", "forward."]],
        )
        joints = np.load(root / "new_joints" / f"{clip_id}.npy")
        steps = np.linalg.norm(np.diff(joints[span.start : span.stop, 0, [0, 2]], axis=0), axis=-1)
        assert steps.min() * 20 > MOVING_SPEED
        # The frames just outside the span are not moving.
        outside = [f for f in (span.start - 1, span.stop) if 0 <= f < len(joints) - 1]
        for frame in outside:
            step = np.linalg.norm(joints[frame + 1, 0, [0, 2]] - joints[frame, 0, [0, 2]])
            assert step * 20 <= MOVING_SPEED


def test_statistics_are_the_training_split_group_stds(root):
    train = np.concatenate(
        [
            np.load(root / "new_joint_vecs" / f"{i}.npy").astype(np.float64)
            for i in ids(root, "train")
        ]
    )
    mean, std = np.load(root / "Mean.npy"), np.load(root / "Std.npy")
    assert mean.dtype == std.dtype == np.float32 and mean.shape == std.shape == (263,)
    np.testing.assert_allclose(mean, train.mean(0), atol=1e-6)
    raw = train.std(0)
    for part in STD_GROUPS:
        expected = max(raw[part].mean(), 1e-3)
        np.testing.assert_allclose(std[part], expected, rtol=1e-5)
    assert std.min() >= 1e-3 and len(set(std.tolist())) <= len(STD_GROUPS)


def test_same_seed_same_bytes_other_seed_differs(root, tmp_path):
    again = tmp_path / "again"
    generate_humanml3d(again, clips=CLIPS, seed=SEED)
    files = sorted(p.relative_to(root) for p in root.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(again) for p in again.rglob("*") if p.is_file())
    for name in files:
        assert (root / name).read_bytes() == (again / name).read_bytes(), name
    generate_humanml3d(again, clips=CLIPS, seed=SEED + 1)  # replaces the earlier dataset
    assert (again / "Mean.npy").read_bytes() != (root / "Mean.npy").read_bytes()
    assert (again / "texts" / "000000.txt").read_text() != (
        root / "texts" / "000000.txt"
    ).read_text()


def test_refuses_a_folder_with_other_data(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="not empty and holds no synthetic dataset"):
        generate_humanml3d(tmp_path, clips=3, seed=0)
    with pytest.raises(ValueError, match="clips must be between 3"):
        generate_humanml3d(tmp_path / "new", clips=2, seed=0)
