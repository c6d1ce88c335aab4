"""Inter-X: person split, 56x6 representation and its inverse, joint positions, the (B, T, P, J, 3) helper."""

from __future__ import annotations

import math

import pytest
import torch
from motion_builders import YUP_TO_ZUP

from intermask.motion.interx import (
    interhuman_joint_positions,
    interx_joint_positions,
    interx_positions,
    person_representation,
    representation_to_axis_angle,
    split_persons,
    to_joint_positions,
)
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.rotations import axis_angle_to_matrix, matrix_to_rot6d, rot6d_to_matrix
from intermask.motion.skeleton import REST_OFFSETS, rest_pose_positions


def random_rows(frames: int, seed: int = 0) -> torch.Tensor:
    """(T, 56, 3) axis-angle rows with angles in (0, pi) and a translation row."""
    generator = torch.Generator().manual_seed(seed)
    axes = torch.nn.functional.normalize(
        torch.randn(frames, 55, 3, generator=generator, dtype=torch.float64), dim=-1
    )
    angles = 0.1 + 2.9 * torch.rand(frames, 55, 1, generator=generator, dtype=torch.float64)
    translation = torch.randn(frames, 1, 3, generator=generator, dtype=torch.float64)
    return torch.cat((axes * angles, translation), dim=1)


def standing_rows(frames: int) -> torch.Tensor:
    """Identity body rows in a Z-up world: global orient = +90 degrees about x (body y -> world z)."""
    rows = torch.zeros(frames, 56, 3, dtype=torch.float64)
    rows[:, 0, 0] = math.pi / 2
    return rows


def test_split_persons() -> None:
    raw = torch.arange(4 * 56 * 6, dtype=torch.float32).reshape(4, 56, 6)
    persons = split_persons(raw)
    assert persons.shape == (4, 2, 56, 3)
    torch.testing.assert_close(persons[:, 0], raw[..., :3])
    torch.testing.assert_close(persons[:, 1], raw[..., 3:])


def test_representation_values() -> None:
    rows = random_rows(6)
    representation = person_representation(rows)
    assert representation.shape == (6, 56, 6)
    expected_rot6d = matrix_to_rot6d(axis_angle_to_matrix(rows[:, :55]))
    torch.testing.assert_close(representation[:, :55], expected_rot6d)
    # "rows" layout: the first two columns of R written row by row
    matrix = axis_angle_to_matrix(rows[2, 7])
    torch.testing.assert_close(representation[2, 7], matrix[:, :2].reshape(6))
    torch.testing.assert_close(representation[:, 55, :3], rows[:, 55])
    torch.testing.assert_close(representation[:-1, 55, 3:], rows[1:, 55] - rows[:-1, 55])
    torch.testing.assert_close(representation[-1, 55, 3:], torch.zeros(3, dtype=torch.float64))


def test_round_trip_to_axis_angle() -> None:
    rows = random_rows(8, seed=1)
    back = representation_to_axis_angle(person_representation(rows))
    torch.testing.assert_close(back, rows, atol=1e-9, rtol=1e-9)


def test_batched_representation() -> None:
    rows = torch.stack([random_rows(5, seed=s) for s in (2, 3)])  # (B, T, 56, 3)
    batched = person_representation(rows)
    torch.testing.assert_close(batched[1], person_representation(rows[1]))


def test_standing_person_is_the_rest_pose_at_the_translation() -> None:
    rows = standing_rows(3)
    rows[:, 55] = torch.tensor(
        [[0.5, -1.0, 0.9], [0.6, -1.0, 0.9], [0.7, -1.0, 0.9]], dtype=torch.float64
    )
    positions = interx_positions(person_representation(rows))
    translation_yup = torch.tensor([0.5, 0.9, 1.0], dtype=torch.float64)  # (x, z, -y)
    expected = rest_pose_positions(REST_OFFSETS.double()) + translation_yup
    torch.testing.assert_close(positions[0], expected)
    torch.testing.assert_close(
        positions[2, :, 0] - positions[0, :, 0], torch.full((22,), 0.2, dtype=torch.float64)
    )


def test_known_elbow_bend() -> None:
    """l_elbow turned 90 degrees about z: the forearm offset (x, y, z) becomes (-y, x, z)."""
    rows = torch.zeros(1, 56, 3, dtype=torch.float64)
    rows[0, 18, 2] = math.pi / 2  # row 18 = joint 18 (l_elbow)
    positions = interx_positions(person_representation(rows), up_axis="y")[0]
    offset = REST_OFFSETS.double()[20]
    torch.testing.assert_close(
        positions[20] - positions[18], torch.stack((-offset[1], offset[0], offset[2]))
    )
    rest = rest_pose_positions(REST_OFFSETS.double())
    torch.testing.assert_close(positions[:20], rest[:20])


def test_positions_match_fk_in_the_raw_frame() -> None:
    rows = random_rows(4, seed=4)
    offsets = REST_OFFSETS.double() * 1.1
    positions = interx_positions(person_representation(rows), offsets=offsets)
    raw_positions = forward_kinematics(
        axis_angle_to_matrix(rows[:, :22]), rows[:, 55], offsets
    ).positions
    torch.testing.assert_close(positions @ YUP_TO_ZUP.T, raw_positions)


def test_joint_positions_helper_layouts() -> None:
    rows = torch.stack([standing_rows(5), random_rows(5, seed=5)])  # (P, T, 56, 3)
    representation = person_representation(rows)[None].expand(3, -1, -1, -1, -1)  # (B, P, T, 56, 6)
    joints = to_joint_positions(representation, "interx")
    assert joints.shape == (3, 5, 2, 22, 3)
    torch.testing.assert_close(joints[1, :, 1], interx_positions(representation[1, 1]))
    torch.testing.assert_close(joints, interx_joint_positions(representation))

    features = torch.randn(3, 2, 7, 262)
    joints = to_joint_positions(features, "interhuman")
    assert joints.shape == (3, 7, 2, 22, 3)
    torch.testing.assert_close(joints[2, 4, 1], features[2, 1, 4, :66].reshape(22, 3))
    torch.testing.assert_close(joints, interhuman_joint_positions(features))


def test_rotations_are_proper() -> None:
    representation = person_representation(random_rows(3, seed=6))
    matrices = rot6d_to_matrix(representation[:, :55])
    torch.testing.assert_close(torch.linalg.det(matrices), torch.ones(3, 55, dtype=torch.float64))


def test_errors() -> None:
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 56, 6\), got \(4, 56, 3\)"):
        split_persons(torch.zeros(4, 56, 3))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 56, 3\), got \(4, 55, 3\)"):
        person_representation(torch.zeros(4, 55, 3))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 56, 6\), got \(4, 56, 3\)"):
        interx_positions(torch.zeros(4, 56, 3))
    with pytest.raises(ValueError, match="up_axis must be 'y' or 'z', got 'x'"):
        interx_positions(torch.zeros(4, 56, 6), up_axis="x")  # type: ignore[arg-type]
    with pytest.raises(
        ValueError, match=r"representation must be one of \('interhuman', 'interx'\), got"
    ):
        to_joint_positions(torch.zeros(1, 2, 4, 262), "amass")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"expected \(\.\.\., P, T, 262\), got \(4, 262\)"):
        interhuman_joint_positions(torch.zeros(4, 262))
