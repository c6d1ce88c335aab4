"""Outputs that appear whole or not at all (intermask/utils/staging.py), and the write errors
they raise naming where the output was to go (intermask/utils/write_errors.py)."""

from __future__ import annotations

import errno
import os

import pytest

from intermask.utils.staging import staged_outputs, write_atomically, write_text_atomically
from intermask.utils.write_errors import describe


def _full(path=None):
    return OSError(errno.ENOSPC, "No space left on device", *([path] if path else []))


def test_replaced_units_appear_together_and_a_failure_keeps_the_old_ones(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "results.md").write_text("old table")
    (out / "tensorboard").mkdir()
    (out / "tensorboard" / "old").write_text("old events")
    with pytest.raises(OSError) as failure:
        with staged_outputs(out, ["results.md", "tensorboard"], replace=True) as staged:
            (staged / "results.md").write_text("new table")
            raise _full(str(staged / "tensorboard" / "events"))
    # the staging path is never shown: the file as it would have been named in place
    assert failure.value.filename == str(out / "tensorboard" / "events")
    assert (out / "results.md").read_text() == "old table"
    assert sorted(os.listdir(tmp_path)) == ["run"]  # no staging folder left
    with staged_outputs(out, ["results.md", "tensorboard"], replace=True) as staged:
        (staged / "results.md").write_text("new table")
        (staged / "tensorboard").mkdir()
    assert (out / "results.md").read_text() == "new table"
    assert os.listdir(out / "tensorboard") == [] and sorted(os.listdir(tmp_path)) == ["run"]


def test_a_failed_write_without_a_file_names_the_output_folder(tmp_path):
    with pytest.raises(RuntimeError) as failure:
        with staged_outputs(tmp_path / "out", ["a"]):
            try:
                raise _full()  # as torch.save reports it: a RuntimeError over the OSError
            except OSError as error:
                raise RuntimeError("unexpected pos 704 vs 598") from error
    assert describe(failure.value, elsewhere="choose another --out") == (
        f"{tmp_path / 'out'}: no space left on the device; free some space there or choose "
        "another --out, then run the command again"
    )
    assert os.listdir(tmp_path) == []


def test_whatever_the_block_wrote_moves_in_only_when_replacing(tmp_path):
    with pytest.raises(ValueError, match="names=None"):
        with staged_outputs(tmp_path / "out", None):
            pass
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "keep.txt").write_text("kept")
    with staged_outputs(tmp_path / "out", None, replace=True) as staged:
        (staged / "a.txt").write_text("a")
        (staged / "b").mkdir()
    assert sorted(os.listdir(tmp_path / "out")) == ["a.txt", "b", "keep.txt"]


def test_a_single_file_is_the_old_one_or_the_new_one(tmp_path):
    path = tmp_path / "bench.json"
    write_text_atomically(path, "old")

    def half_then_full(temporary):
        temporary.write_text("ha")
        raise _full()

    with pytest.raises(OSError) as failure:
        write_atomically(path, half_then_full)
    assert failure.value.filename == str(path)
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["bench.json"]
    write_text_atomically(path, "new")
    assert path.read_text() == "new" and os.listdir(tmp_path) == ["bench.json"]
