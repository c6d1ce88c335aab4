"""torchmetrics metrics; each wraps a plain function that tests check independently."""

from intermask.metrics.diversity import Diversity, MultiModality
from intermask.metrics.fid import FID
from intermask.metrics.mpjpe import MPJPE
from intermask.metrics.retrieval import MMDist, RPrecision
from intermask.metrics.success import InteractionSuccess

__all__ = [
    "FID",
    "MMDist",
    "MPJPE",
    "Diversity",
    "InteractionSuccess",
    "MultiModality",
    "RPrecision",
]
