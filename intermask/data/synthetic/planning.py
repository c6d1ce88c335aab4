"""Dataset-level plans of the synthetic writers: which action and split each clip gets, and the
output folder's check (empty, or an earlier synthetic dataset that is replaced)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np

from intermask.data.synthetic.writers import META_FILE, META_FORMAT
from intermask.motion.actions import ACTIONS

_SPLIT_STREAM = 1  # random streams of the dataset-level draws, apart from the per-clip ones
_ACTION_STREAM = 2
# What a previous synthetic dataset (and statistics computed from it) may have left in `out`.
_OWN_ENTRIES = (
    "annots",
    "motions",
    "motions_processed",
    "split",
    "splits",
    "texts_processed",
    "stats",
    "ignore_list.txt",
    META_FILE,
    "README.txt",
)


_DATASET_STREAM_TAG = 0x5EED  # any non-zero word


def _dataset_rng(seed: int, stream: int) -> np.random.Generator:
    # Clip streams are SeedSequence([seed, index]). SeedSequence drops trailing zero words, so a
    # third word must be non-zero to keep dataset-level streams apart from the clip streams.
    return np.random.default_rng(np.random.SeedSequence([seed, stream, _DATASET_STREAM_TAG]))


def assign_actions(clips: int, seed: int) -> list[str]:
    """Round-robin over a seed-shuffled order of ACTIONS: every type gets clips // 14 or one more."""
    order = _dataset_rng(seed, _ACTION_STREAM).permutation(len(ACTIONS))
    return [ACTIONS[int(order[i % len(ACTIONS)])] for i in range(clips)]


def assign_splits(clips: int, seed: int, fractions: tuple[float, float, float]) -> list[str]:
    """Split name of every clip: a seeded permutation cut into train/val/test blocks; every split
    with a positive fraction gets at least one clip."""
    if (
        len(fractions) != 3
        or min(fractions) < 0
        or abs(sum(fractions) - 1.0) > 1e-6
        or fractions[0] <= 0
    ):
        raise ValueError(
            f"split_fractions must be 3 non-negative numbers summing to 1 with train > 0, got {fractions}"
        )
    sizes = [max(1, round(f * clips)) if f > 0 else 0 for f in fractions[1:]]
    train = clips - sum(sizes)
    if train < 1:
        raise ValueError(
            f"{clips} clips cannot fill the splits {fractions}; generate at least 3 clips"
        )
    labels = np.array(["train"] * train + ["val"] * sizes[0] + ["test"] * sizes[1])
    return labels[_dataset_rng(seed, _SPLIT_STREAM).permutation(clips)].tolist()


def _is_synthetic(meta: Path) -> bool:
    try:
        return json.loads(meta.read_text(encoding="utf-8")).get("format") == META_FORMAT
    except (OSError, ValueError, AttributeError):
        return False


def check_folder(out: Path) -> list[str]:
    """Refuse (FileExistsError) an `out` that is not missing, empty or an earlier synthetic
    dataset -> the entries of that dataset (and of statistics computed from it) in `out`."""
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"{out} exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not _is_synthetic(out / META_FILE):
        raise FileExistsError(
            f"{out} is not empty and holds no synthetic dataset (no {META_FILE} with format "
            f"{META_FORMAT!r}); choose an empty folder"
        )
    return [name for name in _OWN_ENTRIES if (out / name).exists()]


def prepare_folder(out: Path) -> None:
    """Create `out`; clear it if it holds an earlier synthetic dataset; refuse anything else."""
    if check_folder(out):
        for name in _OWN_ENTRIES:
            path = out / name
            if path.is_dir():
                shutil.rmtree(path)
            elif path.exists():
                path.unlink()
    out.mkdir(parents=True, exist_ok=True)
