"""The data-parallel helpers on 2 gloo processes, and the random state kept in checkpoints."""

from __future__ import annotations

import functools
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch
import torch.distributed as dist
from gloo import run_on_processes

from callbacks.random_state import RandomStateCheckpoint
from intermask.interm.module import global_masked_cross_entropy, masked_cross_entropy
from intermask.utils.distributed import gather_rows, global_mean_scale, local_rows, process_group
from intermask.utils.lightning import ScheduledModule

ROWS, CODES = 3, 5


def _global_batch() -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Features (6, 2, 1, 4, F) of 6 samples, a shared weight (F, K) (the model), targets and a
    mask masking more tokens in the first half (rank 0) than in the second."""
    generator = torch.Generator().manual_seed(0)
    features = torch.randn(2 * ROWS, 2, 1, 4, 3, generator=generator)
    weight = torch.randn(3, CODES, generator=generator)
    targets = torch.randint(CODES, (2 * ROWS, 2, 1, 4), generator=generator)
    mask = torch.rand(2 * ROWS, 2, 1, 4, generator=generator) < 0.5
    mask[:ROWS] |= torch.rand(ROWS, 2, 1, 4, generator=generator) < 0.5
    return features, weight, targets, mask


def _weight_gradient(loss_fn, features, weight, targets, mask) -> torch.Tensor:
    weight = weight.clone().requires_grad_(True)
    loss_fn(features @ weight, targets, mask).backward()
    return weight.grad


def _worker(rank: int, world: int, *, out_dir: str) -> None:
    features, weight, targets, mask = _global_batch()
    mine = local_rows(ROWS)
    grad = _weight_gradient(
        global_masked_cross_entropy, features[mine], weight, targets[mine], mask[mine]
    )
    dist.all_reduce(grad)  # what DDP does to a parameter's gradient: the ranks' sum ...
    grad /= world  # ... over the world size
    rows = gather_rows(torch.arange(ROWS) + 10 * rank)
    uneven = None
    try:
        gather_rows(torch.zeros(ROWS + rank))
    except RuntimeError as error:
        uneven = str(error)
    torch.save(
        {"grad": grad, "rows": rows, "group": process_group(), "uneven": uneven},
        Path(out_dir) / f"rank{rank}.pt",
    )


def test_two_ranks_take_the_one_process_gradient_of_a_masked_mean(tmp_path):
    run_on_processes(functools.partial(_worker, out_dir=str(tmp_path)), world=2)
    features, weight, targets, mask = _global_batch()
    assert mask[:ROWS].sum() > mask[ROWS:].sum()  # the ranks' means would weigh tokens unequally
    one_process = _weight_gradient(masked_cross_entropy, features, weight, targets, mask)
    for rank in range(2):
        out = torch.load(tmp_path / f"rank{rank}.pt", weights_only=True)
        torch.testing.assert_close(out["grad"], one_process)
        assert out["rows"].tolist() == [0, 1, 2, 10, 11, 12] and tuple(out["group"]) == (rank, 2)
        assert out["uneven"] == (
            f"rank {rank}: the ranks hold [3, 4] rows; data-parallel steps need equal blocks "
            "of the global batch (EpochSampler)"
        )


def test_one_process_helpers_are_the_identity():
    features, weight, targets, mask = _global_batch()
    logits = features @ weight
    assert process_group() == (0, 1) and local_rows(4) == slice(0, 4)
    assert torch.equal(gather_rows(targets), targets)
    assert float(global_mean_scale(torch.tensor(8))) == 1 / 8
    torch.testing.assert_close(
        global_masked_cross_entropy(logits, targets, mask),
        masked_cross_entropy(logits, targets, mask),
    )
    empty = torch.zeros_like(mask)
    assert float(global_masked_cross_entropy(logits, targets, empty)) == 0.0


def test_random_state_travels_with_the_checkpoint():
    callback = RandomStateCheckpoint()
    torch.manual_seed(5)
    saved = callback.state_dict()
    expected = torch.rand(3)
    torch.rand(10)  # the run went on, then died
    callback.load_state_dict(saved)
    assert torch.equal(torch.rand(3), expected)
    with pytest.raises(ValueError, match="holds no torch generator state \\(got list\\)"):
        callback.load_state_dict({"torch": [1, 2]})


def test_batch_generators_depend_on_seed_stage_and_batch_only():
    def draws(seed: int, stage: str, batch_idx: int, total: int) -> torch.Tensor:
        module = ScheduledModule()
        module.draw_seed = seed
        loop = SimpleNamespace(epoch_loop=SimpleNamespace(total_batch_idx=total))
        module._trainer = SimpleNamespace(fit_loop=loop)
        return torch.rand(4, generator=module.batch_generator(stage, batch_idx))

    assert torch.equal(draws(1, "train", 0, 7), draws(1, "train", 3, 7))  # the fit's count rules
    assert not torch.equal(draws(1, "train", 0, 7), draws(1, "train", 0, 8))
    assert not torch.equal(draws(1, "train", 0, 7), draws(2, "train", 0, 7))
    assert torch.equal(draws(1, "val", 2, 0), draws(1, "val", 2, 99))  # every validation alike
    assert not torch.equal(draws(1, "val", 7, 0), draws(1, "train", 0, 7))
    assert ScheduledModule().batch_generator("train", 0) is None  # outside a trainer
    module = ScheduledModule()
    module._trainer = SimpleNamespace()
    with pytest.raises(ValueError, match="stage must be 'train' or 'val', got 'test'"):
        module.batch_generator("test", 0)
