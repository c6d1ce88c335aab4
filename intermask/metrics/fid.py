"""Frechet distance between two sets of evaluator embeddings (docs/evaluation.md, "FID")."""

from __future__ import annotations

import torch
from torchmetrics import Metric

from intermask.metrics.dedup import gather_samples, sample_id_column
from intermask.metrics.functional import (
    FID_COVARIANCE_EPS,
    FID_IMAGINARY_ATOL,
    frechet_distance,
    gaussian_statistics,
)


class FID(Metric):
    """FID of the ``real=False`` set against the ``real=True`` set, embeddings x ``emb_scale``.

    ``update(embeddings (B, D), *, real: bool, sample_ids (B,) int64 | None = None)``;
    ``compute() -> ()`` float64. Generation FID: real = GT embeddings of a second,
    independently re-sampled pass over the test set, fake = generated. VQ reconstruction FID:
    real = GT embeddings, fake = embeddings of the reconstructions of the same clips.

    Unlike torchmetrics' FID (running float64 sums), every embedding is kept: padded
    duplicates from a ``DistributedSampler`` can only be removed by id at ``compute``. The
    cost is small (N x D floats, N a few thousand). Mean and unbiased covariance are taken in
    float64; see ``functional.frechet_distance`` for the safeguards.
    """

    full_state_update = False
    higher_is_better = False
    is_differentiable = False

    def __init__(
        self,
        *,
        emb_scale: float = 1.0,
        eps: float = FID_COVARIANCE_EPS,
        imaginary_atol: float = FID_IMAGINARY_ATOL,
    ) -> None:
        super().__init__()
        self.emb_scale = emb_scale
        self.eps = eps
        self.imaginary_atol = imaginary_atol
        for name in ("real_embeddings", "real_ids", "fake_embeddings", "fake_ids"):
            self.add_state(name, default=[], dist_reduce_fx="cat")

    def update(
        self, embeddings: torch.Tensor, *, real: bool, sample_ids: torch.Tensor | None = None
    ) -> None:
        if embeddings.ndim != 2:
            raise ValueError(f"FID needs (B, D) embeddings, got {tuple(embeddings.shape)}")
        if not bool(torch.isfinite(embeddings).all()):
            raise ValueError(f"FID: {'real' if real else 'fake'} embeddings contain NaN or inf")
        ids = sample_id_column(
            sample_ids, embeddings.shape[0], metric="FID", device=embeddings.device
        )
        prefix = "real" if real else "fake"
        getattr(self, f"{prefix}_embeddings").append(embeddings.detach().double())
        getattr(self, f"{prefix}_ids").append(ids)

    def compute(self) -> torch.Tensor:
        statistics = []
        for prefix in ("real", "fake"):
            stored = getattr(self, f"{prefix}_embeddings")
            # a list before the DDP gather, one tensor after it
            values = (
                gather_samples(stored, getattr(self, f"{prefix}_ids"), metric="FID")
                if len(stored)
                else None
            )
            count = 0 if values is None else values.shape[0]
            if values is None or count < 2:
                raise ValueError(f"FID needs at least 2 {prefix} embeddings, got {count}")
            statistics.append(gaussian_statistics(values.cpu().numpy() * self.emb_scale))
        (mu_real, sigma_real), (mu_fake, sigma_fake) = statistics
        value = frechet_distance(
            mu_real,
            sigma_real,
            mu_fake,
            sigma_fake,
            eps=self.eps,
            imaginary_atol=self.imaginary_atol,
        )
        return torch.tensor(value, dtype=torch.float64)
