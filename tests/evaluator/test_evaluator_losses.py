"""Losses and in-batch retrieval accuracy against independent numpy computations."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from intermask.evaluator.losses import RetrievalAccuracy, clip_loss, margin_loss, retrieval_hits


def _log_softmax(x, axis):
    x = x - x.max(axis=axis, keepdims=True)
    return x - np.log(np.exp(x).sum(axis=axis, keepdims=True))


def test_clip_loss_matches_numpy():
    rng = np.random.default_rng(0)
    text, motion = rng.normal(size=(5, 8)), rng.normal(size=(5, 8))
    t = text / np.linalg.norm(text, axis=1, keepdims=True)
    m = motion / np.linalg.norm(motion, axis=1, keepdims=True)
    logits = 2.3 * m @ t.T
    expected = (
        -(np.diag(_log_softmax(logits, 1)).mean() + np.diag(_log_softmax(logits, 0)).mean()) / 2
    )
    got = clip_loss(
        torch.tensor(text), torch.tensor(motion), torch.tensor(2.3, dtype=torch.float64)
    )
    assert float(got) == pytest.approx(expected, rel=1e-9)


def test_margin_loss_matches_numpy():
    rng = np.random.default_rng(1)
    text, motion = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    positive = (np.linalg.norm(text - motion, axis=1) ** 2).mean()
    rolled = motion[[2, 3, 0, 1]]  # shift 2
    negative = (np.maximum(5.0 - np.linalg.norm(text - rolled, axis=1), 0) ** 2).mean()
    got = margin_loss(torch.tensor(text), torch.tensor(motion), margin=5.0, shift=2)
    assert float(got) == pytest.approx(positive + negative, rel=1e-6)
    with pytest.raises(ValueError, match=r"shift must lie in \[1, 3\]"):
        margin_loss(torch.tensor(text), torch.tensor(motion), margin=5.0, shift=0)


def _numpy_hits(text, motion, ks):
    distances = np.linalg.norm(text[:, None] - motion[None], axis=-1)
    order = np.argsort(distances, axis=1)
    return [sum(i in order[i, :k] for i in range(len(text))) for k in ks]


def test_retrieval_hits_match_numpy_argsort():
    rng = np.random.default_rng(2)
    text = rng.normal(size=(30, 6))
    motion = text + rng.normal(scale=1.0, size=(30, 6))
    got = retrieval_hits(torch.tensor(text), torch.tensor(motion), (1, 2, 3, 10)).tolist()
    assert got == _numpy_hits(text, motion, (1, 2, 3, 10))


def test_retrieval_accuracy_groups_and_drops_the_remainder():
    rng = np.random.default_rng(3)
    text, motion = rng.normal(size=(25, 4)), rng.normal(size=(25, 4))
    metric = RetrievalAccuracy(group_size=10)
    metric.update(torch.tensor(text[:13]), torch.tensor(motion[:13]))
    metric.update(torch.tensor(text[13:]), torch.tensor(motion[13:]))
    result = metric.compute()
    hits = np.add(
        _numpy_hits(text[:10], motion[:10], (1, 3)), _numpy_hits(text[10:20], motion[10:20], (1, 3))
    )
    assert float(result["top1"]) == pytest.approx(hits[0] / 20)
    assert float(result["top3"]) == pytest.approx(hits[1] / 20)
    small = RetrievalAccuracy(group_size=96)
    small.update(torch.tensor(text[:7]), torch.tensor(text[:7]))
    assert float(small.compute()["top1"]) == 1.0 and float(small.compute()["group_size"]) == 7
    with pytest.raises(ValueError, match="group_size must be >= 2"):
        RetrievalAccuracy(group_size=1)
