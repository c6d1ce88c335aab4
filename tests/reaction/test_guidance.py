"""Penetration guidance: Algorithm 1's gradient through the network, the clean-prediction
gradient, the paper's update rules, their settings."""

from __future__ import annotations

import pytest
import torch
from reaction_builders import Oracle, make_net, parts, standing_pair

from intermask.physics import penetration_loss
from intermask.reaction.flow import euler_step
from intermask.reaction.guidance import (
    Guidance,
    network_penetration_gradient,
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


@pytest.mark.parametrize("mode", ["clean_gradient", "improved"])
def test_clean_prediction_guidance_never_differentiates_the_network(mode):
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
    with pytest.raises(
        ValueError,
        match="guidance mode must be one of 'none', 'vanilla', 'clean_gradient', 'improved', "
        "got 'strong'",
    ):
        Guidance(mode="strong")
    with pytest.raises(ValueError, match=r"w and beta must lie in \[0, 1\], got 1.5 and 0.0"):
        Guidance(w=1.5)
    with pytest.raises(ValueError, match="lambda_pene and zeta must be >= 0"):
        Guidance(lambda_pene=-1.0)
    for mode in ("vanilla", "clean_gradient"):
        with pytest.raises(ValueError, match=f"'improved' or 'none', not '{mode}'"):
            Guidance(mode=mode, beta=0.02)


class Blend(torch.nn.Module):
    """x1_hat = a x_t + (1 - a) x1: a prediction that depends on the state, Jacobian a I."""

    def __init__(self, x1: torch.Tensor, a: float) -> None:
        super().__init__()
        self.x1, self.a, self.calls = x1, torch.nn.Parameter(torch.tensor(a)), 0
        self.feature_dim, self.text_dim = x1.shape[-1], None

    def forward(self, x_t, t, actor, frame_mask, text=None, drop=None):
        self.calls += 1
        return self.a * x_t + (1 - self.a) * self.x1


def test_algorithm_1_differentiates_through_the_network_by_the_chain_rule():
    actor, reactor, mask = _overlapping()
    joints = SPACE.joints(actor)
    clean = penetration_gradient(reactor, joints, SPACE, frame_mask=mask)
    # x1_hat = 0.5 x_t + 0.5 reactor: at x_t = reactor, x1_hat = reactor and the gradient with
    # respect to x_t is the clean one times the Jacobian, 0.5
    x1_hat, direction = network_penetration_gradient(
        lambda x: 0.5 * x + 0.5 * reactor, reactor, joints, SPACE, frame_mask=mask
    )
    torch.testing.assert_close(x1_hat, reactor)
    torch.testing.assert_close(direction, 0.5 * clean)
    assert direction.abs().max() > 0
    # an identity network gives the clean gradient, in the same dataset units
    scaled = FeatureSpace(representation="interhuman")
    scaled.set_statistics(torch.zeros(262), torch.full((262,), 2.0))
    _, identity = network_penetration_gradient(
        lambda x: x, reactor / 2, joints, scaled, frame_mask=mask
    )
    torch.testing.assert_close(
        identity, penetration_gradient(reactor / 2, joints, scaled, frame_mask=mask)
    )


def test_algorithm_1_gradient_differs_from_the_clean_one_on_a_real_network():
    actor, reactor, mask = _overlapping()
    net = make_net(causal=False)
    t = torch.full((actor.shape[0],), 0.5)
    x1_hat, through = network_penetration_gradient(
        lambda x: net(x, t, actor, mask), reactor, SPACE.joints(actor), SPACE, frame_mask=mask
    )
    clean = penetration_gradient(x1_hat, SPACE.joints(actor), SPACE, frame_mask=mask)
    assert through.abs().max() > 0 and clean.abs().max() > 0
    cosine = torch.nn.functional.cosine_similarity(through.flatten(), clean.flatten(), dim=0)
    assert float(cosine) < 0.9  # the network's Jacobian turns the direction
    assert through[..., 66:].abs().max() > 0  # and reaches features the loss never scores
    assert all(p.grad is None for p in net.parameters())


def test_vanilla_guidance_reduces_penetration_with_one_network_call_per_step():
    actor, reactor, mask = _overlapping()
    blend = Blend(reactor, a=0.3)
    unguided = generate_reaction(parts(blend), actor, mask, steps=5, guidance=Guidance.off())
    assert blend.calls == 5
    guided = generate_reaction(
        parts(blend), actor, mask, steps=5, guidance=Guidance(mode="vanilla")
    )
    assert blend.calls == 10 and blend.a.grad is None and not guided.requires_grad
    # the Jacobian (0.3 I) damps the step: penetration falls, by less than the clean variant's
    assert _penetration(guided, actor) < 0.9 * _penetration(unguided, actor)
    # and it is not the clean-gradient variant's result
    clean = generate_reaction(
        parts(blend), actor, mask, steps=5, guidance=Guidance(mode="clean_gradient")
    )
    assert (guided - clean).abs().max() > 1e-3
    assert _penetration(clean, actor) < _penetration(guided, actor)
