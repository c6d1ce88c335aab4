"""order=reference (intermask/evaluation/reference_order.py): the authors' eval.py draws, checked
against torch's DataLoader and a dataset that draws from the global generators as theirs does;
deterministic; and on data where only the order can differ, the same metrics as the default."""

# ruff: noqa: NPY002  (the authors' code draws from numpy's legacy global generator)
from __future__ import annotations

import random

import numpy as np
import pytest
import torch
from torch.utils.data import DataLoader, Dataset

from intermask.evaluation.protocol import MotionSource, ProtocolConstants, ProtocolRunner
from intermask.evaluation.reference_order import (
    GENERATED,
    GROUND_TRUTH,
    ReferenceItems,
    ReferenceOrderLoop,
    Streams,
    caption_lines,
    length_order,
    loader_pass,
)
from intermask.evaluation.sources import GroundTruth


@pytest.fixture(autouse=True)
def _keep_global_generators():
    """The tests seed the global generators as the reference does; leave them as they were."""
    python, numpy = random.getstate(), np.random.get_state()
    with torch.random.fork_rng(devices=[]):
        yield
    random.setstate(python)
    np.random.set_state(numpy)


def _fixseed(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


@pytest.mark.parametrize(("batch_size", "shuffle", "drop_last"), [(1, True, False), (4, True, True), (1, False, False)])  # fmt: skip
def test_loader_pass_draws_what_a_dataloader_draws(batch_size, shuffle, drop_last):
    _fixseed(11)
    torch.rand(3)  # the stream need not be fresh
    seen = [int(i) for batch in DataLoader(list(range(10)), batch_size=batch_size,
                                           shuffle=shuffle, drop_last=drop_last) for i in batch]  # fmt: skip
    streams = Streams.seeded(11)
    torch.rand(3, generator=streams.torch)
    order = loader_pass(streams, 10, shuffle=shuffle)
    assert seen == (order[:8] if drop_last else order)
    assert torch.equal(streams.torch.get_state(), torch.get_rng_state())
    assert sorted(order) == list(range(10)) and (order != list(range(10))) == shuffle


class _ReferenceLike(Dataset):
    """Draws per item as the authors' InterHumanDataset.__getitem__ does: Python's choice of a
    caption, of a crop start (clips over 300 frames), numpy's rand() > 0.5 twice."""

    def __init__(self, frames, captions):
        self.frames, self.captions = frames, captions

    def __len__(self):
        return len(self.frames)

    def __getitem__(self, item):
        caption = random.choice(self.captions[item]).strip()
        start = (
            random.choice(list(range(0, self.frames[item] - 300))) if self.frames[item] > 300 else 0
        )
        return item, caption, start, np.random.rand() > 0.5, np.random.rand() > 0.5


def _features(clip: int, swap: bool, start: int, frames: int) -> torch.Tensor:
    """(frames - 1, 2, 4): (clip, file person, start, 1 for the canonical reference), the
    reference first, as clip_features orders them."""
    persons = [torch.tensor([clip, p, start, 0.0]) for p in ((2, 1) if swap else (1, 2))]
    persons[0][3] = 1.0
    return torch.stack(persons).expand(frames - 1, 2, 4).clone()


FRAMES = [40, 320, 75, 301, 90, 60, 310, 45]
CAPTIONS = [[f"clip {i} take {k}" for k in range(1 + i % 3)] for i in range(len(FRAMES))]


def test_items_are_drawn_in_the_reference_order():
    _fixseed(5)
    expected = [tuple(x[0] if isinstance(x, list | tuple) else x.item() for x in row)
                for row in DataLoader(_ReferenceLike(FRAMES, CAPTIONS), batch_size=1, shuffle=True)]  # fmt: skip
    items = ReferenceItems(clips=range(8), frames=FRAMES, captions=CAPTIONS, features=_features)
    streams = Streams.seeded(5)
    drawn = []
    for index in loader_pass(streams, len(items), shuffle=True):
        item = items.draw(index, streams)
        first, second = item.motion[0, 0], item.motion[1, 0]  # the item's persons
        reference = first if first[3] == 1 else second
        drawn.append((int(first[0]), item.caption, int(first[2]), int(reference[1]) == 2,
                      bool(second[3] == 1)))  # fmt: skip
        assert item.length == min(FRAMES[index], 300) - 1
        assert bool(item.motion[:, item.length :].eq(0).all())
    assert [(i, c, s, bool(a), bool(b)) for i, c, s, a, b in expected] == drawn
    assert torch.equal(streams.torch.get_state(), torch.get_rng_state())
    assert streams.numpy.get_state()[2] == np.random.get_state()[2]
    assert streams.python.getstate() == random.getstate()


def test_caption_lines_keep_blank_lines_and_drop_only_the_last_newline(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("one\n\ntwo\n")
    assert caption_lines(path) == ["one", "", "two"]
    path.write_text("one\ntwo")
    assert caption_lines(path) == ["one", "two"]


def test_length_order_is_numpys_reversed_argsort():
    lengths = [30, 50, 30, 50, 10] * 4  # ties beyond insertion sort's 16 elements
    assert length_order(lengths).tolist() == np.argsort(lengths)[::-1].tolist()
    assert [lengths[i] for i in length_order(lengths)] == sorted(lengths, reverse=True)


def test_streams_survive_a_file(tmp_path):
    streams = Streams.seeded(9, split_lines=12)
    streams.numpy.rand()
    copy = Streams.load(streams.save(tmp_path / "state.pt"))
    assert copy.python.random() == streams.python.random()
    assert copy.numpy.rand() == streams.numpy.rand()
    assert torch.equal(torch.rand(4, generator=copy.torch), torch.rand(4, generator=streams.torch))
    with pytest.raises(ValueError, match="not a reference stream state"):
        torch.save({"format": "other"}, tmp_path / "bad.pt")
        Streams.load(tmp_path / "bad.pt")


# ---------------------------------------------------------------------- the loop
SIMPLE_FRAMES = [20, 24, 28, 33, 20, 40, 36, 29]


def _value(caption: str) -> float:
    return float(caption.split()[1]) + 1.0


def _simple_features(clip, swap, start, frames):
    return torch.full((frames - 1, 2, 3), clip + 1.0)


class _Evaluator:
    """Embeds a motion by its value (the same for both persons: person order does not matter) and
    a caption by its clip's value, so ground truth matches its caption exactly."""

    name, file_hash = "fake", "0"

    @staticmethod
    def _embed(values: torch.Tensor) -> torch.Tensor:
        values = values.double()[:, None]
        return torch.cat([torch.cos(values * k) for k in (0.7, 1.3, 2.1, 3.7)], dim=1).float()

    def encode_motion(self, motion, lengths):
        return self._embed(motion[:, 0, 0, 0] + motion[:, 1, 0, 0] * 0)

    def encode_text(self, captions, tokens=None):
        return self._embed(torch.tensor([_value(c) for c in captions]))


def _generated(value: float, length: int) -> tuple[torch.Tensor, int]:
    frames = length - length % 4
    return torch.full((2, frames, 3), value + 0.05 * frames), frames


class _Generation(MotionSource):
    name, generates, knows_roles = GENERATED, True, False

    def __call__(self, batch, seeds):
        out = [
            _generated(_value(c), int(n))
            for c, n in zip(batch["caption"], batch["length"], strict=True)
        ]
        longest = max(m.shape[1] for m, _ in out)
        motion = torch.stack(
            [torch.cat([m, m.new_zeros(2, longest - m.shape[1], 3)], 1) for m, _ in out]
        )
        return motion, torch.tensor([n for _, n in out])  # fmt: skip


CONSTANTS = ProtocolConstants(eval_batch_size=8, replications=2, mm_replications=2,
                              diversity_pairs=5, mm_texts=3, mm_generations=4, mm_pairs=2)  # fmt: skip


def _loop(seed: int = 3) -> dict:
    items = ReferenceItems(clips=range(8), frames=SIMPLE_FRAMES,
                           captions=[[f"clip {i}"] for i in range(8)], features=_simple_features)  # fmt: skip
    loop = ReferenceOrderLoop(items=items, evaluator=_Evaluator(),
                              generate=lambda caption, n: _generated(_value(caption), n),
                              constants=CONSTANTS, streams=Streams.seeded(seed))  # fmt: skip
    result = loop.run({}).to_dict()
    assert result["header"]["generated"] == 2 * (8 + 3 * (4 - 1))
    return result["rows"]


def _default() -> dict:
    def loader(epoch):
        order = torch.randperm(8, generator=torch.Generator().manual_seed(epoch)).tolist()
        motion = torch.zeros(8, 2, 300, 3)
        for row, clip in enumerate(order):
            motion[row, :, : SIMPLE_FRAMES[clip] - 1] = clip + 1.0
        yield {"motion": motion, "length": torch.tensor([SIMPLE_FRAMES[c] - 1 for c in order]),
               "caption": [f"clip {c}" for c in order]}  # fmt: skip

    ground_truth = GroundTruth(normalizer=None)
    runner = ProtocolRunner(loader=loader, evaluator=_Evaluator(), ground_truth=ground_truth,
                            sources=[ground_truth, _Generation()], constants=CONSTANTS)  # fmt: skip
    return runner.run({}).to_dict()["rows"]


def test_the_reference_order_is_deterministic_and_differs_from_the_default_only_in_order():
    first, again, default = _loop(), _loop(), _default()
    assert first == again
    for row in (GROUND_TRUTH, GENERATED):
        for metric in ("top1", "top2", "top3", "mm_dist", "fid", "multimodality"):
            if metric not in default[row]:
                continue
            ours, theirs = first[row][metric]["values"], default[row][metric]["values"]
            assert ours == pytest.approx(theirs, rel=1e-6, abs=1e-9), (row, metric)
    assert first[GROUND_TRUTH]["top1"]["values"] == [1.0, 1.0]
    assert first[GROUND_TRUTH]["mm_dist"]["values"] == pytest.approx([0.0, 0.0], abs=1e-6)
    assert first[GENERATED]["multimodality"]["values"] == [0.0, 0.0]  # one output per caption
    # Diversity: its pairs are numpy's draws in the reference order, not the default's
    assert first[GENERATED]["diversity"]["values"] != default[GENERATED]["diversity"]["values"]
    assert _loop(seed=4)[GENERATED]["diversity"] != first[GENERATED]["diversity"]
