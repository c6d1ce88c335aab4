"""Two-person relation: person 2 re-expressed in person 1's canonical frame."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from motion_builders import random_motion

from intermask.motion.interhuman import (
    canonicalize_person,
    interaction_features,
    person_features,
    split_features,
)


# --- an independent numpy port of InterGen's process_motion_np + rigid_transform (quaternions) ---
def _qmul(q: np.ndarray, r: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = q
    w2, x2, y2, z2 = r
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def _qinv(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    u = q[1:]
    t = 2 * np.cross(u, v)
    return v + q[0] * t + np.cross(u, t)


def _qbetween(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    q = np.concatenate([[np.sqrt((a @ a) * (b @ b)) + a @ b], np.cross(a, b)])
    return q / np.linalg.norm(q)


def _reference_process(raw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Canonical (T, 22, 3) positions, the facing quaternion and the frame-0 root xz."""
    trans = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])
    positions = np.einsum("mn,tjn->tjm", trans, raw[:, :66].reshape(-1, 22, 3))
    positions[:, :, 1] -= positions[:, :, 1].min()
    root_xz = positions[0, 0] * np.array([1.0, 0, 1])
    positions = positions - root_xz
    across = positions[0, 2] - positions[0, 1]
    forward = np.cross([0.0, 1, 0], across)
    quat = _qbetween(forward / np.linalg.norm(forward), np.array([0.0, 0, 1]))
    rotated = np.stack([[_qrot(quat, p) for p in frame] for frame in positions])
    return rotated, quat, root_xz


def _reference_person2(raw1: np.ndarray, raw2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Person 2's positions and velocities (T-1 frames) after InterGen's rigid_transform."""
    _, quat1, root1 = _reference_process(raw1)
    positions2, quat2, root2 = _reference_process(raw2)
    relative = _qmul(quat2, _qinv(quat1))
    angle = np.arctan2(relative[2], relative[0])
    xz = _qrot(quat1, root2 - root1)[[0, 2]]
    rotation = _qinv(np.array([np.cos(angle), 0.0, np.sin(angle), 0.0]))
    moved = np.stack([[_qrot(rotation, p) for p in frame] for frame in positions2])
    moved[..., [0, 2]] += xz
    velocities = np.stack(
        [[_qrot(rotation, v) for v in frame] for frame in positions2[1:] - positions2[:-1]]
    )
    return moved[:-1], velocities


def _pair(seed: int, frames: int = 12):
    generator = torch.Generator().manual_seed(seed)
    return random_motion(generator, frames=frames), random_motion(generator, frames=frames)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_person2_matches_the_reference_computation(seed: int) -> None:
    one, two = _pair(seed)
    features = interaction_features(one.raw, two.raw)
    parts = split_features(features[:, 1])
    positions, velocities = _reference_person2(one.raw.numpy(), two.raw.numpy())
    np.testing.assert_allclose(parts.positions.numpy(), positions, atol=1e-10)
    np.testing.assert_allclose(parts.velocities.numpy(), velocities, atol=1e-10)


def test_person1_is_person_features_and_person2_keeps_rotations_and_contacts() -> None:
    one, two = _pair(3)
    features = interaction_features(one.raw, two.raw)
    assert features.shape == (11, 2, 262)
    start = split_features(features[0, 0]).positions
    torch.testing.assert_close(start[0, [0, 2]], torch.zeros(2, dtype=torch.float64))
    across = start[2] - start[1]  # r_hip - l_hip points to -x when facing +z
    assert across[0] < 0 and abs(across[2].item()) < 1e-12
    torch.testing.assert_close(features[:, 0], person_features(one.raw).features)
    alone = split_features(person_features(two.raw).features)
    moved = split_features(features[:, 1])
    torch.testing.assert_close(moved.rot6d, alone.rot6d)
    torch.testing.assert_close(moved.contacts, alone.contacts)


def test_relation_preserves_the_world_geometry_between_persons() -> None:
    one, two = _pair(4, frames=10)
    parts1, parts2 = (split_features(f) for f in interaction_features(one.raw, two.raw).unbind(1))
    world1, world2 = one.positions[:-1], two.positions[:-1]

    # Horizontal distances between any joint of person 1 and any joint of person 2 are unchanged.
    def horizontal_distances(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        return torch.cdist(a[..., [0, 2]], b[..., [0, 2]])

    torch.testing.assert_close(
        horizontal_distances(parts1.positions, parts2.positions),
        horizontal_distances(world1, world2),
    )
    # Heights: each person stands on their own floor.
    floor2 = two.positions[..., 1].min()
    torch.testing.assert_close(parts2.positions[..., 1], world2[..., 1] - floor2)
    # Velocities stay the frame differences of the moved positions.
    torch.testing.assert_close(parts2.velocities[:-1], parts2.positions[1:] - parts2.positions[:-1])


def test_person2_equals_person1_transform_applied_to_person2_world() -> None:
    one, two = _pair(5, frames=8)
    canonical1 = canonicalize_person(one.positions)
    floored2 = two.positions - torch.stack(
        (canonical1.origin[0], two.positions[..., 1].min(), canonical1.origin[2])
    )
    expected = floored2 @ canonical1.facing.T
    moved = split_features(interaction_features(one.raw, two.raw)[:, 1]).positions
    torch.testing.assert_close(moved, expected[:-1])


def test_same_person_twice_gives_identical_rows() -> None:
    one, _ = _pair(6, frames=6)
    features = interaction_features(one.raw, one.raw)
    torch.testing.assert_close(features[:, 0], features[:, 1])


def test_batched_interactions_equal_one_by_one() -> None:
    pairs = [_pair(seed, frames=7) for seed in (7, 8)]
    raw1 = torch.stack([a.raw for a, _ in pairs])
    raw2 = torch.stack([b.raw for _, b in pairs])
    batched = interaction_features(raw1, raw2)
    assert batched.shape == (2, 6, 2, 262)
    for index, (a, b) in enumerate(pairs):
        torch.testing.assert_close(batched[index], interaction_features(a.raw, b.raw))


def test_persons_with_different_lengths_are_rejected() -> None:
    with pytest.raises(ValueError, match=r"same shape; got \(10, 492\) and \(9, 492\)"):
        interaction_features(torch.zeros(10, 492), torch.zeros(9, 492))
