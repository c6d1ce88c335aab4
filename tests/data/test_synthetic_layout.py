"""The synthetic generator writes both official layouts, reproducibly."""

from __future__ import annotations

import json
import pickle
import re
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from intermask.data.synthetic import (
    ACTIONS,
    assign_splits,
    default_workers,
    generate_clip,
    generate_dataset,
)
from intermask.data.synthetic.writers import interhuman_raw
from intermask.motion.rotations import matrix_to_rot6d

CLIPS = 28  # two of each of the 14 interactions
SEED = 7
INTERX_NAME = re.compile(r"^G\d{3}T\d{3}A(\d{3})R\d{3}$")
PROCESSED_LINE = re.compile(r"^[^#]+#(?:[a-z]+/[A-Z]+ ?)+#0\.0#0\.0$")


@pytest.fixture(scope="module")
def interhuman_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("synth") / "interhuman"
    generate_dataset(root, format="interhuman", clips=CLIPS, seed=SEED)
    return root


@pytest.fixture(scope="module")
def interx_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("synth") / "interx"
    generate_dataset(root, format="interx", clips=CLIPS, seed=SEED)
    return root


def _split_ids(folder: Path) -> dict[str, list[str]]:
    return {s: (folder / f"{s}.txt").read_text().split() for s in ("train", "val", "test")}


def test_interhuman_layout_shapes_and_captions(interhuman_root: Path) -> None:
    splits = _split_ids(interhuman_root / "split")
    ids = sorted(i for ids in splits.values() for i in ids)
    assert sorted(ids, key=int) == [str(i) for i in range(1, CLIPS + 1)]  # a partition of all clips
    assert [len(splits[s]) for s in ("train", "val", "test")] == [22, 3, 3]
    assert (interhuman_root / "ignore_list.txt").read_text() == ""
    for clip_id in ids:
        lines = (interhuman_root / "annots" / f"{clip_id}.txt").read_text().splitlines()
        assert len(lines) == 3 and len(set(lines)) == 3
        person1 = np.load(interhuman_root / "motions_processed" / "person1" / f"{clip_id}.npy")
        person2 = np.load(interhuman_root / "motions_processed" / "person2" / f"{clip_id}.npy")
        assert person1.dtype == np.float32 and person1.shape == person2.shape
        frames = person1.shape[0]
        assert person1.shape[1] == 492 and 60 <= frames <= 300  # 2-10 s at 30 fps
        for raw in (person1, person2):
            positions = raw[:, :186].reshape(frames, 62, 3)
            assert abs(positions[..., 2].min()) < 1e-4  # Z-up: the ground is z = 0
            assert 0.75 < positions[0, 0, 2] < 1.15  # pelvis height
            hands = raw[:, 186 + 21 * 6 :].reshape(frames, 30, 6)
            np.testing.assert_allclose(
                hands, np.broadcast_to([1, 0, 0, 1, 0, 0], hands.shape), atol=1e-6
            )
            wrists = positions[:, [20, 21]]
            left = np.concatenate(
                (positions[:, 22:37], positions[:, 52:57]), 1
            )  # joints, then tips
            assert (
                np.linalg.norm(left - wrists[:, None, 0], axis=-1).max() < 0.25
            )  # fingers at the left wrist


def test_interhuman_rotations_are_the_posed_local_rotations(interhuman_root: Path) -> None:
    meta = json.loads((interhuman_root / "interaction_meta.json").read_text())
    clip = generate_clip(seed=SEED, index=0, action=meta["clips"]["1"]["action"])
    raw = np.load(interhuman_root / "motions_processed" / "person1" / "1.npy")
    np.testing.assert_array_equal(raw, interhuman_raw(clip, 0))
    expected = matrix_to_rot6d(clip.local_rotations[0, :, 1:], layout="rows").reshape(
        clip.frames, -1
    )
    np.testing.assert_allclose(raw[:, 186:312], expected.numpy(), atol=1e-6)
    # The "rows" layout: [R00, R01, R10, R11, R20, R21] of the left knee.
    knee = clip.local_rotations[0, :, 4]
    np.testing.assert_allclose(
        raw[:, 186 + 3 * 6 : 186 + 4 * 6], knee[:, :, :2].reshape(-1, 6).numpy(), atol=1e-6
    )


def test_meta_lists_every_clip_with_action_and_actor(interhuman_root: Path) -> None:
    meta = json.loads((interhuman_root / "interaction_meta.json").read_text())
    assert meta["format"] == "synthetic-v1" and meta["actions"] == list(ACTIONS)
    assert len(ACTIONS) >= 12
    clips = meta["clips"]
    assert set(clips) == {str(i) for i in range(1, CLIPS + 1)}
    counts = {action: 0 for action in ACTIONS}
    for entry in clips.values():
        assert entry["actor"] in (1, 2) and ACTIONS[entry["action_id"]] == entry["action"]
        counts[entry["action"]] += 1
    assert set(counts.values()) == {CLIPS // len(ACTIONS)}  # every interaction, equally often
    assert {entry["actor"] for entry in clips.values()} == {1, 2}
    readme = (interhuman_root / "README.txt").read_text()
    assert "synthetic" in readme.lower() and f"seed: {SEED}" in readme and "synthetic-v1" in readme


def test_interx_layout(interx_root: Path) -> None:
    splits = _split_ids(interx_root / "splits")
    meta = json.loads((interx_root / "interaction_meta.json").read_text())["clips"]
    order = pickle.loads((interx_root / "annots" / "interaction_order.pkl").read_bytes())
    names = [n for ids in splits.values() for n in ids]
    assert len(names) == len(set(names)) == CLIPS and set(meta) == set(names) == set(order)
    for split, listed in splits.items():
        with h5py.File(interx_root / "motions" / f"{split}.h5", "r") as handle:
            assert sorted(handle.keys()) == sorted(listed)
            for name in listed:
                data = handle[name][:]
                assert (
                    data.dtype == np.float32
                    and data.shape[1:] == (56, 6)
                    and 60 <= data.shape[0] <= 300
                )
                assert int(INTERX_NAME.match(name).group(1)) == meta[name]["action_id"]
                assert order[name] == (0 if meta[name]["actor"] == 1 else 1)
                np.testing.assert_array_equal(data[:, 22:55], 0.0)  # jaw, eyes, hands
                np.testing.assert_allclose(
                    data[0, 55, 0:2], 0.0, atol=1e-6
                )  # P1 frame-0 at the origin
                assert (
                    0.8 < data[0, 55, 2] < 1.0 and 0.8 < data[0, 55, 5] < 1.0
                )  # Z-up pelvis height
        for name in listed:
            lines = (interx_root / "texts_processed" / f"{name}.txt").read_text().splitlines()
            assert len(lines) == 3 and all(PROCESSED_LINE.match(line) for line in lines), lines


def test_interx_rows_rebuild_the_generated_joints(interx_root: Path) -> None:
    """FK of the written rows with the template body gives the generated joints (shifted)."""
    from intermask.motion.interx import interx_positions, person_representation, split_persons

    meta = json.loads((interx_root / "interaction_meta.json").read_text())["clips"]
    name = _split_ids(interx_root / "splits")["train"][0]
    with h5py.File(interx_root / "motions" / "train.h5", "r") as handle:
        raw = torch.from_numpy(handle[name][:]).double()
    group, take, repetition = int(name[1:4]), int(name[5:8]), int(name[13:16])
    index = (group - 1) * 1000 + take * 10 + repetition
    clip = generate_clip(seed=SEED, index=index, action=meta[name]["action"], vary_bodies=False)
    persons = split_persons(raw)
    rebuilt = torch.stack([interx_positions(person_representation(persons[:, p])) for p in (0, 1)])
    shift = rebuilt - clip.positions  # one constant ground-plane shift for everything
    assert shift.std(dim=(1, 2)).max() < 1e-5 and shift[..., 1].abs().max() < 1e-5


def test_same_seed_same_bytes_other_seed_other_bytes(tmp_path: Path) -> None:
    def files(root: Path) -> dict[str, bytes]:
        return {
            str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
        }

    for dataset_format in ("interhuman", "interx"):
        first, second, other = (tmp_path / f"{dataset_format}{k}" for k in range(3))
        for root, seed in ((first, 3), (second, 3), (other, 4)):
            generate_dataset(root, format=dataset_format, clips=5, seed=seed)
        assert files(first) == files(second)
        motions = (
            "motions_processed/person1/1.npy"
            if dataset_format == "interhuman"
            else "motions/train.h5"
        )
        assert files(first)[motions] != files(other)[motions]


def test_splits_follow_the_fractions() -> None:
    labels = assign_splits(1000, 0, (0.8, 0.1, 0.1))
    assert [labels.count(s) for s in ("train", "val", "test")] == [800, 100, 100]
    assert labels != assign_splits(1000, 1, (0.8, 0.1, 0.1))
    assert [assign_splits(3, 0, (0.8, 0.1, 0.1)).count(s) for s in ("train", "val", "test")] == [
        1,
        1,
        1,
    ]
    with pytest.raises(ValueError, match="summing to 1"):
        assign_splits(10, 0, (0.5, 0.1, 0.1))
    with pytest.raises(ValueError, match="at least 3 clips"):
        assign_splits(2, 0, (0.8, 0.1, 0.1))


def _tree(root: Path) -> dict[str, bytes]:
    return {
        str(f.relative_to(root)): f.read_bytes() for f in sorted(root.rglob("*")) if f.is_file()
    }


def test_worker_processes_write_the_same_bytes(tmp_path: Path) -> None:
    # Both layouts share the clip pool; a small dataset keeps the two workers' start-up
    # the test's main cost.
    for workers in (1, 2):
        generate_dataset(
            tmp_path / str(workers), format="interx", clips=6, seed=SEED, workers=workers
        )
    assert _tree(tmp_path / "2") == _tree(tmp_path / "1") and len(_tree(tmp_path / "1")) > 6


def test_default_workers_need_enough_clips_and_fork(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr("os.sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    monkeypatch.setattr("multiprocessing.get_all_start_methods", lambda: ["fork", "spawn"])
    assert [default_workers(n) for n in (3, 199, 200, 400, 1000, 5000)] == [1, 1, 1, 2, 4, 4]
    monkeypatch.setattr("multiprocessing.get_all_start_methods", lambda: ["spawn", "fork"])
    assert default_workers(5000) == 1  # spawned workers would re-import the caller's script


def test_bad_arguments_and_foreign_folders(tmp_path: Path) -> None:
    with pytest.raises(
        ValueError, match=r"format must be one of \('interhuman', 'interx'\), got 'bvh'"
    ):
        generate_dataset(tmp_path / "a", format="bvh", clips=5, seed=0)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="clips must be between 3"):
        generate_dataset(tmp_path / "a", format="interx", clips=2, seed=0)
    with pytest.raises(ValueError, match="workers must be at least 1, got 0"):
        generate_dataset(tmp_path / "a", format="interx", clips=5, seed=0, workers=0)
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError, match="holds no synthetic dataset"):
        generate_dataset(foreign, format="interhuman", clips=3, seed=0)
    assert (foreign / "notes.txt").read_text() == "mine"


def test_regenerating_replaces_an_earlier_synthetic_dataset(tmp_path: Path) -> None:
    root = tmp_path / "data"
    generate_dataset(root, format="interhuman", clips=80, seed=0)  # a meta file of > 20 kB
    (root / "run_record.json").write_text("{}")  # what the CLI adds next to the data
    generate_dataset(root, format="interx", clips=3, seed=1)
    assert (
        not (root / "motions_processed").exists()
        and len(list((root / "texts_processed").iterdir())) == 3
    )
    assert len(json.loads((root / "interaction_meta.json").read_text())["clips"]) == 3
    assert (root / "run_record.json").read_text() == "{}"


@pytest.mark.slow
@pytest.mark.parametrize("dataset_format", ["interhuman", "interx"])
def test_thousand_clips_in_under_a_minute(tmp_path: Path, dataset_format: str) -> None:
    start = time.perf_counter()
    summary = generate_dataset(tmp_path / "big", format=dataset_format, clips=1000, seed=0)
    assert time.perf_counter() - start < 60.0
    assert summary.clips == 1000 and min(summary.action_counts.values()) >= 71
