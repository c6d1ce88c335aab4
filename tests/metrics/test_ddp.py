"""A 2-process CPU (gloo) DDP run of the metrics gives the numbers of a single process.

Each rank reads its shard the way a ``DistributedSampler`` hands it out, padding included:
samples for FID / Diversity / MultiModality, whole eval batches for RPrecision / MMDist (the
within-batch distance matrix must group the same samples as the single-process run).
"""

from __future__ import annotations

import functools
from pathlib import Path

import pytest
import torch
from gloo import run_on_processes
from torch.utils.data import DistributedSampler

from intermask.metrics import FID, Diversity, MMDist, MultiModality, RPrecision

SAMPLES, WIDTH, EVAL_BATCH, TEXTS, GENERATIONS = 45, 6, 5, 9, 12  # odd counts force padding


def _embedding_set() -> dict[str, torch.Tensor]:
    generator = torch.Generator().manual_seed(0)
    text = torch.randn(SAMPLES, WIDTH, generator=generator)
    return {
        "real": torch.randn(SAMPLES, WIDTH, generator=generator),
        "fake": torch.randn(SAMPLES, WIDTH, generator=generator) * 1.3 + 0.2,
        "text": text,
        "motion": text + torch.randn(SAMPLES, WIDTH, generator=generator),
        "generations": torch.randn(TEXTS, GENERATIONS, WIDTH, generator=generator),
    }


def _shard(count: int, *, rank: int, world: int) -> list[int]:
    """The indices a shuffled ``DistributedSampler`` gives this rank (padded to equal length)."""
    return list(
        DistributedSampler(range(count), num_replicas=world, rank=rank, shuffle=True, seed=1)
    )


def _run_metrics(rank: int, world: int) -> dict[str, torch.Tensor]:
    data = _embedding_set()
    fid, diversity = FID(emb_scale=6.0), Diversity(num_pairs=20, emb_scale=6.0, divide_by=2.0)
    r_precision, mm_dist = RPrecision(top_k=3), MMDist()
    multimodality = MultiModality(num_pairs=5, scale=3.0)
    samples = torch.tensor(_shard(SAMPLES, rank=rank, world=world))
    for ids in samples.split(7):
        fid.update(data["real"][ids], real=True, sample_ids=ids)
        fid.update(data["fake"][ids], real=False, sample_ids=ids)
        diversity.update(data["fake"][ids], sample_ids=ids)
    for batch in _shard(SAMPLES // EVAL_BATCH, rank=rank, world=world):
        ids = torch.arange(batch * EVAL_BATCH, (batch + 1) * EVAL_BATCH)
        r_precision.update(data["text"][ids], data["motion"][ids], sample_ids=ids)
        mm_dist.update(data["text"][ids], data["motion"][ids], sample_ids=ids)
    for ids in torch.tensor(_shard(TEXTS, rank=rank, world=world)).split(2):
        multimodality.update(data["generations"][ids], sample_ids=ids)
    metrics = {"fid": fid, "diversity": diversity, "r_precision": r_precision}
    metrics |= {"mm_dist": mm_dist, "multimodality": multimodality}
    return {name: metric.compute() for name, metric in metrics.items()}


def _save_metrics(rank: int, world: int, *, out_dir: str) -> None:
    torch.save(_run_metrics(rank, world), Path(out_dir) / f"rank{rank}.pt")


def _assert_ddp_matches_single_process(tmp_path: Path, *, start_method: str) -> None:
    single = _run_metrics(0, 1)
    shards = [_shard(SAMPLES, rank=r, world=2) for r in range(2)]
    assert len(sum(shards, [])) > SAMPLES  # the split really has padded duplicates
    work = functools.partial(_save_metrics, out_dir=str(tmp_path))
    run_on_processes(work, world=2, start_method=start_method)
    for rank in range(2):
        gathered = torch.load(tmp_path / f"rank{rank}.pt", weights_only=True)
        assert gathered.keys() == single.keys()
        for name, value in single.items():
            torch.testing.assert_close(
                gathered[name], value, rtol=0, atol=1e-6, msg=f"{name} on rank {rank}"
            )


def test_ddp_fork_matches_single_process(tmp_path: Path):
    # fork: the children inherit the imported modules, so the run takes about a second
    _assert_ddp_matches_single_process(tmp_path, start_method="fork")


@pytest.mark.slow
def test_ddp_spawn_matches_single_process(tmp_path: Path):
    # spawn, as Lightning launches CPU DDP: fresh interpreters re-import torch (several seconds)
    _assert_ddp_matches_single_process(tmp_path, start_method="spawn")
