"""The action-to-reaction path and the x1-prediction Euler sampler (ARFlow eqs. 4, 7, 9, 12-13)."""

from __future__ import annotations

import pytest
import torch
from reaction_builders import Oracle, parts

from intermask.reaction.flow import (
    euler_step,
    interpolate,
    path_scale,
    recover_x0,
    time_grid,
    velocity,
)
from intermask.reaction.guidance import Guidance, reprojection_step
from intermask.reaction.sampler import generate_reaction

SIGMA = 1e-2  # large enough to see its effect


def _pair(seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    return torch.randn(3, 5, 7, generator=generator), torch.randn(3, 5, 7, generator=generator)


def test_path_endpoints():
    x0, x1 = _pair()
    assert torch.equal(interpolate(x0, x1, 0.0, sigma_min=SIGMA), x0)
    # t = 1 keeps sigma_min of the action: x1 + sigma_min x0
    torch.testing.assert_close(interpolate(x0, x1, 1.0, sigma_min=SIGMA), x1 + SIGMA * x0)
    t = torch.tensor([0.0, 0.5, 1.0])
    mid = interpolate(x0, x1, t, sigma_min=SIGMA)
    torch.testing.assert_close(mid[1], 0.5 * x1[1] + (1 - 0.5 * (1 - SIGMA)) * x0[1])
    assert path_scale(1.0, SIGMA) == pytest.approx(SIGMA)


def test_recover_x0_inverts_the_path():
    x0, x1 = _pair(1)
    t = torch.tensor([0.0, 0.3, 0.9])
    x_t = interpolate(x0, x1, t, sigma_min=SIGMA)
    torch.testing.assert_close(recover_x0(x_t, x1, t, sigma_min=SIGMA), x0)


def test_euler_step_is_the_velocity_step_and_the_reprojection():
    x0, x1 = _pair(2)
    x1_hat = x1 + 0.3  # an imperfect prediction
    x_t = interpolate(x0, x1, 0.4, sigma_min=SIGMA)
    step = euler_step(x_t, x1_hat, 0.4, 0.6, sigma_min=SIGMA)
    # eq. 8 with the vector field of eq. 7
    torch.testing.assert_close(step, x_t + 0.2 * velocity(x_t, x1_hat, 0.4, sigma_min=SIGMA))
    # eqs. 12-13: re-interpolating between x1_hat and x0_hat is the same step
    torch.testing.assert_close(reprojection_step(x_t, x1_hat, x0, 0.4, 0.6, sigma_min=SIGMA), step)


@pytest.mark.parametrize("steps", [1, 2, 5, 10])
def test_sampler_with_a_perfect_predictor_returns_x1(steps):
    x0, x1 = _pair(3)
    oracle = Oracle(x1)
    mask = torch.ones(x0.shape[:2], dtype=torch.bool)
    out = generate_reaction(parts(oracle, sigma_min=SIGMA), x0, mask, steps=steps)
    # the state stays on the path at every step, so it ends at x_1 = x1 + sigma_min x0
    torch.testing.assert_close(out, x1 + SIGMA * x0)
    assert oracle.calls == steps


def test_improved_sampling_without_guidance_force_keeps_x1():
    x0, x1 = _pair(4)
    mask = torch.ones(x0.shape[:2], dtype=torch.bool)
    # w < 1 pulls x0_hat towards the true x0, which a perfect predictor already implies
    out = generate_reaction(
        parts(Oracle(x1), sigma_min=SIGMA), x0, mask, steps=5, guidance=Guidance(lambda_pene=0.0)
    )
    torch.testing.assert_close(out, x1 + SIGMA * x0)


def test_time_grid_and_its_errors():
    assert time_grid(5).tolist() == pytest.approx([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    with pytest.raises(ValueError, match="steps must be >= 1, got 0"):
        time_grid(0)
    x0, x1 = _pair()
    with pytest.raises(ValueError, match=r"t must be a scalar or \(3,\), got \(2,\)"):
        interpolate(x0, x1, torch.zeros(2))
    with pytest.raises(ValueError, match="x0 and x1 must have one shape"):
        interpolate(x0, x1[:, :2], 0.5)
    with pytest.raises(ValueError, match=r"sigma_min must lie in \(0, 1\), got 0.0"):
        generate_reaction(parts(Oracle(x1), sigma_min=0.0), x0, torch.ones(3, 5, dtype=torch.bool))
