"""Spread of generated embeddings: Diversity over the whole set, MultiModality per text."""

from __future__ import annotations

import torch
from torchmetrics import Metric

from intermask.metrics.dedup import gather_samples, sample_id_column
from intermask.metrics.functional import diversity, multimodality


def _check_finite(embeddings: torch.Tensor, *, metric: str) -> None:
    if not bool(torch.isfinite(embeddings).all()):
        raise ValueError(f"{metric}: embeddings contain NaN or inf")


class Diversity(Metric):
    """Mean distance between ``num_pairs`` random pairs of samples, x ``emb_scale`` / ``divide_by``.

    ``update(embeddings (B, D), sample_ids (B,) int64 | None)``; ``compute() -> ()`` float64.
    Paper values (docs/evaluation.md): 300 pairs; InterHuman emb_scale 6, divide_by 2;
    Inter-X 1, 1.
    The pairs come from ``functional.draw_pair_indices(N, num_pairs, seed=seed)`` over the
    samples in ascending sample-id order (update order without ids), so ``compute`` is
    deterministic; a protocol replication passes its own ``seed``.
    """

    full_state_update = False
    higher_is_better = None  # closer to the ground truth's value is better
    is_differentiable = False

    def __init__(
        self,
        *,
        num_pairs: int = 300,
        emb_scale: float = 1.0,
        divide_by: float = 1.0,
        seed: int = 3407,
    ) -> None:
        super().__init__()
        if num_pairs < 1:
            raise ValueError(f"Diversity num_pairs must be >= 1, got {num_pairs}")
        self.num_pairs = num_pairs
        self.emb_scale = emb_scale
        self.divide_by = divide_by
        self.seed = seed
        self.add_state("embeddings", default=[], dist_reduce_fx="cat")
        self.add_state("sample_ids", default=[], dist_reduce_fx="cat")

    def update(self, embeddings: torch.Tensor, sample_ids: torch.Tensor | None = None) -> None:
        if embeddings.ndim != 2:
            raise ValueError(f"Diversity needs (B, D) embeddings, got {tuple(embeddings.shape)}")
        _check_finite(embeddings, metric="Diversity")
        self.embeddings.append(embeddings.detach().double())
        self.sample_ids.append(
            sample_id_column(
                sample_ids, embeddings.shape[0], metric="Diversity", device=embeddings.device
            )
        )

    def compute(self) -> torch.Tensor:
        values = gather_samples(self.embeddings, self.sample_ids, metric="Diversity")
        return diversity(
            values,
            num_pairs=self.num_pairs,
            seed=self.seed,
            emb_scale=self.emb_scale,
            divide_by=self.divide_by,
        )


class MultiModality(Metric):
    """Mean distance between ``num_pairs`` random pairs of generations of one text, x ``scale``.

    ``update(embeddings (B, G, D), sample_ids (B,) int64 | None)``: G generations for each of
    B texts, G >= num_pairs (paper: 100 texts x 30 generations, 10 pairs). One pair draw over
    the G generations, ``functional.draw_pair_indices(G, num_pairs, seed=seed)``, is shared by
    all texts. ``scale`` is the convention's factor and the caller's choice: the InterMask code
    applies x3 (= emb_scale 6 / 2) on InterHuman, InterGen applies none (1.0), Inter-X 1.0.
    ``compute() -> ()`` float64.
    """

    full_state_update = False
    higher_is_better = True
    is_differentiable = False

    def __init__(self, *, num_pairs: int = 10, scale: float = 1.0, seed: int = 3407) -> None:
        super().__init__()
        if num_pairs < 1:
            raise ValueError(f"MultiModality num_pairs must be >= 1, got {num_pairs}")
        self.num_pairs = num_pairs
        self.scale = scale
        self.seed = seed
        self.add_state("embeddings", default=[], dist_reduce_fx="cat")
        self.add_state("sample_ids", default=[], dist_reduce_fx="cat")

    def update(self, embeddings: torch.Tensor, sample_ids: torch.Tensor | None = None) -> None:
        if embeddings.ndim != 3:
            raise ValueError(
                f"MultiModality needs (B, G, D) embeddings, got {tuple(embeddings.shape)}"
            )
        if embeddings.shape[1] < self.num_pairs:
            raise ValueError(
                f"MultiModality needs G >= num_pairs={self.num_pairs} generations per text, "
                f"got G={embeddings.shape[1]}"
            )
        _check_finite(embeddings, metric="MultiModality")
        self.embeddings.append(embeddings.detach().double())
        self.sample_ids.append(
            sample_id_column(
                sample_ids, embeddings.shape[0], metric="MultiModality", device=embeddings.device
            )
        )

    def compute(self) -> torch.Tensor:
        values = gather_samples(self.embeddings, self.sample_ids, metric="MultiModality")
        return multimodality(values, num_pairs=self.num_pairs, seed=self.seed, scale=self.scale)
