"""Dataset readers (InterHuman, Inter-X, HumanML3D, synthetic), normalization, windowing, validation, DataModule.

Shapes: P persons (2), T frames, C channels. InterHuman items carry (P, T, 262) features,
Inter-X items (P, T, 56, 6), HumanML3D items (T, 263) (one person); VQ windows are
single-person (T, C...).
"""

from intermask.data.captions import swap_left_right
from intermask.data.common import EpochSampler, item_rng
from intermask.data.errors import DataError, DataProblem, SkippedClip
from intermask.data.humanml3d import HumanML3DDataset
from intermask.data.interhuman import InterHumanDataset
from intermask.data.interx import InterXDataset
from intermask.data.item import ExportedItem, export_item, load_item
from intermask.data.normalization import Normalizer, default_stats_dir
from intermask.data.reader import ClipReader
from intermask.data.readers import READERS, reader_class
from intermask.data.statistics import compute_and_save_stats
from intermask.data.validation import CheckReport, check_dataset, check_dataset_report
from intermask.data.windows import WindowIndex, build_window_index, window_count


def __getattr__(name: str):
    # The DataModule pulls in Lightning; import it only when asked for.
    if name == "InteractionDataModule":
        from intermask.data.datamodule import InteractionDataModule

        return InteractionDataModule
    raise AttributeError(f"module 'intermask.data' has no attribute {name!r}")


__all__ = [
    "READERS",
    "CheckReport",
    "ClipReader",
    "DataError",
    "DataProblem",
    "EpochSampler",
    "ExportedItem",
    "HumanML3DDataset",
    "InterHumanDataset",
    "InterXDataset",
    "InteractionDataModule",
    "Normalizer",
    "SkippedClip",
    "WindowIndex",
    "build_window_index",
    "check_dataset",
    "check_dataset_report",
    "compute_and_save_stats",
    "default_stats_dir",
    "export_item",
    "item_rng",
    "load_item",
    "reader_class",
    "swap_left_right",
    "window_count",
]
