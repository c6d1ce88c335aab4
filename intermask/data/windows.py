"""Window index for VQ training: fixed-length single-person windows over whole sequences.

Pure functions (no I/O). The index is computed once at dataset construction so that
``__getitem__`` is a slice.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np


class WindowIndex(NamedTuple):
    """Flat window index.

    sequence: (N,) int64, which sequence each window comes from.
    start: (N,) int64, first frame of the window inside that sequence.
    """

    sequence: np.ndarray
    start: np.ndarray


def window_count(length: int, *, window: int, stride: int) -> int:
    """Number of windows of ``window`` frames, ``stride`` apart, that fit in ``length`` frames.

    ``floor((length - window) / stride) + 1`` when ``length >= window``, else 0 (the reference
    ``range(0, length - window + 1, stride)``).
    """
    _check_window(window, stride)
    if length < window:
        return 0
    return (length - window) // stride + 1


def build_window_index(lengths: Sequence[int], *, window: int, stride: int) -> WindowIndex:
    """All windows over sequences of the given lengths, in sequence order then start order.

    Sequences shorter than ``window`` contribute no windows (the caller logs them).
    """
    _check_window(window, stride)
    counts = [window_count(int(n), window=window, stride=stride) for n in lengths]
    sequence = np.repeat(np.arange(len(counts), dtype=np.int64), counts)
    starts = [np.arange(c, dtype=np.int64) * stride for c in counts]
    start = np.concatenate(starts) if starts else np.zeros(0, dtype=np.int64)
    return WindowIndex(sequence=sequence, start=start)


def _check_window(window: int, stride: int) -> None:
    if window < 1:
        raise ValueError(f"window must be >= 1 frame, got {window}")
    if stride < 1:
        raise ValueError(f"stride must be >= 1 frame, got {stride}")
