"""What data-parallel training needs to equal one process with the same global batch.

Each rank holds a contiguous block of the global batch (``EpochSampler``). Random draws of a
training step are made for the whole global batch, identically on every rank (from the batch's
keyed generator, ``ScheduledModule.batch_generator``), and each rank keeps its rows; losses that
average over a varying number of items (masked tokens) divide by the count of the whole
global batch. With one process all three are the identity.
"""

from __future__ import annotations

import torch
import torch.distributed as dist


def process_group() -> tuple[int, int]:
    """(rank, world size) of the default process group; (0, 1) without one."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def all_reduce_sum(tensor: torch.Tensor) -> torch.Tensor:
    """Sum over the ranks, in place (every replica then applies the same update)."""
    if process_group()[1] > 1:
        dist.all_reduce(tensor)
    return tensor


def gather_rows(tensor: torch.Tensor) -> torch.Tensor:
    """(N, ...) on each rank -> (world * N, ...) in rank order, the rows of the global batch.

    Every rank must hold the same number of rows (the sampler gives each the same block size).
    """
    rank, world = process_group()
    if world == 1:
        return tensor
    sizes = [torch.zeros((), dtype=torch.long, device=tensor.device) for _ in range(world)]
    dist.all_gather(sizes, torch.tensor(tensor.shape[0], device=tensor.device))
    if len({int(size) for size in sizes}) != 1:
        raise RuntimeError(
            f"rank {rank}: the ranks hold {[int(s) for s in sizes]} rows; data-parallel steps "
            "need equal blocks of the global batch (EpochSampler)"
        )
    parts = [torch.empty_like(tensor) for _ in range(world)]
    dist.all_gather(parts, tensor.contiguous())
    return torch.cat(parts)


def local_rows(rows: int) -> slice:
    """This rank's rows of a global batch whose blocks hold ``rows`` each."""
    rank, _ = process_group()
    return slice(rank * rows, (rank + 1) * rows)


def global_mean_scale(count: torch.Tensor) -> torch.Tensor:
    """``world / (count summed over the ranks)``: a per-rank sum times this, averaged over the
    ranks by data-parallel gradient reduction, is the mean over the whole global batch."""
    _, world = process_group()
    total = all_reduce_sum(count.detach().to(torch.float64).clone())
    return world / total.clamp_min(1.0)
