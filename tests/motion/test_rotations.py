import math

import pytest
import torch

from intermask.motion import rotations as rot


@pytest.fixture
def random_matrices() -> torch.Tensor:
    generator = torch.Generator().manual_seed(0)
    return rot.axis_angle_to_matrix(
        torch.randn(256, 3, generator=generator, dtype=torch.float64) * 1.5
    )


def test_matrices_are_proper_rotations(random_matrices):
    identity = torch.eye(3, dtype=torch.float64)
    torch.testing.assert_close(
        random_matrices @ random_matrices.transpose(-1, -2), identity.expand_as(random_matrices)
    )
    torch.testing.assert_close(
        torch.linalg.det(random_matrices), torch.ones(256, dtype=torch.float64)
    )


@pytest.mark.parametrize("layout", ["rows", "columns"])
def test_rot6d_round_trip(random_matrices, layout):
    torch.testing.assert_close(
        rot.rot6d_to_matrix(rot.matrix_to_rot6d(random_matrices, layout), layout), random_matrices
    )


def test_rot6d_rows_layout_is_first_two_columns_written_row_by_row():
    matrix = torch.arange(9.0).reshape(3, 3)
    # [R00, R01, R10, R11, R20, R21], the layout of the InterHuman release
    assert rot.matrix_to_rot6d(matrix).tolist() == [0.0, 1.0, 3.0, 4.0, 6.0, 7.0]
    assert rot.matrix_to_rot6d(matrix, "columns").tolist() == [0.0, 3.0, 6.0, 1.0, 4.0, 7.0]


def test_rot6d_layouts_differ_on_the_same_numbers(random_matrices):
    as_rows = rot.matrix_to_rot6d(random_matrices, "rows")
    misread = rot.rot6d_to_matrix(as_rows, "columns")
    assert (misread - random_matrices).abs().amax() > 0.1


def test_rot6d_projects_any_input_to_a_rotation():
    matrices = rot.rot6d_to_matrix(torch.randn(64, 6, dtype=torch.float64))
    torch.testing.assert_close(torch.linalg.det(matrices), torch.ones(64, dtype=torch.float64))


def test_axis_angle_and_quaternion_round_trips(random_matrices):
    torch.testing.assert_close(
        rot.axis_angle_to_matrix(rot.matrix_to_axis_angle(random_matrices)), random_matrices
    )
    torch.testing.assert_close(
        rot.quaternion_to_matrix(rot.matrix_to_quaternion(random_matrices)), random_matrices
    )
    axis_angle = torch.tensor([[0.3, -0.2, 0.1], [0.0, 0.0, 3.0]], dtype=torch.float64)
    torch.testing.assert_close(
        rot.quaternion_to_axis_angle(rot.axis_angle_to_quaternion(axis_angle)), axis_angle
    )


def test_small_angles_are_finite_with_gradients():
    axis_angle = torch.tensor(
        [[1e-9, 0.0, 0.0], [0.0, 0.0, 0.0]], dtype=torch.float64, requires_grad=True
    )
    matrix = rot.axis_angle_to_matrix(axis_angle)
    matrix.sum().backward()
    assert torch.isfinite(axis_angle.grad).all()
    torch.testing.assert_close(rot.matrix_to_axis_angle(matrix.detach()), axis_angle.detach())


def test_rotation_about_axis_is_right_handed():
    quarter = rot.rotation_about_axis(torch.tensor(math.pi / 2), "z")
    torch.testing.assert_close(
        quarter @ torch.tensor([1.0, 0.0, 0.0]), torch.tensor([0.0, 1.0, 0.0])
    )
    quarter_y = rot.rotation_about_axis(torch.tensor(math.pi / 2), "y")
    torch.testing.assert_close(
        quarter_y @ torch.tensor([0.0, 0.0, 1.0]), torch.tensor([1.0, 0.0, 0.0])
    )


def test_quaternion_product_matches_matrix_product(random_matrices):
    q1, q2 = (
        rot.matrix_to_quaternion(random_matrices[:128]),
        rot.matrix_to_quaternion(random_matrices[128:]),
    )
    product = rot.quaternion_to_matrix(rot.quaternion_multiply(q1, q2))
    torch.testing.assert_close(product, random_matrices[:128] @ random_matrices[128:])
    vectors = torch.randn(128, 3, dtype=torch.float64)
    torch.testing.assert_close(
        rot.quaternion_apply(q1, vectors), (random_matrices[:128] @ vectors[..., None])[..., 0]
    )
    identity = rot.quaternion_multiply(q1, rot.quaternion_inverse(q1))
    torch.testing.assert_close(
        identity, torch.tensor([1.0, 0, 0, 0], dtype=torch.float64).expand_as(identity)
    )


def test_geodesic_angle(random_matrices):
    angles = torch.tensor([0.0, 0.5, 2.0, 3.1], dtype=torch.float64)
    turned = random_matrices[:4] @ rot.rotation_about_axis(angles, "x")
    torch.testing.assert_close(rot.geodesic_angle(random_matrices[:4], turned), angles)


def test_shape_errors_name_the_shape():
    with pytest.raises(
        ValueError, match=r"rot6d_to_matrix: expected shape \(\.\.\., 6\), got \(4, 5\)"
    ):
        rot.rot6d_to_matrix(torch.zeros(4, 5))
    with pytest.raises(ValueError, match="unknown 6D layout 'cols'"):
        rot.matrix_to_rot6d(torch.eye(3), "cols")
    with pytest.raises(ValueError, match="unknown axis 'w'"):
        rot.rotation_about_axis(torch.tensor(0.0), "w")
