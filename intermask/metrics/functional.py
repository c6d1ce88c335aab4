"""Plain metric math (docs/evaluation.md, "Metrics"): the functions the torchmetrics classes wrap.

Shapes: ``N`` samples, ``B`` eval batch, ``G`` generations per text, ``D`` embedding width.
Everything that tests compare against numpy is computed in float64.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg
import torch

# docs/evaluation.md, "FID": offset added to both covariances when sqrtm(S1 S2) is not finite, and
# the largest imaginary part of its diagonal that counts as round-off.
FID_COVARIANCE_EPS = 1e-6
FID_IMAGINARY_ATOL = 1e-3


def euclidean_distance_matrix(text: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
    """``text (B, D)``, ``motion (B', D)`` -> ``(B, B')`` float64 with ``[i, j] = ||s_i - m_j||``."""
    if text.ndim != 2 or motion.ndim != 2 or text.shape[1] != motion.shape[1]:
        raise ValueError(
            "distances need text (B, D) and motion (B', D) embeddings of one width, got "
            f"{tuple(text.shape)} and {tuple(motion.shape)}"
        )
    # The direct difference (not the |a|^2 + |b|^2 - 2ab expansion) so the diagonal of
    # perfectly matched pairs is exactly 0 and ties are not created by cancellation.
    return torch.cdist(text.double(), motion.double(), compute_mode="donot_use_mm_for_euclid_dist")


def top_k_hits(distances: torch.Tensor, *, top_k: int) -> torch.Tensor:
    """``distances (B, B)`` texts x motions -> ``(B, top_k)`` bool, cumulative hit@1..top_k.

    Row ``i`` is a hit at ``k`` when motion ``i`` is among the ``k`` nearest motions of text
    ``i``. Ties are broken by a stable sort (a lower motion index ranks first), which is
    deterministic where the reference's numpy quicksort is not.
    """
    if distances.ndim != 2 or distances.shape[0] != distances.shape[1]:
        raise ValueError(
            f"R-precision needs a square (B, B) distance matrix, got {tuple(distances.shape)}"
        )
    batch = distances.shape[0]
    if not 1 <= top_k <= batch:
        raise ValueError(f"R-precision top_k must lie in [1, B={batch}], got {top_k}")
    order = torch.argsort(distances, dim=1, stable=True)  # (B, B) motion indices, nearest first
    own = torch.arange(batch, device=distances.device)[:, None]
    rank = (order == own).int().argmax(dim=1)  # (B,) position of the true motion
    return rank[:, None] < torch.arange(1, top_k + 1, device=distances.device)[None, :]


def matching_distances(text: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
    """``text (B, D)``, ``motion (B, D)`` -> ``(B,)`` float64 ``||s_i - m_i||`` (MM Dist terms)."""
    if text.shape != motion.shape or text.ndim != 2:
        raise ValueError(
            "MM Dist needs text and motion embeddings of one (B, D) shape, got "
            f"{tuple(text.shape)} and {tuple(motion.shape)}"
        )
    return torch.linalg.vector_norm(text.double() - motion.double(), dim=1)


def gaussian_statistics(embeddings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(N, D)`` -> mean ``(D,)`` and unbiased (N - 1) covariance ``(D, D)``, float64."""
    embeddings = np.asarray(embeddings, dtype=np.float64)
    if embeddings.ndim != 2 or embeddings.shape[0] < 2:
        raise ValueError(f"FID statistics need (N >= 2, D) embeddings, got {embeddings.shape}")
    return embeddings.mean(axis=0), np.cov(embeddings, rowvar=False, ddof=1)


def _sqrtm(matrix: np.ndarray) -> np.ndarray:
    # scipy warns about singular products (N < D, or rank-deficient sets); the caller checks
    # finiteness and the imaginary part itself, so the warning would only be noise.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", scipy.linalg.LinAlgWarning)
        return scipy.linalg.sqrtm(matrix)


def frechet_distance(
    mu1: np.ndarray,
    sigma1: np.ndarray,
    mu2: np.ndarray,
    sigma2: np.ndarray,
    *,
    eps: float = FID_COVARIANCE_EPS,
    imaginary_atol: float = FID_IMAGINARY_ATOL,
) -> float:
    """Frechet distance of two Gaussians: ``||mu1 - mu2||^2 + Tr(S1) + Tr(S2) - 2 Tr(sqrtm(S1 S2))``.

    ``mu (D,)``, ``sigma (D, D)``. If ``sqrtm(S1 S2)`` is not finite, ``eps * I`` is added to
    both covariances and it is retried. A complex square root is accepted when the imaginary
    parts of its diagonal (the only entries the trace uses) are within ``imaginary_atol``;
    otherwise ``ValueError`` names the largest one.
    """
    mu1, mu2 = (np.atleast_1d(np.asarray(mu, np.float64)) for mu in (mu1, mu2))
    sigma1, sigma2 = (np.atleast_2d(np.asarray(s, np.float64)) for s in (sigma1, sigma2))
    width = mu1.shape[0]
    if mu2.shape != (width,) or sigma1.shape != (width, width) or sigma2.shape != (width, width):
        raise ValueError(
            f"FID needs means (D,) and covariances (D, D) of one width, got {mu1.shape}, "
            f"{sigma1.shape}, {mu2.shape}, {sigma2.shape}"
        )
    covmean = _sqrtm(sigma1 @ sigma2)
    if not np.isfinite(covmean).all():
        offset = np.eye(width) * eps
        covmean = _sqrtm((sigma1 + offset) @ (sigma2 + offset))
        if not np.isfinite(covmean).all():
            raise ValueError(f"FID: sqrtm(S1 S2) is not finite even after adding {eps} * I")
    if np.iscomplexobj(covmean):
        imaginary = np.abs(np.diagonal(covmean).imag).max()
        if imaginary > imaginary_atol:
            raise ValueError(
                f"FID: sqrtm(S1 S2) has an imaginary component of {imaginary:.3g} on its "
                f"diagonal (> atol {imaginary_atol}); the covariances are not valid"
            )
        covmean = covmean.real
    diff = mu1 - mu2
    return float(diff @ diff + np.trace(sigma1) + np.trace(sigma2) - 2.0 * np.trace(covmean))


def draw_pair_indices(
    num_items: int, num_pairs: int, *, seed: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Two independent draws of ``num_pairs`` of ``range(num_items)`` without replacement.

    Returns two ``(num_pairs,)`` int64 CPU tensors from one ``torch.Generator`` seeded with
    ``seed``, so the same arguments always give the same pairs (tests reproduce them this way).
    """
    if num_pairs < 1:
        raise ValueError(f"num_pairs must be >= 1, got {num_pairs}")
    if num_items < num_pairs:
        raise ValueError(
            f"cannot draw {num_pairs} pairs without replacement from {num_items} items"
        )
    generator = torch.Generator().manual_seed(seed)
    first = torch.randperm(num_items, generator=generator)[:num_pairs]
    second = torch.randperm(num_items, generator=generator)[:num_pairs]
    return first, second


def diversity(
    embeddings: torch.Tensor,
    *,
    num_pairs: int,
    seed: int,
    emb_scale: float = 1.0,
    divide_by: float = 1.0,
) -> torch.Tensor:
    """``embeddings (N, D)`` -> float64 scalar ``mean ||a_i - b_i|| * emb_scale / divide_by``.

    ``a``/``b`` are the rows picked by ``draw_pair_indices(N, num_pairs, seed=seed)``.
    """
    if embeddings.ndim != 2:
        raise ValueError(f"Diversity needs (N, D) embeddings, got {tuple(embeddings.shape)}")
    if embeddings.shape[0] < num_pairs:
        raise ValueError(
            f"Diversity needs at least num_pairs={num_pairs} samples, got {embeddings.shape[0]}"
        )
    first, second = draw_pair_indices(embeddings.shape[0], num_pairs, seed=seed)
    scaled = embeddings.double() * emb_scale
    distances = torch.linalg.vector_norm(
        scaled[first.to(scaled.device)] - scaled[second.to(scaled.device)], dim=1
    )
    return distances.mean() / divide_by


def multimodality(
    embeddings: torch.Tensor, *, num_pairs: int, seed: int, scale: float = 1.0
) -> torch.Tensor:
    """``embeddings (N, G, D)`` (G generations per text) -> float64 scalar.

    One draw ``draw_pair_indices(G, num_pairs, seed=seed)`` is shared by all texts, as in the
    reference; the result is the mean over texts and pairs of ``||e[n, a_i] - e[n, b_i]||``
    times ``scale``.
    """
    if embeddings.ndim != 3:
        raise ValueError(f"MultiModality needs (N, G, D) embeddings, got {tuple(embeddings.shape)}")
    if embeddings.shape[1] < num_pairs:
        raise ValueError(
            f"MultiModality needs G >= num_pairs={num_pairs} generations per text, got "
            f"G={embeddings.shape[1]}"
        )
    first, second = draw_pair_indices(embeddings.shape[1], num_pairs, seed=seed)
    values = embeddings.double()
    distances = torch.linalg.vector_norm(
        values[:, first.to(values.device)] - values[:, second.to(values.device)], dim=2
    )  # (N, num_pairs)
    return distances.mean() * scale
