"""Per-person InterHuman processing: axis change, canonical frame, foot contacts, the 262-d feature."""

from __future__ import annotations

import math

import pytest
import torch
from motion_builders import YUP_TO_ZUP

from intermask.motion.interhuman import (
    CONTACTS,
    FEATURE_DIM,
    POSITIONS,
    ROTATIONS,
    VELOCITIES,
    canonicalize_person,
    facing_rotation,
    foot_contacts,
    person_features,
    select_body,
    split_features,
    yup_to_zup,
    zup_to_yup,
)
from intermask.motion.rotations import rotation_about_axis
from intermask.motion.skeleton import REST_OFFSETS, rest_pose_positions

UP = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)


def forward_of(joints: torch.Tensor) -> torch.Tensor:
    """normalize(cross(up, r_hip - l_hip)) for (22, 3) Y-up joints, written out independently."""
    forward = torch.linalg.cross(UP, joints[2] - joints[1])
    return forward / forward.norm()


def test_feature_layout_constants() -> None:
    sizes = [s.stop - s.start for s in (POSITIONS, VELOCITIES, ROTATIONS, CONTACTS)]
    assert sizes == [66, 66, 126, 4]
    assert CONTACTS.stop == FEATURE_DIM == 262


def test_axis_change_matches_the_reference_matrix_and_round_trips() -> None:
    vectors = torch.randn(5, 7, 3, dtype=torch.float64)
    reference = torch.tensor(
        [[1.0, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=torch.float64
    )  # InterGen trans_matrix
    torch.testing.assert_close(zup_to_yup(vectors), vectors @ reference.T)
    torch.testing.assert_close(yup_to_zup(vectors), vectors @ YUP_TO_ZUP.T)
    torch.testing.assert_close(yup_to_zup(zup_to_yup(vectors)), vectors)
    assert torch.linalg.det(reference) == pytest.approx(1.0)  # a rotation, not a reflection


def test_select_body_reads_the_documented_columns(make_motion) -> None:
    motion = make_motion(frames=6)
    body = select_body(motion.raw)
    torch.testing.assert_close(body.positions, motion.positions @ YUP_TO_ZUP.T)
    torch.testing.assert_close(body.rot6d[..., 0, :], motion.raw[:, 186:192])
    assert body.rot6d.shape == (6, 21, 6)


def test_canonical_frame_properties(make_motion) -> None:
    motion = make_motion(frames=30)
    canonical = canonicalize_person(motion.positions)
    positions = canonical.positions
    torch.testing.assert_close(positions[0, 0, [0, 2]], torch.zeros(2, dtype=torch.float64))
    assert positions[..., 1].min().item() == pytest.approx(0.0, abs=1e-12)
    torch.testing.assert_close(
        forward_of(positions[0]), torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    )
    # A rigid motion: canonical = facing (world - origin) with facing a proper rotation about y.
    facing = canonical.facing
    torch.testing.assert_close(facing @ facing.T, torch.eye(3, dtype=torch.float64))
    assert torch.linalg.det(facing).item() == pytest.approx(1.0)
    torch.testing.assert_close(facing @ UP, UP)
    torch.testing.assert_close(positions, (motion.positions - canonical.origin) @ facing.T)
    assert canonical.origin[1].item() == pytest.approx(motion.positions[..., 1].min().item())


@pytest.mark.parametrize("yaw", [0.0, math.pi / 2, math.pi, -math.pi / 2, 2.5])
def test_facing_rotation_turns_any_heading_to_plus_z(make_motion, yaw: float) -> None:
    joints = make_motion(frames=2, yaw=yaw).positions[0]
    facing = facing_rotation(joints)
    torch.testing.assert_close(
        facing @ forward_of(joints), torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    )


def test_rest_pose_faces_plus_z_already() -> None:
    facing = facing_rotation(rest_pose_positions())
    torch.testing.assert_close(facing, torch.eye(3))


def test_facing_rotation_rejects_vertical_hips() -> None:
    joints = torch.zeros(22, 3)
    joints[2, 1] = 1.0
    with pytest.raises(ValueError, match="hip vector r_hip - l_hip needs a horizontal component"):
        facing_rotation(joints)


def test_features_are_invariant_to_where_and_how_the_person_stands(make_motion) -> None:
    motion = make_motion(frames=20)
    turn = rotation_about_axis(torch.tensor(1.3, dtype=torch.float64), "y")
    moved = motion.positions @ turn.T + torch.tensor([3.0, 0.7, -2.0], dtype=torch.float64)
    raw_moved = motion.raw.clone()
    raw_moved[:, :66] = (moved @ YUP_TO_ZUP.T).reshape(20, 66)
    torch.testing.assert_close(
        person_features(raw_moved).features, person_features(motion.raw).features
    )


def test_features_positions_velocities_rotations(make_motion) -> None:
    motion = make_motion(frames=16)
    result = person_features(motion.raw)
    parts = split_features(result.features)
    canonical = canonicalize_person(motion.positions).positions
    assert result.features.shape == (15, FEATURE_DIM)
    torch.testing.assert_close(parts.positions, canonical[:-1])
    torch.testing.assert_close(parts.velocities, canonical[1:] - canonical[:-1])
    torch.testing.assert_close(parts.velocities[:-1], parts.positions[1:] - parts.positions[:-1])
    torch.testing.assert_close(result.features[:, ROTATIONS], motion.raw[:-1, 186:312])
    torch.testing.assert_close(parts.positions[0, 0, [0, 2]], torch.zeros(2, dtype=torch.float64))
    assert parts.positions[..., 1].min() >= -1e-12


def _swinging_right_leg(make_built_motion, frames: int = 12):
    """Pelvis still, left leg planted, right hip swinging forward by 0.06 rad per frame."""
    local = torch.eye(3, dtype=torch.float64).repeat(frames, 22, 1, 1)
    swing = -0.06 * torch.arange(
        frames, dtype=torch.float64
    )  # negative about x lifts the leg forward
    local[:, 2] = rotation_about_axis(swing, "x")
    pelvis_height = -rest_pose_positions(REST_OFFSETS.double())[:, 1].min()
    root = torch.tensor([0.5, 0.0, 0.2], dtype=torch.float64).repeat(frames, 1)
    root[:, 1] = pelvis_height
    return make_built_motion(local, root)


def test_foot_contacts_planted_and_moving_feet(make_built_motion) -> None:
    motion = _swinging_right_leg(make_built_motion)
    positions = canonicalize_person(motion.positions).positions
    contacts = foot_contacts(positions)
    assert contacts.shape == (11, 4)
    assert contacts.dtype == torch.float64
    torch.testing.assert_close(
        contacts[:, :2], torch.ones(11, 2, dtype=torch.float64)
    )  # left planted
    torch.testing.assert_close(
        contacts[:, 2:], torch.zeros(11, 2, dtype=torch.float64)
    )  # right swings
    features = person_features(motion.raw).features
    torch.testing.assert_close(features[:, CONTACTS], contacts)


def test_foot_contacts_thresholds() -> None:
    positions = torch.zeros(3, 22, 3)
    positions[:, [7, 8], 1] = 0.10  # ankles below 0.12
    positions[:, [10, 11], 1] = 0.04  # feet below 0.05
    positions[1:, 8, 0] = 0.04  # right ankle: squared step 0.0016 >= 0.001 between frames 0 and 1
    positions[:, 11, 1] = torch.tensor([0.04, 0.06, 0.04])  # right foot lifted at frame 1
    expected = torch.tensor([[1.0, 1.0, 0.0, 1.0], [1.0, 1.0, 1.0, 0.0]])
    torch.testing.assert_close(foot_contacts(positions), expected)
    # looser thresholds turn everything into contact
    torch.testing.assert_close(foot_contacts(positions, 0.01, (0.2, 0.2)), torch.ones(2, 4))


def test_batched_persons_equal_one_by_one(make_motion) -> None:
    raws = torch.stack([make_motion(frames=10).raw for _ in range(3)])  # (3, T, 492)
    batched = person_features(raws)
    for index in range(3):
        single = person_features(raws[index])
        torch.testing.assert_close(batched.features[index], single.features)
        torch.testing.assert_close(batched.facing[index], single.facing)
        torch.testing.assert_close(batched.origin[index], single.origin)


def test_float32_works_and_keeps_dtype(make_motion) -> None:
    raw = make_motion(frames=8).raw
    features32 = person_features(raw.float()).features
    assert features32.dtype == torch.float32
    torch.testing.assert_close(
        features32.double(), person_features(raw).features, atol=1e-5, rtol=1e-5
    )


def test_features_are_differentiable(make_motion) -> None:
    raw = make_motion(frames=6).raw.requires_grad_(True)
    person_features(raw).features[:, :132].square().sum().backward()
    assert raw.grad is not None and torch.isfinite(raw.grad).all()


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 492\), got \(10, 262\)"):
        person_features(torch.zeros(10, 262))
    with pytest.raises(ValueError, match=r"T >= 2"):
        person_features(torch.zeros(1, 492))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 22, 3\), got \(5, 21, 3\)"):
        canonicalize_person(torch.zeros(5, 21, 3))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 3\), got \(4, 2\)"):
        zup_to_yup(torch.zeros(4, 2))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 22, 3\)"):
        foot_contacts(torch.zeros(5, 22, 2))
