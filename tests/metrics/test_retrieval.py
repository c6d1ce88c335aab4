import numpy as np
import pytest
import torch

from intermask.metrics import MMDist, RPrecision
from intermask.metrics.functional import top_k_hits


def _numpy_r_precision(
    text: np.ndarray, motion: np.ndarray, *, batch: int, top_k: int
) -> np.ndarray:
    hits = []
    for start in range(0, len(text), batch):
        s, m = text[start : start + batch], motion[start : start + batch]
        distances = np.sqrt(((s[:, None, :] - m[None, :, :]) ** 2).sum(-1))
        rank = np.argsort(distances, axis=1, kind="stable").argsort(axis=1)[
            np.arange(len(s)), np.arange(len(s))
        ]
        hits.append(rank[:, None] < np.arange(1, top_k + 1)[None, :])
    return np.concatenate(hits).mean(0)


def _feed(metric, text: np.ndarray, motion: np.ndarray, *, batch: int) -> torch.Tensor:
    for start in range(0, len(text), batch):
        metric.update(
            torch.tensor(text[start : start + batch]), torch.tensor(motion[start : start + batch])
        )
    return metric.compute()


def test_r_precision_is_one_on_aligned_embeddings():
    x = np.random.default_rng(0).normal(size=(64, 16))
    result = _feed(RPrecision(top_k=3), x, x, batch=32)
    assert result.dtype == torch.float64 and result.shape == (3,)
    assert result.tolist() == [1.0, 1.0, 1.0]


def test_r_precision_on_unrelated_embeddings_is_k_over_b():
    rng = np.random.default_rng(1)
    batch, batches = 16, 300
    text, motion = rng.normal(size=(2, batch * batches, 8))
    result = _feed(RPrecision(top_k=3), text, motion, batch=batch)
    # 4800 rows: the standard error of a hit rate p = 3/16 is 0.0056
    np.testing.assert_allclose(result.numpy(), np.arange(1, 4) / batch, atol=0.025)


def test_r_precision_and_mm_dist_match_numpy():
    rng = np.random.default_rng(2)
    text = rng.normal(size=(96, 12))
    motion = text + rng.normal(size=(96, 12)) * 1.2  # partly aligned: a mix of hits and misses
    expected = _numpy_r_precision(text, motion, batch=32, top_k=3)
    assert 0.1 < expected[0] < 0.9
    np.testing.assert_allclose(
        _feed(RPrecision(top_k=3), text, motion, batch=32).numpy(), expected, rtol=1e-12
    )
    mm_dist = _feed(MMDist(), text, motion, batch=32)
    assert mm_dist.item() == pytest.approx(np.linalg.norm(text - motion, axis=1).mean(), rel=1e-12)


def test_top_k_hits_breaks_ties_by_motion_index():
    distances = torch.tensor([[1.0, 1.0, 1.0], [1.0, 1.0, 0.5], [2.0, 0.0, 2.0]])
    # row 0: own motion first among equals; row 1: behind motions 2 and 0; row 2: behind 1 and 0
    assert top_k_hits(distances, top_k=3).tolist() == [
        [True, True, True],
        [False, False, True],
        [False, False, True],
    ]


def test_retrieval_metrics_drop_a_duplicated_batch_by_sample_id():
    rng = np.random.default_rng(3)
    text = torch.tensor(rng.normal(size=(20, 6)))
    motion = text + torch.tensor(rng.normal(size=(20, 6)))
    ids = torch.arange(20)
    reference_r, reference_mm = RPrecision(top_k=2), MMDist()
    deduplicated_r, deduplicated_mm = RPrecision(top_k=2), MMDist()
    for start in (0, 10):
        part = slice(start, start + 10)
        reference_r.update(text[part], motion[part])
        reference_mm.update(text[part], motion[part])
    for start in (10, 0, 0):  # the last batch is a sampler's padding: ids repeat
        part = slice(start, start + 10)
        deduplicated_r.update(text[part], motion[part], sample_ids=ids[part])
        deduplicated_mm.update(text[part], motion[part], sample_ids=ids[part])
    assert torch.equal(deduplicated_r.compute(), reference_r.compute())
    assert deduplicated_mm.compute().item() == pytest.approx(
        reference_mm.compute().item(), rel=1e-12
    )


def test_retrieval_errors():
    with pytest.raises(ValueError, match="RPrecision top_k must be >= 1, got 0"):
        RPrecision(top_k=0)
    with pytest.raises(ValueError, match="an eval batch of 2 samples cannot rank top_k=3"):
        RPrecision(top_k=3).update(torch.zeros(2, 4), torch.zeros(2, 4))
    with pytest.raises(
        ValueError,
        match=r"RPrecision needs text and motion embeddings of one \(B, D\) shape, got \(4, 4\) and \(4, 5\)",
    ):
        RPrecision().update(torch.zeros(4, 4), torch.zeros(4, 5))
    with pytest.raises(ValueError, match="MMDist: embeddings contain NaN or inf"):
        MMDist().update(torch.zeros(4, 4), torch.full((4, 4), float("inf")))
    with pytest.raises(ValueError, match=r"top_k must lie in \[1, B=2\], got 3"):
        top_k_hits(torch.zeros(2, 2), top_k=3)
    with (
        pytest.raises(ValueError, match=r"MMDist.compute\(\) called before any update"),
        pytest.warns(UserWarning, match="before the ``update``"),
    ):
        MMDist().compute()
