import numpy as np
import pytest
import torch

from intermask.metrics import Diversity, MultiModality
from intermask.metrics.functional import draw_pair_indices


def test_draw_pair_indices_is_seeded_and_without_replacement():
    first, second = draw_pair_indices(50, 20, seed=3407)
    assert first.dtype == torch.int64 and first.shape == second.shape == (20,)
    assert len(set(first.tolist())) == 20 and len(set(second.tolist())) == 20
    assert 0 <= int(torch.cat([first, second]).min()) and int(torch.cat([first, second]).max()) < 50
    assert not torch.equal(first, second)  # two independent draws
    again = draw_pair_indices(50, 20, seed=3407)
    assert torch.equal(first, again[0]) and torch.equal(second, again[1])
    assert not torch.equal(first, draw_pair_indices(50, 20, seed=1)[0])
    with pytest.raises(ValueError, match="cannot draw 20 pairs without replacement from 10 items"):
        draw_pair_indices(10, 20, seed=0)


def test_diversity_matches_numpy_with_the_same_indices():
    embeddings = np.random.default_rng(0).normal(size=(50, 8))
    metric = Diversity(num_pairs=20, emb_scale=6.0, divide_by=2.0, seed=11)
    for chunk in np.array_split(embeddings, 4):
        metric.update(torch.tensor(chunk, dtype=torch.float32))
    first, second = (i.numpy() for i in draw_pair_indices(50, 20, seed=11))
    scaled = embeddings.astype(np.float32).astype(np.float64) * 6.0
    expected = np.linalg.norm(scaled[first] - scaled[second], axis=1).mean() / 2.0
    value = metric.compute()
    assert value.dtype == torch.float64 and value.item() == pytest.approx(expected, rel=1e-12)
    assert metric.compute().item() == value.item()  # compute is deterministic


def test_diversity_orders_by_sample_id_and_drops_duplicates():
    embeddings = torch.tensor(np.random.default_rng(1).normal(size=(30, 4)))
    in_order = Diversity(num_pairs=10)
    in_order.update(embeddings)
    shuffled = Diversity(num_pairs=10)
    permutation = torch.randperm(30, generator=torch.Generator().manual_seed(0))
    shuffled.update(embeddings[permutation], sample_ids=permutation)
    shuffled.update(embeddings[permutation[:4]] + 9.0, sample_ids=permutation[:4])  # padding
    assert shuffled.compute().item() == pytest.approx(in_order.compute().item(), rel=1e-12)


def test_multimodality_matches_numpy_with_the_same_indices():
    embeddings = np.random.default_rng(2).normal(size=(9, 12, 6))
    metric = MultiModality(num_pairs=5, scale=3.0, seed=5)
    metric.update(torch.tensor(embeddings[:4]), sample_ids=torch.arange(4))
    metric.update(torch.tensor(embeddings[4:]), sample_ids=torch.arange(4, 9))
    metric.update(torch.tensor(embeddings[:2]) * 0, sample_ids=torch.arange(2))  # padding
    first, second = (i.numpy() for i in draw_pair_indices(12, 5, seed=5))
    expected = np.linalg.norm(embeddings[:, first] - embeddings[:, second], axis=2).mean() * 3.0
    assert metric.compute().item() == pytest.approx(expected, rel=1e-12)


def test_diversity_and_multimodality_errors():
    metric = Diversity(num_pairs=300)
    metric.update(torch.zeros(50, 4))
    with pytest.raises(ValueError, match="Diversity needs at least num_pairs=300 samples, got 50"):
        metric.compute()
    with pytest.raises(ValueError, match=r"Diversity needs \(B, D\) embeddings, got \(2, 3, 4\)"):
        metric.update(torch.zeros(2, 3, 4))
    with pytest.raises(ValueError, match="Diversity num_pairs must be >= 1, got 0"):
        Diversity(num_pairs=0)
    with pytest.raises(
        ValueError, match="MultiModality needs G >= num_pairs=10 generations per text, got G=8"
    ):
        MultiModality(num_pairs=10).update(torch.zeros(3, 8, 4))
    with pytest.raises(
        ValueError, match=r"MultiModality needs \(B, G, D\) embeddings, got \(3, 4\)"
    ):
        MultiModality().update(torch.zeros(3, 4))
    with pytest.raises(ValueError, match="MultiModality: embeddings contain NaN or inf"):
        MultiModality(num_pairs=2).update(torch.full((1, 3, 4), float("nan")))
    metric = MultiModality(num_pairs=2)
    metric.update(torch.zeros(1, 3, 4))
    metric.update(torch.zeros(1, 4, 4))
    with pytest.raises(
        ValueError,
        match=r"MultiModality: updates had inconsistent per-sample shapes \[\(3, 4\), \(4, 4\)\]",
    ):
        metric.compute()
