"""Dataset pickles are read as plain containers: a payload is refused and never runs."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
from payloads import ExecPayload

from intermask.utils.plain_pickle import UnsafePickle, load_plain_pickle


def test_plain_containers_and_numpy_scalars_load(tmp_path):
    value = {"a": [1, 2.5, "x", (3, None)], "b": {4, 5}, "c": np.int64(7), "d": np.float32(0.5)}
    path = tmp_path / "plain.pkl"
    path.write_bytes(pickle.dumps(value))
    loaded = load_plain_pickle(path)
    assert loaded == value and type(loaded["c"]) is np.int64


@pytest.mark.parametrize("protocol", [0, 2, pickle.HIGHEST_PROTOCOL])
def test_a_payload_is_refused_naming_the_file_and_never_runs(tmp_path, protocol):
    marker = tmp_path / "marker"
    path = tmp_path / "evil.pkl"
    path.write_bytes(pickle.dumps({"k": ExecPayload(marker)}, protocol=protocol))
    with pytest.raises(
        UnsafePickle, match=rf"{path}: refusing to load (__builtin__|builtins).exec"
    ):
        load_plain_pickle(path)
    assert not marker.exists()


def test_an_array_is_not_a_plain_value(tmp_path):
    path = tmp_path / "array.pkl"
    path.write_bytes(pickle.dumps(np.zeros(3)))
    with pytest.raises(UnsafePickle, match=r"refusing to load numpy.*_reconstruct"):
        load_plain_pickle(path)


def test_missing_and_unreadable_files_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match=rf"{tmp_path / 'none.pkl'}: file not found"):
        load_plain_pickle(tmp_path / "none.pkl")
    for name, payload in (("text.pkl", b"nonsense"), ("cut.pkl", pickle.dumps([1, 2])[:-3])):
        (tmp_path / name).write_bytes(payload)
        with pytest.raises(ValueError, match=rf"{tmp_path / name}: not a readable pickle"):
            load_plain_pickle(tmp_path / name)
