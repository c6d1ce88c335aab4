"""The item and window protocol every dataset reader shares (:class:`ClipReader`).

A reader reads one split of one release layout at construction and serves two kinds of items:

- ``mode="interaction"``: a (possibly cropped) two-person clip with one of its captions,
  padded to ``max_length`` frames, drawn from a generator seeded by ``(seed, epoch, index)``
  (:func:`~intermask.data.common.item_rng`), so a pass is the same in every run;
- ``mode="window"``: fixed-length windows of one person (or of both with
  ``window_persons=2``), ``stride`` frames apart, over every whole clip, for VQ training.

A DataLoader fetches a batch through ``__getitems__``, which equals the items one by one; a
reader whose items share work (InterHuman: one feature pass per group of crops of one length and
mirror state) does it once per batch there.

What differs between releases (files, features, crop rules, augmentation) lives in the
subclasses; the class attributes below are what the DataModule and the statistics read instead
of dispatching on the dataset's name.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, ClassVar, Literal

import numpy as np
import torch
from torch.utils.data import Dataset

from intermask.data.common import ItemKey, item_rng, log_skipped, single_threaded, split_key
from intermask.data.errors import DataError, SkippedClip
from intermask.data.normalization import Normalizer
from intermask.data.windows import WindowIndex, build_window_index
from intermask.motion.kinds import DatasetKind

Mode = Literal["interaction", "window"]


class ClipReader(Dataset, ABC):
    """One split of one release layout, as interaction items or VQ windows (module docstring).

    Subclasses set the class attributes, read the split in :meth:`_load` (``clip_ids``,
    ``frames`` and ``skipped`` at least), build :attr:`windows` in :meth:`_build_windows` through
    :meth:`_index_windows`, and make the items.
    """

    kind: ClassVar[DatasetKind]
    feature_shape: ClassVar[tuple[int, ...]]  # per person and frame
    default_max_length: ClassVar[int]  # frames
    default_min_length: ClassVar[int]
    default_swap_persons: ClassVar[bool]  # random person order, the reference's choice
    default_normalize: ClassVar[bool]  # z-scored features, the reference's choice
    supports_mirror: ClassVar[bool] = False  # takes a ``mirror`` argument

    clip_ids: list[str]
    frames: np.ndarray  # (clips,) frames per clip as stored
    skipped: list[SkippedClip]
    windows: WindowIndex

    def __init__(
        self,
        *,
        root: str | Path,
        split: str,
        mode: Mode,
        max_length: int,
        min_length: int,
        window: int,
        stride: int,
        window_persons: int,
        swap_persons: bool,
        normalizer: Normalizer | None,
        seed: int,
        epoch: int,
    ):
        if mode not in ("interaction", "window"):
            raise ValueError(f"mode must be 'interaction' or 'window', got {mode!r}")
        if window_persons not in (1, 2):
            raise ValueError(f"window_persons must be 1 or 2, got {window_persons}")
        if not 2 <= min_length <= max_length:
            raise ValueError(
                f"need 2 <= min_length <= max_length, got {min_length} and {max_length}"
            )
        if normalizer is not None and normalizer.feature_shape != self.feature_shape:
            raise ValueError(
                f"normalizer must have shape {self.feature_shape}, got {normalizer.feature_shape}"
            )
        self.root, self.split, self.mode = Path(root), split, mode
        self.max_length, self.min_length = max_length, min_length
        self.window, self.stride, self.window_persons = window, stride, window_persons
        self.swap_persons, self.normalizer = swap_persons, normalizer
        self.seed, self.epoch = seed, epoch
        self._load()
        if mode == "window":
            self._build_windows()

    @classmethod
    def for_statistics(cls, root: str | Path, split: str) -> ClipReader:
        """The split's whole clips, augmentation off, un-normalized: what the statistics read."""
        return cls(root=root, split=split, mode="interaction", swap_persons=False)

    # ------------------------------------------------------------------ subclass hooks

    @property
    @abstractmethod
    def split_file(self) -> Path:
        """The file listing this split's clips (named in errors about the split)."""

    @abstractmethod
    def _load(self) -> None:
        """Read the split; set ``clip_ids``, ``frames``, ``skipped`` and the subclass's storage."""

    @abstractmethod
    def _build_windows(self) -> None:
        """Set :attr:`windows` through :meth:`_index_windows`."""

    @abstractmethod
    def _interaction_count(self) -> int:
        """Interaction items in one pass (clips, times two with mirrored copies)."""

    @abstractmethod
    def _interaction_item(self, index: int, rng: np.random.Generator) -> dict[str, Any]: ...

    @abstractmethod
    def _window_item(self, index: int) -> dict[str, Any]: ...

    @abstractmethod
    def stats_sequences(self) -> Iterator[torch.Tensor]:
        """Un-normalized features of every clip in the distribution training sees, for the
        normalization statistics (each subclass says which copies)."""

    # ------------------------------------------------------------------ shared protocol

    def _index_windows(self, lengths: Sequence[int], short: Sequence[SkippedClip]) -> None:
        """:attr:`windows` over sequences of ``lengths`` frames; ``short`` (clips without a
        window) is logged, and a split without any window is an error naming its file."""
        self.windows = build_window_index(lengths, window=self.window, stride=self.stride)
        log_skipped(short, where=f"{self.split_file} (windows)")
        if len(self.windows.start) == 0:
            raise DataError(
                f"{self.split_file}: no clip is long enough for a {self.window}-frame window"
            )

    def _check_not_empty(self, listed: int, why: str) -> None:
        """A split whose clips were all skipped is an error naming its file and the reasons."""
        log_skipped(self.skipped, where=str(self.split_file))
        if not self.clip_ids:
            raise DataError(
                f"{self.split_file}: split resolves to zero clips ({listed} listed, "
                f"{len(self.skipped)} skipped: {why})"
            )

    def _normalize(self, features: torch.Tensor) -> torch.Tensor:
        return features if self.normalizer is None else self.normalizer.normalize(features)

    def __len__(self) -> int:
        if self.mode == "window":
            return len(self.windows.start)
        return self._interaction_count()

    def __getitem__(self, key: ItemKey) -> dict[str, Any]:
        return self.__getitems__([key])[0]

    def __getitems__(self, keys: Sequence[ItemKey]) -> list[dict[str, Any]]:
        """The items of ``keys``, equal to ``[self[key] for key in keys]``. A DataLoader fetches
        each batch through this, so a reader can do a batch's work in one pass
        (:meth:`_interaction_items`)."""
        pairs = [split_key(key, self.epoch) for key in keys]
        for index, _ in pairs:
            if not 0 <= index < len(self):
                raise IndexError(f"index {index} out of range for {len(self)} items")
        with single_threaded():
            if self.mode == "window":
                return [self._window_item(index) for index, _ in pairs]
            draws = [(index, item_rng(self.seed, epoch, index)) for index, epoch in pairs]
            return self._interaction_items(draws)

    def _interaction_items(
        self, draws: Sequence[tuple[int, np.random.Generator]]
    ) -> list[dict[str, Any]]:
        """Interaction items of ``(index, generator)`` pairs, one at a time; a reader whose items
        share work overrides this to batch it."""
        return [self._interaction_item(index, rng) for index, rng in draws]
