"""The multi-replication evaluation protocol (InterGen / InterMask convention).

Every constant is a field of :class:`ProtocolConstants` (filled from ``configs/protocol/``) and is
printed in the results header; each config file in configs/protocol/ cites its source.

One replication ``r``:

1. a *reference pass* over the split (loader epoch ``2r``): GT motion embeddings, the real
   set of every row's FID (with ``fid_reference="same_pass"``, as in T2M and MoMask, there is
   no such pass: the real set is the GT of the evaluation pass's own items);
2. an *evaluation pass* (epoch ``2r + 1``, independently re-drawn crops, captions and person
   order): per eval batch, text embeddings once, then every row's motion (GT or generated for
   the batch's captions and lengths) -> R-precision and MM Dist within the batch, FID (fake
   set) and Diversity over the pass;
3. for the first ``mm_replications`` replications and every generating row: MultiModality over
   ``mm_texts`` random items with ``mm_generations`` generations each.

When the batches carry the synthetic dataset's action labels and the runner has a ``joints``
function, every row whose motion has joint positions also gets interaction success (overall
``success`` and ``success/<action>``, :mod:`intermask.metrics.success`) over the evaluation pass.

The GT row runs through exactly the same code as a model row; its FID compares the two passes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import torch

from intermask.metrics.diversity import Diversity, MultiModality
from intermask.metrics.fid import FID
from intermask.metrics.interaction import ACTIONS, SuccessThresholds
from intermask.metrics.retrieval import MMDist, RPrecision
from intermask.metrics.success import InteractionSuccess

Batch = dict[str, Any]
FID_REFERENCES = ("separate_pass", "same_pass")


@dataclass(frozen=True)
class ProtocolConstants:
    """Defaults: InterHuman's, as ``configs/protocol/interhuman.yaml`` states them with their
    sources (docs/evaluation.md, "Constants"); a test keeps the two equal."""

    eval_batch_size: int = 96  # R-precision / MM Dist grouping (Inter-X: 32)
    replications: int = 20
    mm_replications: int = 5  # the InterMask paper: 5 on both datasets
    emb_scale: float = 6.0  # FID and Diversity embeddings x emb_scale (Inter-X: 1)
    divide_by: float = 2.0  # Diversity / divide_by (Inter-X: 1)
    mm_scale: float = 3.0  # InterMask's 6 / 2 on InterHuman; InterGen and Inter-X: 1
    mm_convention: str = "intermask"  # names the MultiModality scaling in the output
    diversity_pairs: int = 300
    mm_texts: int = 100
    mm_generations: int = 30
    mm_pairs: int = 10
    top_k: int = 3
    seed: int = 3407
    # FID's real set: the GT of a second, independently drawn pass ("separate_pass", InterGen
    # and InterMask) or the GT of the evaluated items themselves ("same_pass", T2M and MoMask)
    fid_reference: str = "separate_pass"

    def __post_init__(self) -> None:
        if self.fid_reference not in FID_REFERENCES:
            raise ValueError(
                f"protocol fid_reference must be one of {FID_REFERENCES}, got {self.fid_reference!r}"
            )
        for name in ("eval_batch_size", "replications", "diversity_pairs", "top_k"):
            if getattr(self, name) < 1:
                raise ValueError(f"protocol {name} must be >= 1, got {getattr(self, name)}")
        if self.mm_generations < self.mm_pairs:
            raise ValueError(
                f"mm_generations ({self.mm_generations}) must be >= mm_pairs ({self.mm_pairs})"
            )


class Evaluator(Protocol):
    """The frozen text-motion embedding model (see :mod:`intermask.evaluator`)."""

    name: str
    file_hash: str

    def encode_motion(self, motion: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor: ...

    def encode_text(
        self, captions: Sequence[str], tokens: Sequence[str] | None = None
    ) -> torch.Tensor: ...


class MotionSource:
    """One row of the table: turns an eval batch into the motion the evaluator embeds.

    ``__call__(batch, seeds (B,)) -> (motion (B, 2, T, *F) de-normalized, lengths (B,) frames)``.
    ``generates``: whether MultiModality applies (False for ground truth and reconstruction).
    ``knows_roles``: whether the batch's actor annotation names this row's actor (False for free
    generation from a caption, where either person may act).
    ``extra_metrics`` / ``reset``: row-specific values per replication (e.g. MPJPE).
    """

    name: str = "source"
    generates: bool = False
    knows_roles: bool = True

    def __call__(self, batch: Batch, seeds: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        raise NotImplementedError

    def reset(self) -> None:
        """Forget per-replication state (called before every evaluation pass)."""

    def extra_metrics(self) -> dict[str, float]:
        return {}


@dataclass
class Summary:
    mean: float
    ci95: float  # 1.96 * std(ddof=0) / sqrt(R)
    values: list[float]

    @classmethod
    def of(cls, values: Sequence[float]) -> Summary:
        data = torch.tensor(list(values), dtype=torch.float64)
        ci95 = 1.96 * float(data.std(correction=0)) / math.sqrt(len(values))
        return cls(float(data.mean()), ci95, [float(v) for v in values])


@dataclass
class ProtocolResult:
    header: dict[str, Any]
    rows: dict[str, dict[str, Summary]] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "header": self.header,
            "rows": {
                row: {name: asdict(summary) for name, summary in metrics.items()}
                for row, metrics in self.rows.items()
            },
        }


def sample_seeds(
    constants: ProtocolConstants, replication: int, stream: int, count: int, offset: int
):
    """(count,) int64 per-sample generation seeds, distinct per replication, stream and sample,
    so a sample's result does not depend on how the pass is batched."""
    base = (constants.seed * 1_000_003 + replication * 10_007 + stream) * 1_000_000
    return torch.arange(offset, offset + count, dtype=torch.int64) + base


Joints = Callable[[torch.Tensor], torch.Tensor | None]


def success_labels(batch: Batch) -> tuple[torch.Tensor, torch.Tensor | None] | None:
    """``(action_ids (B,), actors (B,) | None)`` when every item of ``batch`` names one of the
    synthetic ``ACTIONS`` (other labels, e.g. Inter-X's A000..A039, have no predicate), else None."""
    names = batch.get("action")
    if names is None or not all(name in ACTIONS for name in names):
        return None
    action_ids = torch.tensor([ACTIONS.index(name) for name in names], dtype=torch.int64)
    actors = batch.get("actor")
    return action_ids, None if actors is None else torch.as_tensor(actors).long().cpu()


def repeat_items(batch: Batch, indices: torch.Tensor, repeats: int) -> Batch:
    """A batch of ``batch``'s items ``indices``, each repeated ``repeats`` times in a row."""
    picked = indices.repeat_interleave(repeats)
    out: Batch = {}
    for key, value in batch.items():
        if isinstance(value, torch.Tensor):
            out[key] = value[picked.to(value.device)]
        elif isinstance(value, list | tuple):
            out[key] = [value[int(i)] for i in picked]
    return out


class ProtocolRunner:
    """Runs the protocol for ``sources`` (the first is usually the ground truth).

    loader: ``loader(epoch) -> iterable of eval batches`` (shuffled, drop_last, batch size
        ``constants.eval_batch_size``), re-drawing crops, captions and order per epoch.
    ground_truth: the source whose motion is the FID reference (de-normalized GT).
    joints: ``motion (B, 2, T, *F) -> (B, T, 2, 22, 3)`` metres (None when the representation
        has no positions); with it, labelled batches give every row interaction success, judged
        with ``success_thresholds``.
    """

    def __init__(
        self,
        *,
        loader: Callable[[int], Iterable[Batch]],
        evaluator: Evaluator,
        ground_truth: MotionSource,
        sources: Sequence[MotionSource],
        constants: ProtocolConstants,
        multimodality: bool = True,
        generation_batch_size: int = 96,
        progress: Callable[[str], None] | None = None,
        joints: Joints | None = None,
        success_thresholds: SuccessThresholds | None = None,
    ) -> None:
        names = [source.name for source in sources]
        if len(set(names)) != len(names):
            raise ValueError(f"row names must be unique, got {names}")
        self.loader, self.evaluator, self.ground_truth = loader, evaluator, ground_truth
        self.sources, self.constants = list(sources), constants
        self.multimodality = multimodality
        self.generation_batch_size = generation_batch_size
        self.progress = progress or (lambda message: None)
        self.joints = joints
        self.success_thresholds = success_thresholds or SuccessThresholds()

    # ------------------------------------------------------------------ embeddings
    def _text_embeddings(self, batch: Batch) -> torch.Tensor:
        return self.evaluator.encode_text(list(batch["caption"]), batch.get("tokens"))

    def _motion_embeddings(self, source: MotionSource, batch: Batch, seeds) -> torch.Tensor:
        motion, lengths = source(batch, seeds)
        return self.evaluator.encode_motion(motion, lengths)

    def _judge(
        self, success: InteractionSuccess, source: MotionSource, batch: Batch, motion, lengths
    ) -> None:
        """Interaction success of one row's motion for a labelled batch (nothing otherwise)."""
        labels = None if self.joints is None else success_labels(batch)
        if labels is None:
            return
        joints = self.joints(motion)
        if joints is None:  # no positions in this representation: the row shows "-"
            return
        action_ids, actors = labels
        success.update(
            joints.detach().cpu(),
            lengths.detach().cpu().long(),
            action_ids,
            actors if source.knows_roles else None,
        )

    # ------------------------------------------------------------------ one replication
    def _reference_embeddings(self, replication: int) -> list[torch.Tensor]:
        embeddings = []
        for batch in self.loader(2 * replication):
            seeds = torch.zeros(len(batch["caption"]), dtype=torch.int64)
            embeddings.append(self._motion_embeddings(self.ground_truth, batch, seeds))
        if not embeddings:
            raise ValueError(
                f"the evaluation split gave no batch of {self.constants.eval_batch_size} items "
                "(drop_last); use a smaller eval_batch_size or a larger split"
            )
        return embeddings

    def replication(self, replication: int) -> dict[str, dict[str, float]]:
        """Metrics of every row for one replication."""
        c = self.constants
        same_pass = c.fid_reference == "same_pass"
        reference = [] if same_pass else self._reference_embeddings(replication)
        metrics = {
            source.name: {
                "r_precision": RPrecision(top_k=c.top_k),
                "mm_dist": MMDist(),
                "fid": FID(emb_scale=c.emb_scale),
                "diversity": Diversity(
                    num_pairs=c.diversity_pairs,
                    emb_scale=c.emb_scale,
                    divide_by=c.divide_by,
                    seed=c.seed + replication,
                ),
            }
            for source in self.sources
        }
        success = {
            source.name: InteractionSuccess(thresholds=self.success_thresholds)
            for source in self.sources
        }
        for row in metrics.values():
            for embedding in reference:
                row["fid"].update(embedding, real=True)
        for source in self.sources:
            source.reset()
        offset = 0
        for batch in self.loader(2 * replication + 1):
            text = self._text_embeddings(batch)
            count = text.shape[0]
            seeds = sample_seeds(c, replication, 0, count, offset)
            offset += count
            if same_pass:
                real = self._motion_embeddings(self.ground_truth, batch, seeds)
                for row in metrics.values():
                    row["fid"].update(real, real=True)
            for source in self.sources:
                output, lengths = source(batch, seeds)
                motion = self.evaluator.encode_motion(output, lengths)
                self._judge(success[source.name], source, batch, output, lengths)
                row = metrics[source.name]
                row["r_precision"].update(text, motion)
                row["mm_dist"].update(text, motion)
                row["fid"].update(motion, real=False)
                row["diversity"].update(motion)
        results = {}
        for source in self.sources:
            row = metrics[source.name]
            top = row["r_precision"].compute()
            values = {f"top{k + 1}": float(top[k]) for k in range(c.top_k)}
            values |= {name: float(row[name].compute()) for name in ("fid", "mm_dist", "diversity")}
            values |= source.extra_metrics()
            if success[source.name].update_count:
                values |= success[source.name].compute().as_dict()
            results[source.name] = values
        if self.multimodality and replication < c.mm_replications:
            for source in self.sources:
                if source.generates:
                    results[source.name]["multimodality"] = self._multimodality(source, replication)
        return results

    def _multimodality_items(self, replication: int) -> Batch:
        """The first ``mm_texts`` items of a re-drawn pass (its shuffle picks them at random)."""
        wanted, parts = self.constants.mm_texts, []
        for batch in self.loader(10_000 + replication):
            parts.append(batch)
            if sum(len(part["caption"]) for part in parts) >= wanted:
                break
        merged = _concatenate(parts)
        if len(merged["caption"]) < wanted:
            raise ValueError(
                f"MultiModality needs {wanted} test items, the split gave {len(merged['caption'])}"
            )
        return repeat_items(merged, torch.arange(wanted), 1)

    def _multimodality(self, source: MotionSource, replication: int) -> float:
        c = self.constants
        items = self._multimodality_items(replication)
        per_call = max(1, self.generation_batch_size // c.mm_generations)
        metric = MultiModality(num_pairs=c.mm_pairs, scale=c.mm_scale, seed=c.seed + replication)
        for start in range(0, c.mm_texts, per_call):
            indices = torch.arange(start, min(start + per_call, c.mm_texts))
            batch = repeat_items(items, indices, c.mm_generations)
            seeds = sample_seeds(c, replication, 1, len(batch["caption"]), start * c.mm_generations)
            embeddings = self._motion_embeddings(source, batch, seeds)
            metric.update(embeddings.reshape(len(indices), c.mm_generations, -1))
        return float(metric.compute())

    # ------------------------------------------------------------------ all replications
    def run(self, header: dict[str, Any]) -> ProtocolResult:
        collected: dict[str, dict[str, list[float]]] = {s.name: {} for s in self.sources}
        for r in range(self.constants.replications):
            self.progress(f"replication {r + 1}/{self.constants.replications}")
            for row, values in self.replication(r).items():
                for name, value in values.items():
                    collected[row].setdefault(name, []).append(value)
        result = ProtocolResult(
            header={
                **header,
                "constants": asdict(self.constants),
                "multimodality": self.multimodality,
            }
        )
        for row, metrics in collected.items():
            result.rows[row] = {name: Summary.of(values) for name, values in metrics.items()}
        return result


def _concatenate(batches: Sequence[Batch]) -> Batch:
    out: Batch = {}
    for key, value in batches[0].items():
        if isinstance(value, torch.Tensor):
            out[key] = torch.cat([batch[key] for batch in batches])
        elif isinstance(value, list | tuple):
            out[key] = [item for batch in batches for item in batch[key]]
    return out
