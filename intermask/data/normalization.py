"""Per-feature z-score normalization: one mean/std pair shared by both persons.

Our statistics are computed by our own code from the training split and saved next to the data
as ``<root>/stats/{mean,std}.npy`` plus ``stats.json`` (provenance). Statistics released with the
reference code (``global_mean.npy`` / ``global_std.npy``, shape (262,)) load through the same
class.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from intermask.data.errors import DataError

STATS_DIRNAME = "stats"
MEAN_FILE = "mean.npy"
STD_FILE = "std.npy"
PROVENANCE_FILE = "stats.json"
REFERENCE_MEAN_FILE = "global_mean.npy"
REFERENCE_STD_FILE = "global_std.npy"
STATS_FORMAT = "intermask-stats-v1"


class Normalizer:
    """``normalize(x) = (x - mean) / std`` over the trailing dims of ``x`` that match ``mean``.

    mean, std: (C,) for InterHuman (C = 262) or (J, C) for Inter-X (56, 6). Inputs are
    ``(..., *mean.shape)`` tensors or arrays; the output has the input's type, dtype and device.
    ``denormalize(normalize(x)) == x`` up to float rounding.
    """

    def __init__(
        self,
        mean: torch.Tensor | np.ndarray,
        std: torch.Tensor | np.ndarray,
        *,
        source: str = "memory",
    ):
        mean_t = torch.as_tensor(np.asarray(mean, dtype=np.float64))
        std_t = torch.as_tensor(np.asarray(std, dtype=np.float64))
        _check_stats(mean_t, std_t, source)
        self.mean = mean_t
        self.std = std_t
        self.source = source

    @classmethod
    def identity(cls, shape: tuple[int, ...]) -> Normalizer:
        """No-op normalizer (Inter-X default: the reference trains on raw 6D + translation)."""
        return cls(torch.zeros(shape), torch.ones(shape), source="identity")

    @property
    def feature_shape(self) -> tuple[int, ...]:
        return tuple(self.mean.shape)

    @property
    def is_identity(self) -> bool:
        return bool(torch.all(self.mean == 0) and torch.all(self.std == 1))

    def normalize(self, x: torch.Tensor | np.ndarray) -> torch.Tensor | np.ndarray:
        """(..., *feature_shape) -> same shape, z-scored."""
        mean, std = self._like(x)
        return (x - mean) / std

    def denormalize(self, x: torch.Tensor | np.ndarray) -> torch.Tensor | np.ndarray:
        """(..., *feature_shape) -> same shape, back in feature units."""
        mean, std = self._like(x)
        return x * std + mean

    def _like(self, x: torch.Tensor | np.ndarray) -> tuple[Any, Any]:
        n = self.mean.dim()
        if tuple(x.shape[x.ndim - n :]) != self.feature_shape:
            raise ValueError(
                f"normalizer expects trailing dims {self.feature_shape} ({self.source}), "
                f"got input of shape {tuple(x.shape)}"
            )
        if isinstance(x, torch.Tensor):
            return self.mean.to(x.device, x.dtype), self.std.to(x.device, x.dtype)
        return self.mean.numpy().astype(x.dtype), self.std.numpy().astype(x.dtype)

    def save(self, directory: str | Path, *, provenance: dict[str, Any] | None = None) -> Path:
        """Write mean.npy, std.npy (float32) and stats.json into ``directory``; returns it."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        _atomic_save(directory / MEAN_FILE, self.mean.numpy().astype(np.float32))
        _atomic_save(directory / STD_FILE, self.std.numpy().astype(np.float32))
        info = {"format": STATS_FORMAT, "shape": list(self.feature_shape), **(provenance or {})}
        tmp = directory / (PROVENANCE_FILE + ".tmp")
        tmp.write_text(json.dumps(info, indent=2, sort_keys=True))
        os.replace(tmp, directory / PROVENANCE_FILE)
        return directory

    @classmethod
    def load(
        cls, directory: str | Path, *, feature_shape: tuple[int, ...] | None = None
    ) -> Normalizer:
        """Load ours (mean.npy/std.npy) or the reference's (global_mean.npy/global_std.npy).

        Ours win when both are present. ``feature_shape`` (e.g. (262,)) is checked when given.
        """
        directory = Path(directory)
        for mean_name, std_name in (
            (MEAN_FILE, STD_FILE),
            (REFERENCE_MEAN_FILE, REFERENCE_STD_FILE),
        ):
            if (directory / mean_name).is_file() and (directory / std_name).is_file():
                return cls.from_files(
                    directory / mean_name, directory / std_name, feature_shape=feature_shape
                )
        raise DataError(
            f"{directory}: no normalization statistics (expected {MEAN_FILE} + {STD_FILE} or "
            f"{REFERENCE_MEAN_FILE} + {REFERENCE_STD_FILE})"
        )

    @classmethod
    def from_files(
        cls,
        mean_path: str | Path,
        std_path: str | Path,
        *,
        feature_shape: tuple[int, ...] | None = None,
    ) -> Normalizer:
        mean = _load_array(Path(mean_path))
        std = _load_array(Path(std_path))
        for path, arr in ((mean_path, mean), (std_path, std)):
            if feature_shape is not None and tuple(arr.shape) != tuple(feature_shape):
                raise DataError(
                    f"{path}: expected shape {tuple(feature_shape)}, got {tuple(arr.shape)}"
                )
        return cls(mean, std, source=f"{mean_path} + {std_path}")


def stats_exist(directory: str | Path) -> bool:
    directory = Path(directory)
    return any(
        (directory / m).is_file() and (directory / s).is_file()
        for m, s in ((MEAN_FILE, STD_FILE), (REFERENCE_MEAN_FILE, REFERENCE_STD_FILE))
    )


class StatsAccumulator:
    """Running float64 sums for a per-feature mean and population std over many sequences."""

    def __init__(self, feature_shape: tuple[int, ...]):
        self.feature_shape = tuple(feature_shape)
        self.total = np.zeros(self.feature_shape, dtype=np.float64)
        self.total_sq = np.zeros(self.feature_shape, dtype=np.float64)
        self.count = 0

    def update(self, frames: torch.Tensor | np.ndarray) -> None:
        """frames: (..., *feature_shape); every leading entry counts as one sample."""
        x = np.asarray(frames, dtype=np.float64).reshape((-1, *self.feature_shape))
        self.total += x.sum(axis=0)
        self.total_sq += np.square(x).sum(axis=0)
        self.count += x.shape[0]

    def compute(self, *, min_std: float) -> tuple[np.ndarray, np.ndarray, int]:
        """Returns (mean, std, number of features whose std was raised to ``min_std``)."""
        if self.count == 0:
            raise ValueError("no frames were accumulated: cannot compute statistics")
        mean = self.total / self.count
        var = np.maximum(self.total_sq / self.count - np.square(mean), 0.0)
        std = np.sqrt(var)
        # Constant features (e.g. a foot contact that never fires in a small dataset) would divide
        # by zero; a floor keeps them at 0 after normalization instead of exploding.
        floored = int((std < min_std).sum())
        return mean, np.maximum(std, min_std), floored


def compute_normalizer(
    sequences: Iterable[torch.Tensor | np.ndarray],
    *,
    feature_shape: tuple[int, ...],
    min_std: float = 1e-3,
) -> tuple[Normalizer, dict[str, Any]]:
    """Mean/std over all frames of all sequences (each (..., *feature_shape)) + a provenance dict."""
    acc = StatsAccumulator(feature_shape)
    num_sequences = 0
    for seq in sequences:
        acc.update(seq)
        num_sequences += 1
    mean, std, floored = acc.compute(min_std=min_std)
    info = {
        "num_sequences": num_sequences,
        "num_frames": acc.count,
        "min_std": min_std,
        "floored_dims": floored,
    }
    return Normalizer(mean, std, source="computed"), info


def default_stats_dir(root: str | Path) -> Path:
    return Path(root) / STATS_DIRNAME


def _check_stats(mean: torch.Tensor, std: torch.Tensor, source: str) -> None:
    if mean.shape != std.shape:
        raise DataError(f"{source}: mean shape {tuple(mean.shape)} != std shape {tuple(std.shape)}")
    for name, arr in (("mean", mean), ("std", std)):
        if not torch.isfinite(arr).all():
            bad = int((~torch.isfinite(arr)).sum())
            raise DataError(f"{source}: {name} has {bad} NaN/Inf values")
    if (std <= 0).any():
        idx = torch.nonzero(std.reshape(-1) <= 0).reshape(-1)[:8].tolist()
        raise DataError(
            f"{source}: std must be > 0 everywhere, got zero/negative std at flat indices {idx}"
        )


def _load_array(path: Path) -> np.ndarray:
    if not path.is_file():
        raise DataError(f"{path}: statistics file not found")
    try:
        return np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise DataError(f"{path}: cannot read as .npy ({err})") from err


def _atomic_save(path: Path, array: np.ndarray) -> None:
    # Several processes (DDP ranks) may race to write the same statistics: write then rename.
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npy")
    np.save(tmp, array)
    os.replace(tmp, path)
