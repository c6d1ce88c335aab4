"""The training loader resumes a pass where a checkpoint left it (ResumableDataLoader), draws its
order when the first batch is asked for, and never touches torch's global generator."""

from __future__ import annotations

import pytest
import torch
from builders import write_interhuman
from test_datamodule import IH_SPLITS, make

from intermask.data.datamodule import ResumableDataLoader


@pytest.fixture(scope="module")
def ih_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("resumable") / "InterHuman"
    write_interhuman(root, splits=IH_SPLITS, meta=True)
    return root


def _ids(loader) -> list[list[str]]:
    return [list(batch["id"]) for batch in loader]


def _loader(root, **kwargs) -> ResumableDataLoader:
    dm = make(root, batch_size=2, mirror=False, **kwargs)
    dm.setup("fit")
    loader = dm.train_dataloader()
    assert isinstance(loader, ResumableDataLoader)
    return loader


def test_a_pass_resumes_after_the_batches_its_checkpoint_handed_out(ih_root):
    whole = _loader(ih_root)
    whole.sampler.set_epoch(3)
    batches = _ids(whole)
    assert len(batches) == 3  # 5 clips, batches of 2 (the last one partial)
    assert whole.state_dict() == {"epoch": 3, "batches": 3}

    stopped = _loader(ih_root)
    stopped.sampler.set_epoch(3)
    first = next(iter(stopped))
    assert list(first["id"]) == batches[0] and stopped.state_dict() == {"epoch": 3, "batches": 1}

    resumed = _loader(ih_root)
    resumed.load_state_dict(stopped.state_dict())
    resumed.sampler.set_epoch(3)  # Lightning sets the epoch after restoring the loader
    assert _ids(resumed) == batches[1:]
    assert resumed.state_dict() == {"epoch": 3, "batches": 3}
    assert len(resumed) == 3  # the pass's length is the whole pass's (Lightning counts on)
    resumed.sampler.set_epoch(4)
    assert len(_ids(resumed)) == 3  # the next pass from its start


def test_a_checkpoint_of_another_epoch_starts_the_pass_from_its_start(ih_root):
    loader = _loader(ih_root)
    loader.load_state_dict({"epoch": 2, "batches": 3})  # an epoch-end checkpoint of epoch 2
    loader.sampler.set_epoch(3)
    expected = _loader(ih_root)
    expected.sampler.set_epoch(3)
    assert _ids(loader) == _ids(expected)


def test_the_order_is_drawn_for_the_epoch_set_after_the_iterator_was_made(ih_root):
    # Lightning makes the first iterator, then sets the (resumed) epoch; with worker processes
    # torch asks the sampler for indices as soon as the iterator exists
    made_early = _loader(ih_root, num_workers=2)
    iterator = iter(made_early)
    made_early.sampler.set_epoch(5)
    early = [list(batch["id"]) for batch in iterator]
    expected = _loader(ih_root)
    expected.sampler.set_epoch(5)
    assert early == _ids(expected)


def test_making_iterators_leaves_torchs_global_generator_alone(ih_root):
    loader = _loader(ih_root)
    state = torch.get_rng_state()
    for epoch in range(3):
        loader.sampler.set_epoch(epoch)
        _ids(loader)
    assert torch.equal(torch.get_rng_state(), state)
