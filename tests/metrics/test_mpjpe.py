import numpy as np
import pytest
import torch

from intermask.metrics.mpjpe import MPJPE


def test_mpjpe_matches_numpy_and_ignores_masked_frames():
    rng = np.random.default_rng(0)
    prediction, target = rng.normal(size=(3, 10, 22, 3)), rng.normal(size=(3, 10, 22, 3))
    mask = np.ones((3, 10), dtype=bool)
    mask[1, 6:] = False
    prediction[1, 6:] += 100.0  # padding garbage must not count
    expected = np.linalg.norm(prediction - target, axis=-1)[mask].mean() * 1000
    metric = MPJPE(scale=1000.0)
    metric.update(torch.tensor(prediction[:2]), torch.tensor(target[:2]), torch.tensor(mask[:2]))
    metric.update(torch.tensor(prediction[2:]), torch.tensor(target[2:]), torch.tensor(mask[2:]))
    assert metric.compute().item() == pytest.approx(expected, rel=1e-5)


def test_mpjpe_errors():
    with pytest.raises(ValueError, match=r"MPJPE needs two \(\.\.\., J, 3\) tensors of one shape"):
        MPJPE().update(torch.zeros(2, 22, 3), torch.zeros(2, 21, 3))
    with (
        pytest.raises(ValueError, match="before any update"),
        pytest.warns(UserWarning, match="before the ``update``"),
    ):
        MPJPE().compute()
