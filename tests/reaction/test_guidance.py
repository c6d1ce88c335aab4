"""Penetration guidance: gradients at x1_hat only, the paper's update rules, their settings."""

from __future__ import annotations

import pytest
import torch
from reaction_builders import Oracle, make_net, parts, standing_pair

from intermask.physics import penetration_loss
from intermask.reaction.flow import euler_step
from intermask.reaction.guidance import (
    Guidance,
    penetration_gradient,
    random_direction,
    reprojection_step,
    vanilla_step,
)
from intermask.reaction.representation import FeatureSpace
from intermask.reaction.sampler import generate_reaction

SPACE = FeatureSpace(representation="interhuman")


def _overlapping(gap: float = 0.3):
    motion = standing_pair(gap=gap)
    return (
        motion[:, 0],
        motion[:, 1],
        torch.ones(motion.shape[0], motion.shape[2], dtype=torch.bool),
    )


def _penetration(reaction: torch.Tensor, actor: torch.Tensor) -> float:
    return float(penetration_loss(SPACE.joints(reaction), SPACE.joints(actor), zeta=0.5))


def test_gradient_step_reduces_penetration_and_touches_positions_only():
    actor, reactor, mask = _overlapping()
    direction = penetration_gradient(reactor, SPACE.joints(actor), SPACE, frame_mask=mask)
    assert direction.shape == reactor.shape
    assert direction[..., 66:].abs().max() == 0  # velocities, rotations, contacts: not scored
    assert _penetration(reactor - 2.0 * direction, actor) < _penetration(reactor, actor)
    # the step is metres-sized, not a jump across the room
    moved = (SPACE.joints(reactor - 2.0 * direction) - SPACE.joints(reactor)).norm(dim=-1)
    assert 0.01 < float(moved.max()) < 0.5


def test_gradient_is_zero_beyond_the_safe_distance_and_on_padding():
    actor, reactor, mask = _overlapping(gap=3.0)
    assert (
        penetration_gradient(reactor, SPACE.joints(actor), SPACE, frame_mask=mask).abs().max() == 0
    )
    actor, reactor, mask = _overlapping()
    mask[:, 3:] = False
    direction = penetration_gradient(reactor, SPACE.joints(actor), SPACE, frame_mask=mask)
    assert direction[:, 3:].abs().max() == 0 and direction[:, :3].abs().max() > 0


def test_gradient_is_taken_in_dataset_units():
    actor, reactor, mask = _overlapping()
    scaled = FeatureSpace(representation="interhuman")
    scaled.set_statistics(torch.zeros(262), torch.full((262,), 2.0))
    # the same metric body (reactor / 2 in normalized units) gets the same metric step
    plain = penetration_gradient(reactor, SPACE.joints(actor), SPACE, frame_mask=mask)
    direction = penetration_gradient(reactor / 2, SPACE.joints(actor), scaled, frame_mask=mask)
    torch.testing.assert_close(direction * 2, plain)


@pytest.mark.parametrize("mode", ["vanilla", "improved"])
def test_guidance_never_differentiates_the_network(mode):
    actor, reactor, mask = _overlapping()
    oracle = Oracle(reactor)
    out = generate_reaction(parts(oracle), actor, mask, steps=5, guidance=Guidance(mode=mode))
    assert oracle.calls == 5  # one network call per Euler step, guidance adds none
    assert oracle.scale.grad is None and not out.requires_grad
    assert _penetration(out, actor) < _penetration(reactor, actor)


def test_guidance_with_a_real_network_leaves_its_parameters_alone():
    actor, reactor, mask = _overlapping()
    net = make_net(causal=True)
    generate_reaction(parts(net), actor, mask, steps=2, guidance=Guidance())
    assert all(p.grad is None for p in net.parameters())


def test_vanilla_and_reprojection_rules():
    generator = torch.Generator().manual_seed(0)
    x_t, x1_hat, x0, grad = (torch.randn(2, 4, 3, generator=generator) for _ in range(4))
    s, t, t_next, lam, w = 1e-4, 0.4, 0.6, 2.0, 0.7
    torch.testing.assert_close(
        vanilla_step(x_t, x1_hat, grad, t, t_next, lambda_pene=lam, sigma_min=s),
        euler_step(x_t, x1_hat, t, t_next, sigma_min=s) - lam * grad,
    )
    x0_hat = (x_t - t * x1_hat) / (1 - (1 - s) * t)
    expected = t_next * (x1_hat - lam * grad) + (1 - (1 - s) * t_next) * (w * x0_hat + (1 - w) * x0)
    out = reprojection_step(
        x_t, x1_hat, x0, t, t_next, gradient=grad, lambda_pene=lam, w=w, sigma_min=s
    )
    torch.testing.assert_close(out, expected)


def test_stochastic_direction_mixes_with_beta():
    generator = torch.Generator().manual_seed(1)
    x_t, x1_hat, x0, noise = (torch.randn(2, 4, 3, generator=generator) for _ in range(4))
    d_random = random_direction(x0 - x1_hat, noise)
    torch.testing.assert_close(d_random.norm(dim=-1), (x0 - x1_hat).norm(dim=-1))
    beta, t_next = 0.05, 0.6
    x0_hat = (x_t - 0.4 * x1_hat) / (1 - (1 - 1e-4) * 0.4)
    d = x0_hat - x1_hat
    expected = (
        x1_hat
        + (1 - t_next) * (d + beta * (random_direction(d, noise) - d))
        + 1e-4 * t_next * x0_hat
    )
    out = reprojection_step(x_t, x1_hat, x0, 0.4, t_next, beta=beta, noise=noise)
    torch.testing.assert_close(out, expected)
    with pytest.raises(ValueError, match="stochastic sampling .* needs noise"):
        reprojection_step(x_t, x1_hat, x0, 0.4, t_next, beta=beta)


def test_guidance_settings_are_checked():
    assert Guidance() == Guidance(mode="improved", lambda_pene=2.0, zeta=0.5, w=0.7, beta=0.0)
    with pytest.raises(ValueError, match="guidance mode must be 'none', 'vanilla' or 'improved'"):
        Guidance(mode="strong")
    with pytest.raises(ValueError, match=r"w and beta must lie in \[0, 1\], got 1.5 and 0.0"):
        Guidance(w=1.5)
    with pytest.raises(ValueError, match="lambda_pene and zeta must be >= 0"):
        Guidance(lambda_pene=-1.0)
    with pytest.raises(ValueError, match="not 'vanilla'"):
        Guidance(mode="vanilla", beta=0.02)
