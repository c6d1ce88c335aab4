"""The per-joint (22, 12) view, feature splitting and features -> joint positions."""

from __future__ import annotations

import pytest
import torch
from motion_builders import random_motion

from intermask.motion.interhuman import (
    CONTACTS,
    FeatureParts,
    canonicalize_person,
    features_to_joint_view,
    features_to_positions,
    join_features,
    joint_view_to_features,
    person_features,
    split_features,
)


def random_features(*shape: int) -> torch.Tensor:
    return torch.randn(*shape, 262, generator=torch.Generator().manual_seed(0))


def test_joint_view_layout() -> None:
    features = random_features(2, 5)
    view = features_to_joint_view(features)
    assert view.shape == (2, 5, 22, 12)
    torch.testing.assert_close(view[..., 0:3].reshape(2, 5, 66), features[..., 0:66])
    torch.testing.assert_close(view[..., 3:6].reshape(2, 5, 66), features[..., 66:132])
    torch.testing.assert_close(view[..., 1:, 6:].reshape(2, 5, 126), features[..., 132:258])
    torch.testing.assert_close(view[..., 0, 6:], torch.zeros(2, 5, 6))
    # joint 5 (r_knee): position, velocity, rotation of joint 5 = 6D block 4
    torch.testing.assert_close(view[1, 3, 5, :3], features[1, 3, 15:18])
    torch.testing.assert_close(view[1, 3, 5, 3:6], features[1, 3, 66 + 15 : 66 + 18])
    torch.testing.assert_close(view[1, 3, 5, 6:], features[1, 3, 132 + 24 : 132 + 30])


def test_joint_view_round_trip() -> None:
    features = random_features(3, 7)
    back = joint_view_to_features(features_to_joint_view(features))
    expected = features.clone()
    expected[..., CONTACTS] = 0.0
    torch.testing.assert_close(back, expected, rtol=0, atol=0)
    view = features_to_joint_view(features)
    torch.testing.assert_close(
        features_to_joint_view(joint_view_to_features(view)), view, rtol=0, atol=0
    )


def test_joint_view_drops_a_nonzero_root_rotation() -> None:
    view = torch.randn(4, 22, 12)
    back = features_to_joint_view(joint_view_to_features(view))
    torch.testing.assert_close(back[:, 1:], view[:, 1:])
    torch.testing.assert_close(back[:, 0, :6], view[:, 0, :6])
    torch.testing.assert_close(back[:, 0, 6:], torch.zeros(4, 6))


def test_split_and_join_are_inverse() -> None:
    features = random_features(4)
    parts = split_features(features)
    assert isinstance(parts, FeatureParts)
    assert [tuple(p.shape) for p in parts] == [(4, 22, 3), (4, 22, 3), (4, 21, 6), (4, 4)]
    torch.testing.assert_close(join_features(parts), features, rtol=0, atol=0)


def test_features_to_positions_recovers_canonical_joints() -> None:
    motion = random_motion(torch.Generator().manual_seed(1), frames=9)
    positions = features_to_positions(person_features(motion.raw).features)
    torch.testing.assert_close(positions, canonicalize_person(motion.positions).positions[:-1])


def test_joint_view_is_differentiable() -> None:
    features = random_features(2, 3).requires_grad_(True)
    joint_view_to_features(features_to_joint_view(features)).sum().backward()
    expected = torch.ones(2, 3, 262)
    expected[..., CONTACTS] = 0.0
    torch.testing.assert_close(features.grad, expected)


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 262\), got \(5, 263\)"):
        features_to_joint_view(torch.zeros(5, 263))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 22, 12\), got \(5, 22, 11\)"):
        joint_view_to_features(torch.zeros(5, 22, 11))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 262\), got \(66,\)"):
        features_to_positions(torch.zeros(66))
