"""Per-sample ids that let metrics drop the padded duplicates a ``DistributedSampler`` adds.

A ``DistributedSampler`` pads the index list to a multiple of the world size by repeating its
first indices; the repeats land on later ranks, after the originals, so in the rank-ordered
gather the first occurrence of an id is the original. Metrics store one id per sample
(``NO_ID`` when the caller passes none), and at ``compute`` keep the first occurrence of each
id, in ascending id order, which makes the result independent of how the set was sharded.
"""

from __future__ import annotations

import torch
from torchmetrics.utilities import dim_zero_cat

NO_ID = -1  # stored for updates without sample_ids; real ids must be >= 0


def sample_id_column(
    sample_ids: torch.Tensor | None, batch_size: int, *, metric: str, device: torch.device
) -> torch.Tensor:
    """Validate ``sample_ids (B,)`` int64 (or ``None``) -> the ``(B,)`` int64 column to store."""
    if sample_ids is None:
        return torch.full((batch_size,), NO_ID, dtype=torch.int64, device=device)
    if not isinstance(sample_ids, torch.Tensor):
        raise TypeError(
            f"{metric}: sample_ids must be a (B,) int64 tensor, got {type(sample_ids).__name__}"
        )
    if sample_ids.shape != (batch_size,):
        raise ValueError(
            f"{metric}: sample_ids must have shape ({batch_size},) to match the batch, got "
            f"{tuple(sample_ids.shape)}"
        )
    if (
        sample_ids.dtype.is_floating_point
        or sample_ids.dtype.is_complex
        or sample_ids.dtype == torch.bool
    ):
        raise ValueError(f"{metric}: sample_ids must be integers, got dtype {sample_ids.dtype}")
    if batch_size and int(sample_ids.min()) < 0:
        raise ValueError(f"{metric}: sample_ids must be >= 0, got {int(sample_ids.min())}")
    return sample_ids.detach().to(device=device, dtype=torch.int64)


def first_occurrences(sample_ids: torch.Tensor) -> torch.Tensor:
    """``(N,)`` ids -> ``(M,)`` int64 positions of each distinct id's first occurrence, by ascending id."""
    unique, inverse = torch.unique(sample_ids, return_inverse=True)
    positions = torch.arange(sample_ids.shape[0], device=sample_ids.device)
    first = torch.full_like(unique, sample_ids.shape[0])
    return first.scatter_reduce(0, inverse, positions, reduce="amin")


def kept_positions(sample_ids: torch.Tensor, *, metric: str) -> torch.Tensor | None:
    """``(N,)`` stored ids -> positions to keep, or ``None`` when no update passed ids (keep all)."""
    missing = sample_ids == NO_ID
    if bool(missing.all()):
        return None
    if bool(missing.any()):
        raise ValueError(
            f"{metric}: some updates passed sample_ids and some did not ({int(missing.sum())} of "
            f"{sample_ids.shape[0]} samples have none); pass them on every update or on none"
        )
    return first_occurrences(sample_ids)


def gather_samples(
    values: list[torch.Tensor] | torch.Tensor,
    sample_ids: list[torch.Tensor] | torch.Tensor,
    *,
    metric: str,
) -> torch.Tensor:
    """Concatenate a cat-list state (after the DDP gather) and drop duplicate ids -> ``(M, ...)``."""
    if isinstance(values, list) and not values:
        raise ValueError(f"{metric}.compute() called before any update")
    if isinstance(values, list):
        trailing = {tuple(v.shape[1:]) for v in values}
        if len(trailing) > 1:
            raise ValueError(
                f"{metric}: updates had inconsistent per-sample shapes {sorted(trailing)}"
            )
    stacked, ids = dim_zero_cat(values), dim_zero_cat(sample_ids)
    keep = kept_positions(ids, metric=metric)
    return stacked if keep is None else stacked[keep.to(stacked.device)]
