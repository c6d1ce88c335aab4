"""Left/right mirroring: the 6D sign rule, geometric consistency, involution, feature commutation."""

from __future__ import annotations

import pytest
import torch
from motion_builders import SkeletonMotion, build_motion, random_motion

from intermask.motion.interhuman import (
    CONTACTS,
    RAW_MIRROR_PERMUTATION,
    RAW_ROTATION_MIRROR_PERMUTATION,
    interaction_features,
    mirror_features,
    mirror_raw,
    person_features,
    zup_to_yup,
)
from intermask.motion.kinematics import forward_kinematics
from intermask.motion.mirror import (
    ROT6D_NEGATED,
    ROTATION_MIRROR_PERMUTATION,
    mirror_joint_positions,
    mirror_matrix,
    mirror_rot6d,
    reflect_lateral,
)
from intermask.motion.rotations import axis_angle_to_matrix, matrix_to_rot6d, rotation_about_axis
from intermask.motion.skeleton import MIRROR_PERMUTATION, REST_OFFSETS

M = torch.diag(torch.tensor([-1.0, 1.0, 1.0], dtype=torch.float64))


def geometric_mirror(motion: SkeletonMotion, generator: torch.Generator) -> SkeletonMotion:
    """Mirror a skeleton through x = 0 by rebuilding it with FK from mirrored rotations.

    Local rotations L'[j] = M L[swap(j)] M for every joint including the root, root at M root.
    """
    swapped = motion.local_rotations[:, list(MIRROR_PERMUTATION)]
    return build_motion(M @ swapped @ M, motion.root_position @ M, generator)


@pytest.mark.parametrize("layout", ["rows", "columns"])
def test_mirror_rot6d_is_the_6d_of_m_r_m(layout: str) -> None:
    rotations = axis_angle_to_matrix(torch.randn(50, 3, dtype=torch.float64))
    expected = matrix_to_rot6d(M @ rotations @ M, layout=layout)
    torch.testing.assert_close(
        mirror_rot6d(matrix_to_rot6d(rotations, layout=layout), layout=layout), expected
    )
    torch.testing.assert_close(mirror_matrix(rotations), M @ rotations @ M)


def test_rows_layout_negates_components_1_2_4() -> None:
    assert ROT6D_NEGATED["rows"] == (1, 2, 4)
    rot6d = torch.arange(1.0, 7.0)
    torch.testing.assert_close(mirror_rot6d(rot6d), torch.tensor([1.0, -2.0, -3.0, 4.0, -5.0, 6.0]))


def test_lateral_axis_is_x_in_both_raw_and_yup_frames() -> None:
    vectors = torch.randn(10, 3)
    torch.testing.assert_close(
        zup_to_yup(reflect_lateral(vectors)), reflect_lateral(zup_to_yup(vectors))
    )


def test_fk_of_mirrored_rotations_is_the_mirrored_skeleton() -> None:
    """The M R M rule (with the symmetric rest offsets) reproduces the reflected joint positions."""
    motion = random_motion(torch.Generator().manual_seed(0), frames=5)
    local = M @ motion.local_rotations[:, list(MIRROR_PERMUTATION)] @ M
    positions = forward_kinematics(local, motion.root_position @ M, REST_OFFSETS.double()).positions
    torch.testing.assert_close(positions, mirror_joint_positions(motion.positions))
    assert torch.allclose(torch.linalg.det(local), torch.ones(5, 22, dtype=torch.float64))


def test_mirrored_features_equal_features_of_the_mirrored_skeleton() -> None:
    generator = torch.Generator().manual_seed(1)
    motion = random_motion(generator, frames=14)
    mirrored = geometric_mirror(motion, generator)
    expected = person_features(mirrored.raw).features
    torch.testing.assert_close(person_features(motion.raw, mirror=True).features, expected)
    torch.testing.assert_close(person_features(mirror_raw(motion.raw)).features, expected)
    torch.testing.assert_close(mirror_raw(motion.raw)[:, :66], mirrored.raw[:, :66])
    torch.testing.assert_close(mirror_raw(motion.raw)[:, 186:312], mirrored.raw[:, 186:312])


def test_mirror_commutes_with_the_feature_computation() -> None:
    motion = random_motion(torch.Generator().manual_seed(2), frames=10)
    features = person_features(motion.raw).features
    torch.testing.assert_close(
        person_features(motion.raw, mirror=True).features, mirror_features(features)
    )


def test_mirror_commutes_with_the_two_person_relation() -> None:
    generator = torch.Generator().manual_seed(3)
    one, two = random_motion(generator, frames=9), random_motion(generator, frames=9)
    features = interaction_features(one.raw, two.raw)
    torch.testing.assert_close(
        interaction_features(one.raw, two.raw, mirror=True), mirror_features(features)
    )


def test_mirroring_twice_is_the_identity() -> None:
    motion = random_motion(torch.Generator().manual_seed(4), frames=6)
    torch.testing.assert_close(mirror_raw(mirror_raw(motion.raw)), motion.raw, rtol=0, atol=0)
    features = person_features(motion.raw).features
    torch.testing.assert_close(mirror_features(mirror_features(features)), features, rtol=0, atol=0)
    once = mirror_raw(motion.raw)
    assert not torch.allclose(once, motion.raw)


def test_contacts_change_sides() -> None:
    frames = 10
    local = torch.eye(3, dtype=torch.float64).repeat(frames, 22, 1, 1)
    local[:, 2] = rotation_about_axis(
        -0.06 * torch.arange(frames, dtype=torch.float64), "x"
    )  # right leg swings
    root = torch.tensor([0.0, 0.95, 0.0], dtype=torch.float64).repeat(frames, 1)
    motion = build_motion(local, root, torch.Generator().manual_seed(5))
    contacts = person_features(motion.raw).features[:, CONTACTS]
    mirrored = person_features(motion.raw, mirror=True).features[:, CONTACTS]
    assert contacts[:, :2].min() == 1 and contacts[:, 2:].max() == 0
    torch.testing.assert_close(mirrored, contacts[:, [2, 3, 0, 1]])


def test_permutations_swap_sides_and_are_involutions() -> None:
    for permutation in (
        MIRROR_PERMUTATION,
        ROTATION_MIRROR_PERMUTATION,
        RAW_MIRROR_PERMUTATION,
        RAW_ROTATION_MIRROR_PERMUTATION,
    ):
        assert sorted(permutation) == list(range(len(permutation)))
        assert all(permutation[permutation[j]] == j for j in range(len(permutation)))
    assert ROTATION_MIRROR_PERMUTATION[0] == 1  # rotation of joint 1 (l_hip) <-> joint 2 (r_hip)
    assert RAW_MIRROR_PERMUTATION[22:37] == tuple(range(37, 52))  # left hand <-> right hand
    assert RAW_MIRROR_PERMUTATION[52:57] == tuple(range(57, 62))  # left tips <-> right tips
    assert RAW_MIRROR_PERMUTATION[:22] == MIRROR_PERMUTATION


def test_shape_errors() -> None:
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 6\), got \(4, 5\)"):
        mirror_rot6d(torch.zeros(4, 5))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 22, 3\), got \(3, 21, 3\)"):
        mirror_joint_positions(torch.zeros(3, 21, 3))
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 492\), got \(3, 491\)"):
        mirror_raw(torch.zeros(3, 491))
    with pytest.raises(ValueError, match="unknown 6D layout"):
        mirror_rot6d(torch.zeros(6), layout="diagonal")  # type: ignore[arg-type]
