import numpy as np
import pytest
import scipy.linalg
import torch

from intermask.metrics import FID
from intermask.metrics.functional import frechet_distance, gaussian_statistics


def _numpy_fid(x: np.ndarray, y: np.ndarray) -> float:
    """Independent reference: Tr(sqrtm(S1 S2)) from the eigenvalues of S1 S2 (real, >= 0)."""
    mu1, mu2 = x.mean(0), y.mean(0)
    c1 = (x - mu1).T @ (x - mu1) / (len(x) - 1)
    c2 = (y - mu2).T @ (y - mu2) / (len(y) - 1)
    eigenvalues = np.linalg.eigvals(c1 @ c2).real.clip(min=0)
    return float(
        ((mu1 - mu2) ** 2).sum() + np.trace(c1) + np.trace(c2) - 2 * np.sqrt(eigenvalues).sum()
    )


def _fid(real: np.ndarray, fake: np.ndarray, *, emb_scale: float = 1.0) -> float:
    metric = FID(emb_scale=emb_scale)
    for chunk in np.array_split(real, 3):
        metric.update(torch.tensor(chunk), real=True)
    for chunk in np.array_split(fake, 2):
        metric.update(torch.tensor(chunk), real=False)
    value = metric.compute()
    assert value.dtype == torch.float64 and value.shape == ()
    return value.item()


def test_fid_of_a_set_with_itself_is_zero():
    x = np.random.default_rng(0).normal(size=(200, 16))
    assert abs(_fid(x, x)) < 1e-6


def test_fid_matches_independent_numpy_for_full_covariances():
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(8, 8)), rng.normal(size=(8, 8))
    x = rng.normal(size=(300, 8)) @ a + 1.0
    y = rng.normal(size=(250, 8)) @ b - 0.5
    expected = _numpy_fid(x, y)
    assert _fid(x, y) == pytest.approx(expected, rel=1e-6)
    # emb_scale multiplies the embeddings, so FID grows with its square
    assert _fid(x, y, emb_scale=6.0) == pytest.approx(36 * expected, rel=1e-6)


def test_fid_approaches_the_closed_form_for_diagonal_gaussians():
    # population value: ||mu1 - mu2||^2 + sum_d (sqrt(v1_d) - sqrt(v2_d))^2
    rng = np.random.default_rng(2)
    var1, var2 = np.array([1.0, 4.0, 0.25]), np.array([2.0, 1.0, 0.25])
    mu1, mu2 = np.array([0.0, 1.0, -1.0]), np.array([0.5, 1.0, 0.0])
    x = mu1 + rng.normal(size=(40000, 3)) * np.sqrt(var1)
    y = mu2 + rng.normal(size=(40000, 3)) * np.sqrt(var2)
    closed = ((mu1 - mu2) ** 2).sum() + ((np.sqrt(var1) - np.sqrt(var2)) ** 2).sum()
    assert _fid(x, y) == pytest.approx(closed, abs=0.05)


def test_frechet_distance_of_known_matrices():
    rng = np.random.default_rng(3)
    m1, m2 = rng.normal(size=(5, 5)), rng.normal(size=(5, 5))
    s1, s2 = m1 @ m1.T + np.eye(5), m2 @ m2.T + 0.1 * np.eye(5)
    mu1, mu2 = rng.normal(size=5), rng.normal(size=5)
    trace_sqrt = np.sqrt(np.linalg.eigvals(s1 @ s2).real).sum()
    expected = ((mu1 - mu2) ** 2).sum() + np.trace(s1) + np.trace(s2) - 2 * trace_sqrt
    assert frechet_distance(mu1, s1, mu2, s2) == pytest.approx(expected, rel=1e-9)
    mu, sigma = gaussian_statistics(rng.normal(size=(10, 5)))
    assert mu.shape == (5,) and sigma.shape == (5, 5)


def test_frechet_distance_retries_with_an_offset_when_sqrtm_is_not_finite():
    nilpotent = np.array([[0.0, 1.0], [0.0, 0.0]])  # has no square root
    identity = np.eye(2)
    with pytest.warns(scipy.linalg.LinAlgWarning):
        assert not np.isfinite(scipy.linalg.sqrtm(nilpotent @ identity)).all()
    eps = 1e-6
    # sqrtm((N + eps I)(1 + eps) I) has diagonal sqrt(eps (1 + eps))
    expected = 0.0 + 2.0 - 2 * 2 * np.sqrt(eps * (1 + eps))
    zeros = np.zeros(2)
    assert frechet_distance(zeros, nilpotent, zeros, identity, eps=eps) == pytest.approx(
        expected, rel=1e-6
    )
    with pytest.raises(ValueError, match=r"not finite even after adding 1e-06 \* I"):
        frechet_distance(zeros, np.full((2, 2), np.nan), zeros, identity)


def test_frechet_distance_drops_a_small_imaginary_part_and_rejects_a_large_one():
    zeros, identity = np.zeros(2), np.eye(2)
    # sqrtm(diag(-1e-8, 1)) = diag(1e-4 i, 1): imaginary part within atol, trace real part 1
    tiny_negative = np.diag([-1e-8, 1.0])
    assert frechet_distance(zeros, tiny_negative, zeros, identity) == pytest.approx(
        1.0 - 1e-8 + 2.0 - 2.0
    )
    with pytest.raises(
        ValueError, match=r"imaginary component of 1 on its diagonal \(> atol 0.001\)"
    ):
        frechet_distance(zeros, np.diag([-1.0, 1.0]), zeros, identity)


def test_fid_drops_padded_duplicates_by_sample_id():
    rng = np.random.default_rng(4)
    real, fake = rng.normal(size=(30, 4)), rng.normal(size=(30, 4)) + 0.3
    expected = _fid(real, fake)
    metric = FID()
    ids = torch.arange(30)
    metric.update(torch.tensor(real), real=True, sample_ids=ids)
    metric.update(torch.tensor(real[:3] + 5.0), real=True, sample_ids=ids[:3])  # padding repeats
    metric.update(torch.tensor(fake[15:]), real=False, sample_ids=ids[15:])
    metric.update(torch.tensor(fake[:15]), real=False, sample_ids=ids[:15])
    assert metric.compute().item() == pytest.approx(expected, rel=1e-9)


def test_fid_errors():
    metric = FID()
    metric.update(torch.zeros(5, 3), real=True)
    with pytest.raises(ValueError, match="FID needs at least 2 fake embeddings, got 0"):
        metric.compute()
    metric.update(torch.zeros(1, 3), real=False)
    with pytest.raises(ValueError, match="FID needs at least 2 fake embeddings, got 1"):
        metric.compute()
    with pytest.raises(ValueError, match=r"FID needs \(B, D\) embeddings, got \(4,\)"):
        metric.update(torch.zeros(4), real=True)
    with pytest.raises(ValueError, match="FID: fake embeddings contain NaN or inf"):
        metric.update(torch.full((2, 3), float("nan")), real=False)
    with pytest.raises(
        ValueError, match=r"sample_ids must have shape \(2,\) to match the batch, got \(3,\)"
    ):
        metric.update(torch.zeros(2, 3), real=False, sample_ids=torch.arange(3))
    with pytest.raises(ValueError, match="sample_ids must be >= 0, got -2"):
        metric.update(torch.zeros(2, 3), real=False, sample_ids=torch.tensor([0, -2]))
    with pytest.raises(ValueError, match="sample_ids must be integers, got dtype torch.float32"):
        metric.update(torch.zeros(2, 3), real=False, sample_ids=torch.zeros(2))
    metric.update(torch.ones(2, 3), real=False, sample_ids=torch.tensor([0, 1]))
    with pytest.raises(
        ValueError, match=r"some updates passed sample_ids and some did not \(1 of 3"
    ):
        metric.compute()
