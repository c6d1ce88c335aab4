"""Normalization statistics of a dataset, computed by reading its training split with the
readers (which themselves only need :class:`~intermask.data.normalization.Normalizer`)."""

from __future__ import annotations

from pathlib import Path

from intermask.data.normalization import (
    Normalizer,
    compute_normalizer,
    default_stats_dir,
)
from intermask.data.reader import ClipReader
from intermask.data.readers import reader_class
from intermask.motion.kinds import DatasetKind


def compute_and_save_stats(
    root: str | Path,
    *,
    dataset: DatasetKind,
    reader: str | type[ClipReader] | None = None,
    split: str = "train",
    out_dir: str | Path | None = None,
    min_std: float = 1e-3,
) -> Normalizer:
    """Compute statistics from ``split`` of the dataset under ``root`` and save them.

    InterHuman: canonicalized full training clips, both persons (person 2 in person 1's frame),
    both choices of reference person and their mirrored copies. Inter-X: the (56, 6) person
    representation of both persons (each reader's ``stats_sequences``). Saved to ``out_dir``
    (default ``<root>/stats``).
    """
    ds = reader_class(dataset, reader).for_statistics(root, split)
    normalizer, info = compute_normalizer(
        ds.stats_sequences(), feature_shape=ds.feature_shape, min_std=min_std
    )
    info.update(
        {
            "dataset": dataset,
            "split": split,
            "root": str(Path(root).resolve()),
            "num_clips": len(ds.clip_ids),
        }
    )
    normalizer.save(out_dir if out_dir is not None else default_stats_dir(root), provenance=info)
    return normalizer
