"""torchmetrics metrics; each wraps a plain function that tests check independently."""

from intermask.metrics.diversity import Diversity, MultiModality
from intermask.metrics.fid import FID
from intermask.metrics.mpjpe import MPJPE
from intermask.metrics.retrieval import MMDist, RPrecision

__all__ = ["FID", "MMDist", "MPJPE", "Diversity", "MultiModality", "RPrecision"]
