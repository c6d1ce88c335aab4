"""The protocol drawn in the order of the authors' evaluation loop (gohar-malik/InterMask
``eval.py``): ``order=reference`` (``experiment=eval_reference_loop``).

The default protocol (:mod:`intermask.evaluation.protocol`) draws every crop, caption, order and
sample from generators keyed by replication and item, so batching changes nothing. The authors'
loop draws everything from three global generators (Python's ``random``, numpy's legacy
``np.random`` and torch's default generator) in one sequence, one sample at a time. This mode
replays that sequence with three explicit generators (:class:`Streams`), per replication:

1. generation: Python shuffles the item positions (the first ``mm_texts`` are the MultiModality
   items); a shuffled batch-1 DataLoader pass over the test items (:func:`loader_pass`); per item,
   in that order, its draws (:meth:`ReferenceItems.draw`), then one generation
   (``mm_generations`` for a MultiModality item) whose multinomial draws come from the torch stream;
2. matching: a shuffled, ``drop_last`` pass of ``eval_batch_size`` over the GT items, then one over
   the generated items: R-precision and MM Dist per batch, each batch sorted by length first
   (numpy's unstable argsort, reversed: its order of tied lengths decides the rows Diversity picks);
3. FID: the GT items again, the real set of both rows' FID;
4. Diversity: numpy ``choice(N, pairs, replace=False)`` twice, the GT row, then the generated row;
5. MultiModality, in every replication: one unshuffled DataLoader pass (its base seed) and numpy
   ``choice(G, pairs, replace=False)`` twice, shared by all texts.

The metrics are this framework's (:mod:`intermask.metrics`); only the order of the draws is the
reference's. The streams start either as ``fixseed(seed)`` plus the reference dataset's shuffle of
its split lines left them (:meth:`Streams.seeded`), or from a state the reference process had when
its first replication began (:meth:`Streams.load`): its network constructors draw from the torch
stream before that (random initialisation before the weights are loaded), a number of draws only
its own code knows.
"""

from __future__ import annotations

import contextlib
import os
import random
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from intermask.evaluation.protocol import Evaluator, ProtocolConstants, ProtocolResult, Summary
from intermask.metrics.fid import FID
from intermask.metrics.retrieval import MMDist, RPrecision

STATE_FORMAT = "intermask-reference-streams-v1"
GROUND_TRUTH, GENERATED = "Ground Truth", "InterMask"


@dataclass
class Streams:
    """The reference loop's three global generators, as explicit objects."""

    python: random.Random
    numpy: np.random.RandomState
    torch: torch.Generator

    @classmethod
    def seeded(cls, seed: int, *, split_lines: int = 0) -> Streams:
        """``fixseed(seed)``, then the reference dataset's ``random.shuffle`` of its split file's
        ``split_lines`` lines (it shuffles them before reading the clips)."""
        streams = cls(random.Random(seed), np.random.RandomState(seed), torch.Generator())
        streams.torch.manual_seed(seed)
        streams.python.shuffle(list(range(split_lines)))
        return streams

    @classmethod
    def from_globals(cls) -> Streams:
        """Copies of the process's global generators as they stand now."""
        streams = cls(random.Random(), np.random.RandomState(), torch.Generator())
        streams.python.setstate(random.getstate())
        streams.numpy.set_state(np.random.get_state())  # noqa: NPY002 (the reference's global)
        streams.torch.set_state(torch.get_rng_state())
        return streams

    def save(self, path: str | Path) -> Path:
        version, words, gauss = self.python.getstate()
        name, keys, position, has_gauss, cached = self.numpy.get_state()
        payload = {
            "format": STATE_FORMAT,
            "python": {"version": version, "words": torch.tensor(words), "gauss": gauss},
            "numpy": {"name": name, "keys": torch.from_numpy(keys.astype(np.int64)),
                      "position": int(position), "has_gauss": int(has_gauss),
                      "cached": float(cached)},
            "torch": self.torch.get_state(),
        }  # fmt: skip
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        torch.save(payload, path)
        return path

    @classmethod
    def load(cls, path: str | Path) -> Streams:
        payload = torch.load(path, map_location="cpu", weights_only=True)
        if not isinstance(payload, dict) or payload.get("format") != STATE_FORMAT:
            raise ValueError(f"{path}: not a reference stream state (expected {STATE_FORMAT})")
        python, numpy = payload["python"], payload["numpy"]
        streams = cls(random.Random(), np.random.RandomState(), torch.Generator())
        words = tuple(int(w) for w in python["words"].tolist())
        streams.python.setstate((python["version"], words, python["gauss"]))
        keys = numpy["keys"].numpy().astype(np.uint32)
        streams.numpy.set_state(
            (numpy["name"], keys, numpy["position"], numpy["has_gauss"], numpy["cached"])
        )
        streams.torch.set_state(payload["torch"])
        return streams


def _int64(generator: torch.Generator) -> int:
    """One ``torch.empty((), dtype=torch.int64).random_()`` draw, as a DataLoader makes it."""
    return int(torch.empty((), dtype=torch.int64).random_(generator=generator).item())


def loader_pass(streams: Streams, size: int, *, shuffle: bool) -> list[int]:
    """The draws of one pass of ``DataLoader(dataset of size, shuffle=shuffle, num_workers=0)``
    without a generator of its own -> the order it visits the items in: the iterator's base seed,
    and when shuffled the ``RandomSampler``'s seed of a fresh generator for its permutation."""
    _int64(streams.torch)
    if not shuffle:
        return list(range(size))
    sampler = torch.Generator().manual_seed(_int64(streams.torch))
    return torch.randperm(size, generator=sampler).tolist()


def full_batches(order: Sequence[int], size: int) -> Iterator[list[int]]:
    """``order`` in batches of ``size``, the last partial one dropped (``drop_last``)."""
    for start in range(0, len(order) - size + 1, size):
        yield list(order[start : start + size])


def length_order(lengths: Sequence[int]) -> np.ndarray:
    """The reference wrapper's order of a batch: longest first, by numpy's default (unstable)
    argsort reversed, so tied lengths come in the order it leaves them."""
    return np.argsort([int(n) for n in lengths])[::-1].copy()


def caption_lines(path: Path) -> list[str]:
    """A caption file's lines as the reference reads them (``readlines`` without the newline;
    blank lines kept: they count in its random choice)."""
    lines = path.read_text(encoding="utf-8").split("\n")
    return lines[:-1] if lines and lines[-1] == "" else lines


def walk_order(root: Path, names: set[str]) -> list[str]:
    """Clip names in the order the reference dataset finds them: ``os.walk(root)``, ``.npy``
    files in folders whose path holds ``person1``, in the file system's listing order."""
    found = []
    for folder, _, files in os.walk(root):
        if "person1" not in folder:
            continue
        found += [f.split(".")[0] for f in files if f.endswith(".npy") and f.split(".")[0] in names]
    return found


class Item(NamedTuple):
    caption: str
    motion: torch.Tensor  # (2, max_length, *F) un-normalized, zero after ``length``
    length: int  # frames of features


Features = Callable[[int, bool, int, int], torch.Tensor]  # clip, swap, start, frames -> (L, 2, *F)


class ReferenceItems:
    """The test items in the reference dataset's order with its per-item draws.

    clips: the clip index (for ``features``) of each item, in the reference's order.
    frames: raw frames of each item's clip; captions: its caption lines.
    features: ``(clip, swap, start, frames) -> (frames - 1, 2, *F)`` un-normalized features of
        frames ``start:start + frames``, person 2 the canonical reference when ``swap``.
    """

    def __init__(
        self,
        *,
        clips: Sequence[int],
        frames: Sequence[int],
        captions: Sequence[Sequence[str]],
        features: Features,
        max_length: int = 300,
    ) -> None:
        if not len(clips) == len(frames) == len(captions):
            raise ValueError(
                f"clips, frames and captions differ in length: {len(clips)}, {len(frames)}, "
                f"{len(captions)}"
            )
        self.clips, self.frames = list(clips), [int(f) for f in frames]
        self.captions = [list(c) for c in captions]
        self.features, self.max_length = features, max_length

    @classmethod
    def from_interhuman(cls, dataset: Any) -> ReferenceItems:
        """The items of an :class:`~intermask.data.interhuman.InterHumanDataset` split, in the
        order ``os.walk`` lists its ``motions_processed/person1`` files."""
        names = walk_order(dataset.layout.root, set(dataset.clip_ids))
        missing = sorted(set(dataset.clip_ids) - set(names))
        if missing:
            raise ValueError(
                f"{dataset.layout.root}: no person1 file found for clips {missing[:5]}"
            )
        index = {name: i for i, name in enumerate(dataset.clip_ids)}
        clips = [index[name] for name in names]

        def features(clip: int, swap: bool, start: int, frames: int) -> torch.Tensor:
            return dataset.clip_features(clip, swap=swap, start=start, frames=frames)

        return cls(
            clips=clips,
            frames=[int(dataset.frames[c]) for c in clips],
            captions=[caption_lines(dataset.layout.caption_file(n)) for n in names],
            features=features,
            max_length=dataset.max_length,
        )

    def __len__(self) -> int:
        return len(self.clips)

    def draw(self, position: int, streams: Streams) -> Item:
        """Item ``position``: Python draws its caption, then (clips over ``max_length`` frames)
        its crop start in ``range(frames - max_length)``; numpy draws ``rand() > 0.5`` for the
        reference person (person 2), then for the output order (swapped)."""
        frames = self.frames[position]
        caption = streams.python.choice(self.captions[position]).strip()
        start = 0
        if frames > self.max_length:
            start = streams.python.choice(range(frames - self.max_length))
        swap_reference = bool(streams.numpy.rand() > 0.5)
        swap_output = bool(streams.numpy.rand() > 0.5)
        used = min(frames, self.max_length)
        features = self.features(self.clips[position], swap_reference, start, used)
        if swap_output:
            features = features.flip(1)
        length = features.shape[0]
        motion = features.new_zeros(2, self.max_length, *features.shape[2:])
        motion[:, :length] = features.transpose(0, 1)
        return Item(caption, motion, length)


@contextlib.contextmanager
def drawing_from(generator: torch.Generator) -> Iterator[None]:
    """Decoding inside draws its noise from ``generator`` (carried on from call to call, as the
    reference's global generator is) instead of generators made from per-sample seeds.

    ``intermask.interm.decoding.generate`` takes seeds only; with ``noise="reference"`` it draws
    from the first sample's generator, which this swaps for ``generator``. A ``generators``
    argument there would make this unnecessary.
    """
    from intermask.interm import decoding

    original = decoding._generators
    decoding._generators = lambda seeds, batch, device: [generator] * batch
    try:
        yield
    finally:
        decoding._generators = original


Generate = Callable[[str, int], tuple[torch.Tensor, int]]  # caption, frames -> (2, T, *F), frames


def sampler_generation(sampler: Any, streams: Streams) -> Generate:
    """One batch-1 generation with ``sampler`` (an :class:`~intermask.interm.sampler.
    InteractionSampler` with ``noise="reference"``), its draws from the torch stream."""
    if getattr(sampler, "noise", None) != "reference":
        raise ValueError(
            "order=reference draws the generation noise in the reference's order: it needs "
            f"sampler.noise=reference, got {getattr(sampler, 'noise', None)!r}"
        )

    def generate(caption: str, length: int) -> tuple[torch.Tensor, int]:
        with drawing_from(streams.torch):
            out = sampler([caption], torch.tensor([length]), seeds=[0])
        # eval.py decodes each person in a call of its own: so here, whatever the tokenizer's
        # graph ends (docs/fidelity.md, 10b; with graph_batch_first_frame a batch of two would
        # leave person 2's frame 0 without its neighbours, up to 0.23 apart).
        with torch.no_grad():
            alone = torch.cat([sampler.vq.decode_valid(out.tokens[:, p, None]) for p in (0, 1)])
            features = sampler.vq.view.denormalize(alone.float())  # (2, T, *F)
        return features, int(out.lengths[0])

    return generate


class _Generated(NamedTuple):
    captions: list[str]
    motions: list[torch.Tensor]  # (2, T, *F) each
    lengths: list[int]
    multimodal: list[list[torch.Tensor]]  # per MultiModality item, its generations
    multimodal_lengths: list[int]


class ReferenceOrderLoop:
    """The protocol's two rows (ground truth, generation) in the reference loop's order.

    ``run`` returns a :class:`ProtocolResult` like :class:`~intermask.evaluation.protocol.
    ProtocolRunner`'s; MultiModality is computed in every replication (the reference's
    generation pass draws its generations in every one). ``generation_cpu_s`` adds up the CPU
    time of the generation calls.
    """

    def __init__(
        self,
        *,
        items: ReferenceItems,
        evaluator: Evaluator,
        generate: Generate,
        constants: ProtocolConstants,
        streams: Streams,
        progress: Callable[[str], None] | None = None,
    ) -> None:
        if len(items) < constants.eval_batch_size:
            raise ValueError(
                f"{len(items)} test items give no batch of {constants.eval_batch_size} (drop_last)"
            )
        self.items, self.evaluator, self.generate = items, evaluator, generate
        self.constants, self.streams = constants, streams
        self.progress = progress or (lambda message: None)
        self.generation_cpu_s, self.generated = 0.0, 0

    # ------------------------------------------------------------------ passes
    def _generation_pass(self) -> _Generated:
        c, streams = self.constants, self.streams
        positions = list(range(len(self.items)))
        streams.python.shuffle(positions)
        multimodal_positions = set(positions[: c.mm_texts])
        out = _Generated([], [], [], [], [])
        for i, index in enumerate(loader_pass(streams, len(self.items), shuffle=True)):
            item = self.items.draw(index, streams)
            repeats = c.mm_generations if i in multimodal_positions else 1
            start = time.process_time()
            motions = [self.generate(item.caption, item.length) for _ in range(repeats)]
            self.generation_cpu_s += time.process_time() - start
            self.generated += repeats
            out.captions.append(item.caption)
            out.motions.append(motions[0][0])
            out.lengths.append(motions[0][1])
            if i in multimodal_positions:
                out.multimodal.append([motion for motion, _ in motions])
                out.multimodal_lengths.append(motions[0][1])
        return out

    def _motion_embeddings(self, motions: Sequence[torch.Tensor], lengths: Sequence[int]):
        """-> (embeddings (B, D) in the reference wrapper's length order, that order)."""
        order = length_order(lengths)
        longest = max(int(m.shape[1]) for m in motions)
        batch = torch.stack([_pad(motions[i], longest) for i in order])
        embeddings = self.evaluator.encode_motion(batch, torch.tensor([lengths[i] for i in order]))
        return embeddings, order

    def _co_embeddings(self, captions, motions, lengths) -> tuple[torch.Tensor, torch.Tensor]:
        motion, order = self._motion_embeddings(motions, lengths)
        text = self.evaluator.encode_text(list(captions))[torch.from_numpy(order)]
        return text, motion

    def _gt_batches(self) -> Iterator[tuple[list[str], list[torch.Tensor], list[int]]]:
        c, streams = self.constants, self.streams
        order = loader_pass(streams, len(self.items), shuffle=True)
        for batch in full_batches(order, c.eval_batch_size):
            drawn = [self.items.draw(index, streams) for index in batch]
            yield [d.caption for d in drawn], [d.motion for d in drawn], [d.length for d in drawn]

    def _paired_distance(self, embeddings: torch.Tensor, count: int, pairs: int, scale: float):
        first = self.streams.numpy.choice(count, pairs, replace=False)
        second = self.streams.numpy.choice(count, pairs, replace=False)
        a, b = embeddings[..., first, :].double(), embeddings[..., second, :].double()
        return float(torch.linalg.vector_norm((a - b) * scale, dim=-1).mean())

    def replication(self, replication: int) -> dict[str, dict[str, float]]:
        c = self.constants
        generated = self._generation_pass()
        rows = {name: (RPrecision(top_k=c.top_k), MMDist()) for name in (GROUND_TRUTH, GENERATED)}
        activations: dict[str, list[torch.Tensor]] = {GROUND_TRUTH: [], GENERATED: []}
        for captions, motions, lengths in self._gt_batches():
            text, motion = self._co_embeddings(captions, motions, lengths)
            for metric in rows[GROUND_TRUTH]:
                metric.update(text, motion)
            activations[GROUND_TRUTH].append(motion)
        order = loader_pass(self.streams, len(generated.captions), shuffle=True)
        for batch in full_batches(order, c.eval_batch_size):
            text, motion = self._co_embeddings(
                [generated.captions[i] for i in batch],
                [generated.motions[i] for i in batch],
                [generated.lengths[i] for i in batch],
            )
            for metric in rows[GENERATED]:
                metric.update(text, motion)
            activations[GENERATED].append(motion)
        real = [self._motion_embeddings(m, n)[0] for _, m, n in self._gt_batches()]
        results: dict[str, dict[str, float]] = {}
        for name, (r_precision, mm_dist) in rows.items():
            fid = FID(emb_scale=c.emb_scale)
            for embedding in real:
                fid.update(embedding, real=True)
            fake = torch.cat(activations[name])
            fid.update(fake, real=False)
            top = r_precision.compute()
            results[name] = {f"top{k + 1}": float(top[k]) for k in range(c.top_k)}
            results[name] |= {"fid": float(fid.compute()), "mm_dist": float(mm_dist.compute())}
        for name in (GROUND_TRUTH, GENERATED):  # the reference's order of numpy draws
            fake = torch.cat(activations[name])
            scale = c.emb_scale / c.divide_by
            results[name]["diversity"] = self._paired_distance(
                fake, fake.shape[0], c.diversity_pairs, scale
            )
        results[GENERATED]["multimodality"] = self._multimodality(generated)
        return results

    def _multimodality(self, generated: _Generated) -> float:
        c = self.constants
        loader_pass(self.streams, len(generated.multimodal), shuffle=False)
        embeddings = torch.stack(
            [
                self._motion_embeddings(motions, [length] * len(motions))[0]
                for motions, length in zip(
                    generated.multimodal, generated.multimodal_lengths, strict=True
                )
            ]
        )  # (mm_texts, G, D)
        return self._paired_distance(embeddings, c.mm_generations, c.mm_pairs, c.mm_scale)

    def run(self, header: dict[str, Any]) -> ProtocolResult:
        collected: dict[str, dict[str, list[float]]] = {GROUND_TRUTH: {}, GENERATED: {}}
        for r in range(self.constants.replications):
            self.progress(f"replication {r + 1}/{self.constants.replications} (reference order)")
            for row, values in self.replication(r).items():
                for name, value in values.items():
                    collected[row].setdefault(name, []).append(value)
        result = ProtocolResult(
            header={
                **header,
                "constants": vars(self.constants),
                "multimodality": "every replication (the reference loop's)",
                "generation_cpu_s": round(self.generation_cpu_s, 3),
                "generated": self.generated,
            }
        )
        for row, metrics in collected.items():
            result.rows[row] = {name: Summary.of(values) for name, values in metrics.items()}
        return result


def _pad(motion: torch.Tensor, frames: int) -> torch.Tensor:
    """(2, T, *F) -> (2, frames, *F): cut or zero-padded."""
    if motion.shape[1] >= frames:
        return motion[:, :frames]
    padding = motion.new_zeros(motion.shape[0], frames - motion.shape[1], *motion.shape[2:])
    return torch.cat([motion, padding], dim=1)
