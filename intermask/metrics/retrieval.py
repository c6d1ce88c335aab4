"""Text-motion retrieval metrics computed within eval batches: R-precision and MM Dist."""

from __future__ import annotations

import torch
from torchmetrics import Metric

from intermask.metrics.dedup import gather_samples, sample_id_column
from intermask.metrics.functional import (
    euclidean_distance_matrix,
    matching_distances,
    top_k_hits,
)


def _check_pair(text: torch.Tensor, motion: torch.Tensor, *, metric: str) -> None:
    if text.ndim != 2 or text.shape != motion.shape:
        raise ValueError(
            f"{metric} needs text and motion embeddings of one (B, D) shape, got "
            f"{tuple(text.shape)} and {tuple(motion.shape)}"
        )
    if not (bool(torch.isfinite(text).all()) and bool(torch.isfinite(motion).all())):
        raise ValueError(f"{metric}: embeddings contain NaN or inf")


class RPrecision(Metric):
    """R-precision top-1..``top_k``: share of texts whose own motion is among the k nearest.

    ``update(text_embeddings (B, D), motion_embeddings (B, D), sample_ids (B,) int64 | None)``
    with one call per eval batch (row i of both is one sample): the distance matrix is
    texts x motions within that batch only (InterHuman B = 96, Inter-X B = 32, drop_last), so
    the caller's batching is part of the metric. ``compute() -> (top_k,)`` float64, cumulative.
    Per-sample hits are kept so duplicates can be dropped by id; under DDP each rank must
    receive whole eval batches for the grouping to match a single process.
    """

    full_state_update = False
    higher_is_better = True
    is_differentiable = False

    def __init__(self, *, top_k: int = 3) -> None:
        super().__init__()
        if top_k < 1:
            raise ValueError(f"RPrecision top_k must be >= 1, got {top_k}")
        self.top_k = top_k
        # float 0/1 rather than bool: every DDP backend gathers floating tensors
        self.add_state("hits", default=[], dist_reduce_fx="cat")
        self.add_state("sample_ids", default=[], dist_reduce_fx="cat")

    def update(
        self,
        text_embeddings: torch.Tensor,
        motion_embeddings: torch.Tensor,
        sample_ids: torch.Tensor | None = None,
    ) -> None:
        _check_pair(text_embeddings, motion_embeddings, metric="RPrecision")
        batch = text_embeddings.shape[0]
        if batch < self.top_k:
            raise ValueError(
                f"RPrecision: an eval batch of {batch} samples cannot rank top_k={self.top_k}"
            )
        distances = euclidean_distance_matrix(text_embeddings.detach(), motion_embeddings.detach())
        self.hits.append(top_k_hits(distances, top_k=self.top_k).double())  # (B, top_k)
        self.sample_ids.append(
            sample_id_column(sample_ids, batch, metric="RPrecision", device=text_embeddings.device)
        )

    def compute(self) -> torch.Tensor:
        return gather_samples(self.hits, self.sample_ids, metric="RPrecision").mean(dim=0)


class MMDist(Metric):
    """Multimodal distance: mean ``||s_i - m_i||`` over samples (no scaling).

    ``update(text_embeddings (B, D), motion_embeddings (B, D), sample_ids (B,) int64 | None)``;
    ``compute() -> ()`` float64.
    """

    full_state_update = False
    higher_is_better = False
    is_differentiable = False

    def __init__(self) -> None:
        super().__init__()
        self.add_state("distances", default=[], dist_reduce_fx="cat")
        self.add_state("sample_ids", default=[], dist_reduce_fx="cat")

    def update(
        self,
        text_embeddings: torch.Tensor,
        motion_embeddings: torch.Tensor,
        sample_ids: torch.Tensor | None = None,
    ) -> None:
        _check_pair(text_embeddings, motion_embeddings, metric="MMDist")
        self.distances.append(
            matching_distances(text_embeddings.detach(), motion_embeddings.detach())
        )
        self.sample_ids.append(
            sample_id_column(
                sample_ids, text_embeddings.shape[0], metric="MMDist", device=text_embeddings.device
            )
        )

    def compute(self) -> torch.Tensor:
        return gather_samples(self.distances, self.sample_ids, metric="MMDist").mean()
