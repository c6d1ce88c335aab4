"""Contrastive losses and in-batch retrieval accuracy of the evaluators (pure functions + one
torchmetrics Metric)."""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torchmetrics import Metric
from torchmetrics.utilities import dim_zero_cat


def clip_loss(text: torch.Tensor, motion: torch.Tensor, logit_scale: torch.Tensor) -> torch.Tensor:
    """InterGen's CLIP loss: (B, D) text and motion embeddings -> () symmetric cross-entropy of
    ``logit_scale * cosine`` logits, row i of each side matching row i of the other."""
    logits = logit_scale * F.normalize(motion, dim=-1) @ F.normalize(text, dim=-1).T  # (B, B)
    target = torch.arange(len(text), device=text.device)
    return (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target)) / 2


def margin_loss(
    text: torch.Tensor, motion: torch.Tensor, *, margin: float, shift: int
) -> torch.Tensor:
    """T2M's matcher loss: squared distance of matching pairs plus squared hinge
    ``max(0, margin - d)`` of mismatched pairs made by rolling the motions by ``shift`` rows.

    The reference draws shift in [0, B-2]; 0 pairs every text with its own motion as a
    "negative", so callers draw it in [1, B-1].
    """
    if not 1 <= shift < len(text):
        raise ValueError(
            f"shift must lie in [1, {len(text) - 1}] for a batch of {len(text)}, got {shift}"
        )
    positive = F.pairwise_distance(text, motion).square().mean()
    negative = F.pairwise_distance(text, motion.roll(-shift, dims=0))
    return positive + (margin - negative).clamp(min=0).square().mean()


def retrieval_hits(
    text: torch.Tensor, motion: torch.Tensor, top_k: Sequence[int] = (1, 2, 3)
) -> torch.Tensor:
    """(N, D) texts and motions -> (len(top_k),) hit counts: text i hits at k when motion i is
    among its k nearest motions by Euclidean distance (the protocol's R-precision within one
    group; ties count in the text's favour)."""
    distances = torch.cdist(text.double(), motion.double())  # (N, N)
    rank = (distances < distances.diagonal()[:, None]).sum(dim=1)  # (N,) motions strictly closer
    return torch.stack([(rank < k).sum() for k in top_k])


class RetrievalAccuracy(Metric):
    """R-precision top-k within groups of ``group_size`` consecutive (text, motion) pairs.

    The pairs of a validation epoch are concatenated and cut into groups of ``group_size``
    (the protocol's eval batch: 96 InterHuman, 32 Inter-X); a remainder is dropped. Fewer pairs
    than one group form a single smaller group (``compute`` reports the size used).
    """

    full_state_update = False

    def __init__(self, *, group_size: int, top_k: Sequence[int] = (1, 2, 3)) -> None:
        super().__init__()
        if group_size < 2:
            raise ValueError(f"group_size must be >= 2, got {group_size}")
        self.group_size, self.top_k = group_size, tuple(top_k)
        self.add_state("text", default=[], dist_reduce_fx="cat")
        self.add_state("motion", default=[], dist_reduce_fx="cat")

    def update(self, text: torch.Tensor, motion: torch.Tensor) -> None:
        """(B, D) text and motion embeddings, row i matching row i."""
        if text.shape != motion.shape:
            raise ValueError(f"text {tuple(text.shape)} and motion {tuple(motion.shape)} differ")
        self.text.append(text.detach().float())
        self.motion.append(motion.detach().float())

    def compute(self) -> dict[str, torch.Tensor]:
        text, motion = dim_zero_cat(self.text), dim_zero_cat(self.motion)
        size = min(self.group_size, len(text))
        if size < 2:
            raise ValueError(f"need at least 2 pairs for retrieval accuracy, got {len(text)}")
        groups = len(text) // size
        hits = sum(
            retrieval_hits(
                text[g * size : (g + 1) * size], motion[g * size : (g + 1) * size], self.top_k
            )
            for g in range(groups)
        )
        result = {f"top{k}": hits[i].float() / (groups * size) for i, k in enumerate(self.top_k)}
        result["group_size"] = torch.tensor(float(size))
        return result
