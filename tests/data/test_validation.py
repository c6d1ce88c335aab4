import h5py
import numpy as np
from builders import write_interhuman, write_interx

from intermask.data.validation import check_dataset, check_dataset_report


def messages(problems):
    return [str(p) for p in problems]


def test_clean_datasets_have_no_problems(tmp_path):
    write_interhuman(
        tmp_path / "ih", splits={"train": (14, 20, 20), "val": (20,), "test": (20,)}, ignore=["2"]
    )
    report = check_dataset_report(tmp_path / "ih")  # format detected from the layout
    assert report.ok and report.problems == []
    assert report.clips == {"train": 1, "val": 1, "test": 1}
    assert [(s.clip_id, s.reason) for s in report.skipped] == [
        ("0", "shorter than 15 frames"),
        ("2", "on ignore_list.txt"),
    ]
    write_interx(tmp_path / "ix", splits={"train": (23, 40), "val": (40,), "test": (40,)})
    report = check_dataset_report(tmp_path / "ix", "interx")
    assert report.problems == []
    assert report.clips == {"train": 1, "val": 1, "test": 1}
    assert [s.reason for s in report.skipped] == ["23 frames, outside [24, 1000)"]


def test_interhuman_every_problem_at_once(tmp_path):
    write_interhuman(
        tmp_path, splits={"train": (20, 20, 20, 20), "val": (20,), "test": (20, 20), "extra": (20,)}
    )
    mp = tmp_path / "motions_processed"
    np.save(mp / "person1/0.npy", np.zeros((20, 100), np.float32))  # wrong shape
    raw = np.load(mp / "person2/1.npy")
    raw[0, 0] = np.nan
    np.save(mp / "person2/1.npy", raw)  # NaN
    (mp / "person2/2.npy").unlink()  # person2 missing
    (tmp_path / "annots/3.txt").write_text("")  # empty captions
    (tmp_path / "annots/4.txt").unlink()  # missing captions (the only val clip)
    (mp / "person1/4.npy").unlink()  # and its person1
    (tmp_path / "split/test.txt").write_text("5\n6\n7\n")  # 7 is also in train
    (tmp_path / "split/train.txt").write_text("0\n1\n2\n3\n7\n")
    problems = messages(check_dataset(tmp_path, "interhuman"))
    expected = [
        "person1/0.npy: expected shape (T, 492), got (20, 100)",
        "person2/1.npy: 1 NaN/Inf values in the body columns",
        "person2/2.npy: motion file not found",
        "annots/3.txt: caption file is empty",
        "person1/4.npy: motion file not found",
        "annots/4.txt: caption file not found",
        "split/val.txt: split resolves to zero clips (1 listed)",
        "split/test.txt: clip '7' is also in the train split",
    ]
    for text in expected:
        assert sum(text in p for p in problems) == 1, (text, problems)
    assert len(problems) == len(expected)
    assert all(p.startswith(str(tmp_path)) for p in problems)


def test_interhuman_missing_split_and_root(tmp_path):
    write_interhuman(tmp_path, splits={"train": (20,), "val": (20,), "test": (20,)})
    (tmp_path / "split/val.txt").unlink()
    assert messages(check_dataset(tmp_path)) == [
        f"{tmp_path}/split/val.txt: val split file not found"
    ]
    assert messages(check_dataset(tmp_path / "missing")) == [
        f"{tmp_path}/missing: dataset root not found"
    ]


def test_unknown_layout(tmp_path):
    (tmp_path / "something").mkdir()
    problems = messages(check_dataset(tmp_path))
    assert len(problems) == 1 and "follows no official layout" in problems[0]


def test_interx_every_problem_at_once(tmp_path):
    ids = write_interx(tmp_path, splits={"train": (30, 30, 30, 30), "val": (30,), "test": (30,)})
    a, b, c, d = ids["train"]
    with h5py.File(tmp_path / "motions/train.h5", "a") as f:
        del f[a]
        f.create_dataset(a, data=np.zeros((30, 56, 5), np.float32))
        data = f[b][()]
        data[2] = np.inf
        del f[b]
        f.create_dataset(b, data=data)
        del f[c]
    (tmp_path / "texts_processed" / f"{d}.txt").write_text("no tokens here\n")
    (tmp_path / "motions/val.h5").write_bytes(b"junk")
    (tmp_path / "annots/interaction_order.pkl").write_bytes(b"junk")
    problems = messages(check_dataset(tmp_path, "interx"))
    expected = [
        f"train.h5[{a}]: expected shape (T, 56, 6), got (30, 56, 5)",
        f"train.h5[{b}]: 336 NaN/Inf values",
        f"train.h5: no dataset named '{c}'",
        f"{d}.txt: line 1: expected 'caption#tok/POS",
        "motions/val.h5: cannot open as HDF5",
        "interaction_order.pkl: expected a pickled dict",
        "splits/train.txt: split resolves to zero clips (4 listed)",
    ]
    for text in expected:
        assert sum(text in p for p in problems) == 1, (text, problems)
    assert len(problems) == len(expected)
