"""HumanML3D folders through the dataset checker (#54): ``intermask data check`` as users run it,
the checker's problems one by one, and the DataModule reporting every problem when loading fails.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from intermask.data.errors import DataError
from intermask.data.layout import detect_format, detect_layout
from intermask.data.synthetic import generate_humanml3d
from intermask.data.text_motion import TextMotionDataModule
from intermask.data.validation import check_dataset, check_dataset_report

BAD_LINE = "a person waves"  # a caption line without its '#' fields


@pytest.fixture(scope="module")
def valid_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("hml") / "synth"
    generate_humanml3d(root, clips=12, seed=3)  # train 10, val 1, test 1
    return root


@pytest.fixture
def root(valid_root, tmp_path) -> Path:
    """A fresh copy of the valid folder, to break."""
    return Path(shutil.copytree(valid_root, tmp_path / "hml"))


def ids(root: Path, split: str) -> list[str]:
    return (root / f"{split}.txt").read_text().split()


def plant_five_problems(root: Path) -> list[str]:
    """NaN in one file, 262 columns in another, a caption line without '#', no Mean.npy, an id in
    a split file without its files; -> the five messages (file: problem) to expect."""
    a, b, c = ids(root, "train")[:3]
    vectors = root / "new_joint_vecs"
    motion = np.load(vectors / f"{a}.npy")
    motion[3, 7] = np.nan
    np.save(vectors / f"{a}.npy", motion)
    motion = np.load(vectors / f"{b}.npy")
    np.save(vectors / f"{b}.npy", motion[:, :262])
    caption = root / "texts" / f"{c}.txt"
    lines = caption.read_text().splitlines()
    caption.write_text("\n".join([lines[0], BAD_LINE, *lines[1:]]) + "\n")
    (root / "Mean.npy").unlink()
    with (root / "val.txt").open("a") as split:
        split.write("009999\n")
    return [
        f"{root / 'Mean.npy'}: statistics file not found",
        f"{vectors / a}.npy: 1 NaN/Inf values (first bad frames [3])",
        f"{vectors / b}.npy: expected shape (T, 263), got ({len(motion)}, 262)",
        f"{caption}: line 2: expected 'caption#word/POS ...#start#end' (4 fields), "
        f"got 1 fields in '{BAD_LINE}'",
        f"{root / 'val.txt'}: clip '009999' has no files (expected "
        f"{vectors / '009999.npy'} and {root / 'texts' / '009999.txt'})",
    ]


def _intermask(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    script = Path(sys.executable).parent / "intermask"
    return subprocess.run(
        [str(script), *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )


def test_data_check_console_script_names_all_five_problems(valid_root, root, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    done = _intermask("data", "check", str(valid_root), cwd=elsewhere)
    assert done.returncode == 0, done.stderr
    assert done.stdout == f"{valid_root} (humanml3d): no problems found\n"

    expected = plant_five_problems(root)
    done = _intermask("data", "check", str(root), cwd=elsewhere)
    assert done.returncode == 1, done.stderr
    assert done.stdout.splitlines() == expected  # statistics first, then the splits in order
    assert done.stderr == f"5 problem(s) in {root} (humanml3d)\n"
    assert list(elsewhere.iterdir()) == []  # nothing written where it ran


def test_layout_detection(valid_root, tmp_path):
    assert detect_layout(valid_root) == "humanml3d"
    with pytest.raises(ValueError, match="is a HumanML3D folder"):
        detect_format(valid_root)  # the two-person commands (stats, item) do not read it
    report = check_dataset_report(valid_root, "humanml3d")
    assert report.ok and report.clips == {"train": 10, "val": 1, "test": 1}
    with pytest.raises(ValueError, match="format must be one of"):
        check_dataset(valid_root, "kit")


def test_every_bad_caption_line_and_statistics_problem(root):
    a, b, c, d = ids(root, "train")[:4]
    caption = root / "texts" / f"{a}.txt"
    caption.write_text(f"{BAD_LINE}\nwalks.#walk#0.0#0.0\nwalks.#walk/VERB#soon#0.0\n")
    (root / "texts" / f"{b}.txt").unlink()  # captions missing, vectors there
    (root / "new_joint_vecs" / f"{c}.npy").write_text("not an array")
    np.save(root / "Mean.npy", np.zeros(262, np.float32))
    std = np.load(root / "Std.npy")
    std[5] = 0.0
    np.save(root / "Std.npy", std)
    (root / "test.txt").write_text(f"{d}\n")  # also in train
    problems = [str(p) for p in check_dataset(root)]
    expected = [
        "Mean.npy: expected shape (263,), got (262,)",
        f"{a}.txt: line 1: expected 'caption#word/POS",
        f"{a}.txt: line 2: expected tokens 'word/POS ...', got 'walk'",
        f"{a}.txt: line 3: time tags must be numbers (seconds), got 'soon'",
        f"texts/{b}.txt: caption file not found",
        f"{c}.npy: cannot read as .npy",
        f"test.txt: clip '{d}' is also in the train split",
    ]
    for text in expected:
        assert sum(text in p for p in problems) == 1, (text, problems)
    assert len(problems) == len(expected)
    # once Mean.npy is good, the zero std shows; a short clip is skipped, not a problem
    np.save(root / "Mean.npy", np.zeros(263, np.float32))
    np.save(root / "new_joint_vecs" / f"{c}.npy", np.zeros((30, 263), np.float32))
    report = check_dataset_report(root)
    problems = [str(p) for p in report.problems]
    assert problems[0].startswith(f"{root / 'Std.npy'}: std must be > 0 everywhere")
    assert not any("Mean.npy" in p or f"{c}.npy" in p for p in problems)
    assert (c, "30 frames, outside [40, 200)") in [(s.clip_id, s.reason) for s in report.skipped]


def test_datamodule_lists_every_problem(root):
    expected = plant_five_problems(root)
    datamodule = TextMotionDataModule(root=str(root), mode="window")
    with pytest.raises(DataError) as raised:
        datamodule.setup("fit")
    message = str(raised.value)
    assert message.startswith(f"{root}: 5 problems in the dataset (`intermask data check {root}`")
    assert message.splitlines()[1:] == [f"  {text}" for text in expected]


def test_datamodule_with_one_problem_raises_it_alone(root):
    train = ids(root, "train")
    motion = np.load(root / "new_joint_vecs" / f"{train[1]}.npy")
    np.save(root / "new_joint_vecs" / f"{train[1]}.npy", motion[:, :262])
    with pytest.raises(DataError) as raised:
        TextMotionDataModule(root=str(root)).setup("fit")
    assert str(raised.value) == (
        f"{root / 'new_joint_vecs' / train[1]}.npy: expected shape (T, 263), got "
        f"({len(motion)}, 262)"
    )
