"""The differentiable penetration loss pushes overlapping bodies apart and leaves the actor alone."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from physics_builders import facing_pair, point_segment_distance

from intermask.motion.skeleton import BONES
from intermask.physics import (
    body_capsules,
    bone_sample_points,
    intersection_volume,
    penetration_loss,
    signed_distance,
)


def test_bone_points_are_joints_then_evenly_spaced_bone_points():
    joints = torch.randn(3, 22, 3, dtype=torch.float64)
    points = bone_sample_points(joints, points_per_bone=3)
    assert points.shape == (3, 22 + 21 * 3, 3)
    assert torch.equal(points[:, :22], joints)
    parent, child = BONES[4]
    expected = joints[:, parent] + 0.5 * (joints[:, child] - joints[:, parent])
    np.testing.assert_allclose(points[:, 22 + 4 * 3 + 1].numpy(), expected.numpy(), atol=1e-12)
    assert bone_sample_points(joints, points_per_bone=0).shape == (3, 22, 3)


def test_loss_is_relu_of_zeta_minus_distance_against_numpy():
    actor, reactor = facing_pair(0.3, frames=2)
    reactor = (
        reactor
        + torch.tensor([0.0, 0.0, -0.1], dtype=torch.float64) * torch.arange(2.0)[:, None, None]
    )
    caps = [tuple(x.numpy() for x in body_capsules(actor[f])) for f in range(2)]
    expected = np.mean(
        [
            np.maximum(
                0.2 - (point_segment_distance(reactor[f].numpy(), a, b, samples=2001) - r).min(-1),
                0.0,
            )
            for f, (a, b, r) in enumerate(caps)
        ]
    )
    got = penetration_loss(reactor, actor, zeta=0.2, points_per_bone=0)
    assert got.item() == pytest.approx(expected, abs=2e-4) and expected > 0


def test_gradient_steps_push_the_reactor_out_of_the_actor():
    actor, reactor = facing_pair(0.15, frames=2, dtype=torch.float32)
    reactor = reactor.clone().requires_grad_(True)
    start_gap = signed_distance(reactor.detach(), body_capsules(actor)).min()
    start_volume = intersection_volume(actor, reactor.detach(), pitch=0.02).sum()
    losses = []
    for _ in range(3):
        loss = penetration_loss(reactor, actor, zeta=0.05, reduction="sum")
        (grad,) = torch.autograd.grad(loss, reactor)
        with torch.no_grad():
            reactor -= 0.05 * grad
        losses.append(loss.item())
    end_gap = signed_distance(reactor.detach(), body_capsules(actor)).min()
    assert losses[0] > 0.5 and losses[-1] < 0.1 * losses[0]
    assert start_gap < 0 and end_gap > start_gap + 0.05
    assert intersection_volume(actor, reactor.detach(), pitch=0.02).sum() < 0.5 * start_volume


def test_only_the_reactor_gets_gradients_unless_asked():
    actor, reactor = facing_pair(0.2, frames=1, dtype=torch.float32)
    actor.requires_grad_(True)
    reactor.requires_grad_(True)
    penetration_loss(reactor, actor).backward()
    assert actor.grad is None and reactor.grad.abs().sum() > 0
    penetration_loss(reactor, actor, detach_actor=False).backward()
    assert actor.grad is not None and actor.grad.abs().sum() > 0


def test_far_apart_bodies_cost_nothing_and_masks_and_reductions_agree():
    actor, reactor = facing_pair(0.2, frames=4, dtype=torch.float32)
    reactor = reactor.clone()
    reactor[3] += 5.0
    assert penetration_loss(reactor[3:], actor[3:]).item() == 0.0
    batch_r, batch_a = reactor.reshape(2, 2, 22, 3), actor.reshape(2, 2, 22, 3)
    mask = torch.tensor([[True, False], [True, True]])
    masked = penetration_loss(batch_r, batch_a, frame_mask=mask)
    subset = penetration_loss(reactor[[0, 2, 3]], actor[[0, 2, 3]])
    assert masked.item() == pytest.approx(subset.item(), rel=1e-6)
    total = penetration_loss(batch_r, batch_a, frame_mask=mask, reduction="sum")
    assert total.item() == pytest.approx(masked.item() * 3 * (22 + 21 * 2), rel=1e-6)


def test_errors_name_the_problem():
    actor, reactor = facing_pair(0.2, frames=2, dtype=torch.float32)
    with pytest.raises(
        ValueError,
        match=r"must both be \(\.\.\., 22, 3\) of one shape, got \(1, 22, 3\) and \(2, 22, 3\)",
    ):
        penetration_loss(reactor[:1], actor)
    bad = reactor.clone()
    bad[0, 0, 0] = torch.inf
    with pytest.raises(
        ValueError, match="penetration_loss: reactor_joints contains 1 NaN or inf values"
    ):
        penetration_loss(bad, actor)
    with pytest.raises(ValueError, match="zeta must be >= 0 metres, got -0.1"):
        penetration_loss(reactor, actor, zeta=-0.1)
    with pytest.raises(ValueError, match="reduction must be 'mean' or 'sum', got 'max'"):
        penetration_loss(reactor, actor, reduction="max")
    with pytest.raises(ValueError, match=r"frame_mask must be a bool tensor of shape \(2,\)"):
        penetration_loss(reactor, actor, frame_mask=torch.ones(3, dtype=torch.bool))
    with pytest.raises(ValueError, match="points_per_bone must be >= 0, got -1"):
        penetration_loss(reactor, actor, points_per_bone=-1)


def test_autocast_and_half_inputs_keep_full_precision():
    actor, reactor = facing_pair(0.2, frames=2, dtype=torch.float32)
    expected = penetration_loss(reactor, actor)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        assert body_capsules(actor).a.dtype == torch.float32
        assert penetration_loss(reactor, actor).item() == pytest.approx(expected.item(), rel=1e-6)
    half = penetration_loss(reactor.bfloat16(), actor.bfloat16())
    assert half.dtype == torch.float32 and half.item() == pytest.approx(expected.item(), rel=0.05)
