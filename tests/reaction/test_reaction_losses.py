"""Reconstruction and interaction losses (ARFlow eqs. 5-6)."""

from __future__ import annotations

import math

import pytest
import torch

from intermask.motion.rotations import rotation_about_axis
from intermask.motion.skeleton import rest_pose_positions
from intermask.reaction.losses import (
    interaction_loss,
    masked_mean,
    reconstruction_loss,
    relative_root_orientation,
    relative_root_translation,
    root_frames,
)


def _persons(batch: int = 2, frames: int = 5, seed: int = 0):
    generator = torch.Generator().manual_seed(seed)
    rest = rest_pose_positions()
    actor = rest + 0.02 * torch.randn(batch, frames, 22, 3, generator=generator)
    reactor = (
        rest
        + torch.tensor([0.3, 0.0, 1.2])
        + 0.02 * torch.randn(batch, frames, 22, 3, generator=generator)
    )
    return actor, reactor, torch.ones(batch, frames, dtype=torch.bool)


def test_interaction_loss_is_zero_for_identical_motion_and_positive_otherwise():
    actor, reactor, mask = _persons()
    same = interaction_loss(reactor, reactor.clone(), actor, mask)
    assert same.total == 0 and same.distance == 0 and same.orientation == 0
    moved = interaction_loss(reactor + torch.tensor([0.1, 0.0, 0.0]), reactor, actor, mask)
    assert moved.translation > 0 and moved.distance > 0 and moved.orientation < 1e-12
    turned = reactor @ rotation_about_axis(torch.tensor(0.5), "y").T
    assert interaction_loss(turned, reactor, actor, mask).orientation > 0


def test_relations_do_not_depend_on_the_world_frame():
    actor, reactor, _ = _persons(seed=1)
    rotation = rotation_about_axis(torch.tensor(1.1), "y")
    shift = torch.tensor([2.0, 0.0, -3.0])

    def world(x):
        return x @ rotation.T + shift

    torch.testing.assert_close(
        relative_root_translation(world(reactor), world(actor)),
        relative_root_translation(reactor, actor),
    )
    torch.testing.assert_close(
        relative_root_orientation(world(reactor), world(actor)),
        relative_root_orientation(reactor, actor),
    )


def test_root_frames_are_rotations_and_rest_pose_faces_forward():
    frames = root_frames(_persons()[0])
    identity = torch.eye(3).expand_as(frames)
    torch.testing.assert_close(frames.transpose(-1, -2) @ frames, identity, atol=1e-5, rtol=0)
    torch.testing.assert_close(torch.linalg.det(frames), torch.ones(frames.shape[:-2]))
    rest = root_frames(rest_pose_positions())
    forward = rest[:, 2]  # tilted with the spine, heading +Z
    assert abs(float(forward[0])) < 1e-6 and float(forward[2]) > 0.9


def test_padding_is_excluded_even_when_it_is_not_finite():
    actor, reactor, mask = _persons()
    mask[:, 3:] = False
    predicted = reactor.clone()
    predicted[:, 3:] = float("nan")
    predicted.requires_grad_(True)
    terms = interaction_loss(predicted, reactor, actor, mask)
    assert terms.total == 0
    terms.total.backward()
    assert torch.isfinite(predicted.grad[:, :3]).all()
    x1 = torch.randn(2, 5, 7)
    x1_hat = x1.clone()
    x1_hat[:, 3:] += 100.0
    assert reconstruction_loss(x1_hat, x1, mask) == 0
    x1_hat[:, 0] += 1.0
    assert reconstruction_loss(x1_hat, x1, mask).item() == pytest.approx(1.0 / 3.0)


def test_distances_of_coinciding_joints_have_finite_gradients():
    actor, _, mask = _persons()
    predicted = actor.clone().requires_grad_(True)
    interaction_loss(predicted, actor + 0.1, actor, mask).total.backward()
    assert torch.isfinite(predicted.grad).all()


def test_errors_name_the_shapes():
    actor, reactor, mask = _persons()
    with pytest.raises(ValueError, match=r"must all be \(B, T, 22, 3\)"):
        interaction_loss(reactor[..., :2], reactor, actor, mask)
    with pytest.raises(ValueError, match=r"disagree on \(B, T\)"):
        masked_mean(torch.zeros(2, 4, 3), mask)
    assert math.isclose(float(masked_mean(torch.ones(2, 5, 3), mask)), 1.0)
