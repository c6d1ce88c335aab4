"""EpochSampler's data-parallel blocks: N ranks together read exactly one process's batches."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from test_datamodule import ih_root, make  # noqa: F401  (module fixture)

from intermask.data.common import EpochSampler


def _indices(**kwargs) -> list[int]:
    return [index for index, _ in EpochSampler(**kwargs)]


def test_ranks_read_contiguous_blocks_of_the_one_process_batches():
    one = _indices(size=10, shuffle=True, seed=1, batch_size=4)
    assert sorted(one) == list(range(10)) and one != list(range(10))
    ranks = [
        _indices(size=10, shuffle=True, seed=1, batch_size=2, rank=r, world_size=2, drop_last=True)
        for r in range(2)
    ]
    # global batches of 4: rank 0 takes items 0-1 of each, rank 1 items 2-3; the last 2 dropped
    assert ranks == [one[0:2] + one[4:6], one[2:4] + one[6:8]]


def test_a_partial_last_batch_is_padded_from_the_start_so_ranks_run_equal_steps():
    order = _indices(size=11, shuffle=False, seed=0, batch_size=6)
    assert order == list(range(11))
    ranks = [
        _indices(size=11, shuffle=False, seed=0, batch_size=2, rank=r, world_size=3)
        for r in range(3)
    ]
    # one full global batch of 6 (items 0-5), then 5 left, padded with item 0 to 2 per rank
    assert ranks[0][:2] == [0, 1] and ranks[1][:2] == [2, 3] and ranks[2][:2] == [4, 5]
    tails = [r[2:] for r in ranks]
    assert tails == [[6, 7], [8, 9], [10, 0]]
    lengths = [
        len(EpochSampler(11, shuffle=False, seed=0, batch_size=2, rank=r, world_size=3))
        for r in range(3)
    ]
    assert lengths == [4, 4, 4]


def test_one_process_is_unchanged_and_bad_ranks_are_refused():
    assert _indices(size=7, shuffle=True, seed=3, batch_size=3) == _indices(
        size=7, shuffle=True, seed=3
    )
    with pytest.raises(ValueError, match="rank 2 is not one of world_size=2 processes"):
        EpochSampler(4, shuffle=False, seed=0, rank=2, world_size=2)
    with pytest.raises(ValueError, match="batch_size must be >= 1, got 0"):
        EpochSampler(4, shuffle=False, seed=0, batch_size=0)


def test_datamodule_shards_for_the_trainer_and_refuses_a_second_sampler(ih_root):  # noqa: F811
    dm = make(ih_root, batch_size=2, mirror=False)
    dm.setup("fit")
    trainer = SimpleNamespace(
        global_rank=1,
        world_size=2,
        _accelerator_connector=SimpleNamespace(use_distributed_sampler=False),
    )
    dm.trainer = trainer
    sampler = dm.train_dataloader().sampler
    assert (sampler.rank, sampler.world_size, sampler.batch_size) == (1, 2, 2)
    assert dm.eval_dataloader("val").sampler.world_size == 1  # protocol passes stay whole
    trainer._accelerator_connector.use_distributed_sampler = True
    with pytest.raises(ValueError, match="trainer.use_distributed_sampler must be false"):
        dm.train_dataloader()
