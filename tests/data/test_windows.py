import numpy as np
import pytest

from intermask.data.windows import build_window_index, window_count


@pytest.mark.parametrize(
    ("length", "window", "stride", "expected"),
    [
        (63, 64, 10, 0),
        (64, 64, 10, 1),
        (73, 64, 10, 1),
        (74, 64, 10, 2),
        (299, 64, 10, 24),
        (10, 4, 3, 3),
    ],
)
def test_window_count_formula(length, window, stride, expected):
    assert window_count(length, window=window, stride=stride) == expected
    # Same as the reference's range(0, length - window + 1, stride).
    assert expected == len(range(0, length - window + 1, stride))


def test_build_window_index_lists_every_window_in_order():
    index = build_window_index([10, 3, 7], window=4, stride=3)
    assert index.sequence.tolist() == [0, 0, 0, 2, 2]
    assert index.start.tolist() == [0, 3, 6, 0, 3]
    assert index.sequence.dtype == np.int64


def test_build_window_index_empty():
    index = build_window_index([1, 2], window=4, stride=1)
    assert len(index.sequence) == 0 and len(index.start) == 0


@pytest.mark.parametrize(
    ("window", "stride", "match"), [(0, 1, "window must be >= 1"), (4, 0, "stride must be >= 1")]
)
def test_invalid_window(window, stride, match):
    with pytest.raises(ValueError, match=match):
        window_count(10, window=window, stride=stride)
