import numpy as np
import pytest
import torch
from body_builders import known_params

from intermask.body.amass import YUP_TO_ZUP, amass_arrays, read_amass, write_amass
from intermask.body.export import body_vertices
from intermask.body.fit import FitSettings, fit_bodies, pose_error_degrees, start_pose
from intermask.motion.interhuman import FeatureParts, join_features, yup_to_zup
from intermask.motion.interx import person_representation
from intermask.motion.rotations import matrix_to_axis_angle, matrix_to_rot6d


def interhuman_features(joints: torch.Tensor, rotations: torch.Tensor) -> torch.Tensor:
    """(P, T, 262): the positions and the local 6D rotations of joints 1..21 (velocities and
    contacts are not read by the fit)."""
    persons, frames = joints.shape[:2]
    return join_features(
        FeatureParts(
            joints,
            torch.zeros_like(joints),
            matrix_to_rot6d(rotations[:, :, 1:]),
            joints.new_zeros(persons, frames, 4),
        )
    )


@pytest.mark.parametrize("fixture", ["smplx_model", "smplh_model"])
def test_round_trip_finds_the_known_bodies(fixture, request):
    """Joints made from known parameters (a back-facing and a lying person) come back within
    5 mm mean joint error and 2 degrees of pose."""
    model = request.getfixturevalue(fixture)
    truth = known_params(30)
    joints = model.body_joints(truth.betas, truth.rotations, truth.transl)
    fit = fit_bodies(model, joints, interhuman_features(joints, truth.rotations))
    assert fit.error.mean() < 0.005 and fit.error.max() < 0.01
    angles = pose_error_degrees(fit.params.rotations, truth.rotations)
    assert angles.mean() < 2.0 and angles.max() < 5.0
    torch.testing.assert_close(fit.joints, joints, atol=0.01, rtol=0)


def test_positions_alone_are_fitted_by_inverse_kinematics(smplx_model):
    truth = known_params(20)
    joints = smplx_model.body_joints(truth.betas, truth.rotations, truth.transl)
    fit = fit_bodies(smplx_model, joints, None)
    assert fit.error.mean() < 0.005
    # the root and the joints with one child are seen by the positions (no twist about the bone)
    assert pose_error_degrees(fit.params.rotations[:, :, 0], truth.rotations[:, :, 0]).mean() < 2.0


def test_interx_start_is_its_own_rotations_turned_to_y_up(smplx_model):
    truth = known_params(6)
    joints = smplx_model.body_joints(truth.betas, truth.rotations, truth.transl)
    # the Inter-X release is Z up: the root orientation and translation turned, the rest local
    zup = truth.rotations.clone()
    zup[:, :, 0] = YUP_TO_ZUP @ truth.rotations[:, :, 0]
    rows = torch.cat((zup, torch.eye(3, dtype=torch.float64).expand(2, 6, 3, 3, 3), truth.hands), 2)
    axis_angle = torch.cat((matrix_to_axis_angle(rows), yup_to_zup(truth.transl)[:, :, None]), 2)
    features = person_representation(axis_angle)  # (P, T, 56, 6)
    start = start_pose(joints, features, smplx_model.body_offsets(truth.betas))
    torch.testing.assert_close(start.rotations, truth.rotations, atol=1e-9, rtol=0)
    torch.testing.assert_close(start.hands, truth.hands, atol=1e-9, rtol=0)


def test_fit_rejects_bad_joints(smplx_model):
    with pytest.raises(ValueError, match=r"joints must be \(P, T, 22, 3\), got \(2, 5, 24, 3\)"):
        fit_bodies(smplx_model, torch.zeros(2, 5, 24, 3))
    with pytest.raises(ValueError, match="joints contain NaN"):
        fit_bodies(smplx_model, torch.full((1, 3, 22, 3), float("nan")))
    with pytest.raises(ValueError, match="features of shape \\(1, 3, 100\\)"):
        fit_bodies(smplx_model, torch.zeros(1, 3, 22, 3), torch.zeros(1, 3, 100))
    with pytest.raises(ValueError, match="FitSettings: prior must be >= 0"):
        FitSettings(prior=-1.0)


@pytest.mark.parametrize("fixture", ["smplx_model", "smplh_model"])
def test_amass_files_are_z_up_and_read_back(fixture, request, tmp_path):
    model = request.getfixturevalue(fixture)
    truth = known_params(8)
    paths = write_amass(truth, model, tmp_path, fps=30.0)
    assert [p.name for p in paths] == ["body_person1.npz", "body_person2.npz"]
    with np.load(paths[0]) as archive:
        assert archive["poses"].shape == (8, 3 * model.num_joints)
        assert archive["trans"].shape == (8, 3) and archive["betas"].shape == (10,)
        assert str(archive["gender"]) == "neutral" and float(archive["mocap_framerate"]) == 30.0
        assert str(archive["surface_model_type"]) == model.kind
        np.testing.assert_array_equal(archive["root_orient"], archive["poses"][:, :3])
        np.testing.assert_array_equal(archive["pose_body"], archive["poses"][:, 3:66])
    # what a reader of the file computes (the body model on poses and trans) is our body in Z up
    arrays = amass_arrays(truth, model, 1, fps=30.0)
    from intermask.motion.rotations import axis_angle_to_matrix

    rotations = axis_angle_to_matrix(torch.from_numpy(arrays["poses"]).reshape(8, -1, 3))
    zup, _ = model.pose(
        torch.from_numpy(arrays["betas"])[None], rotations, torch.from_numpy(arrays["trans"])
    )
    yup = body_vertices(model, truth)[1]
    torch.testing.assert_close(zup, yup @ YUP_TO_ZUP.T, atol=1e-9, rtol=0)
    back, fps = read_amass(paths, model)
    assert fps == 30.0
    torch.testing.assert_close(
        body_vertices(model, back), body_vertices(model, truth), atol=1e-9, rtol=0
    )
