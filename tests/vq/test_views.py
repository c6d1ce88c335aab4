"""The InterHuman view's root-relative switch: what the image holds, and that it inverts exactly."""

import pytest
import torch

from intermask.motion import humanml3d as hml
from intermask.motion import interhuman as ih
from intermask.vq.views import HumanML3DView, InterHumanView
from tests.data.test_humanml3d import turning_walk


def _view(relative: bool) -> InterHumanView:
    generator = torch.Generator().manual_seed(0)
    mean = torch.randn(ih.FEATURE_DIM, generator=generator)
    std = torch.rand(ih.FEATURE_DIM, generator=generator) + 0.1
    return InterHumanView(mean=mean, std=std, relative_positions=relative)


def _features() -> torch.Tensor:
    features = torch.randn(2, 8, ih.FEATURE_DIM, generator=torch.Generator().manual_seed(1))
    features[..., ih.CONTACTS] = 0.0  # the view does not carry contacts (0 = their mean)
    return features


def test_relative_positions_hold_each_joint_in_metres_from_the_root_horizontally():
    view, features = _view(True), _features()
    joints = view.to_joints(features)
    metres = view.denormalize(features)[..., ih.POSITIONS].unflatten(-1, (22, 3))
    for axis in (0, 2):  # x and z: metres from the root
        expected = metres[..., 1:, axis] - metres[..., :1, axis]
        torch.testing.assert_close(joints[..., 1:, axis], expected, rtol=0, atol=1e-5)
    plain = _view(False).to_joints(features)
    torch.testing.assert_close(joints[..., 0, :], plain[..., 0, :])  # the root stays as it was
    torch.testing.assert_close(joints[..., 1], plain[..., 1])  # heights stay normalized
    torch.testing.assert_close(joints[..., 3:], plain[..., 3:])  # velocities and rotations too


def test_relative_positions_invert_exactly_and_a_root_shift_moves_the_whole_body():
    view, features = _view(True), _features()
    torch.testing.assert_close(
        view.from_joints(view.to_joints(features)), features, atol=2e-6, rtol=0
    )
    joints = view.to_joints(features)
    shifted = joints.clone()
    shifted[..., 0, 0] += 0.5 / view.std[0]  # the root 0.5 m further along x (normalized units)
    before = view.geometry(view.from_joints(joints)).positions
    after = view.geometry(view.from_joints(shifted)).positions
    # every joint's x moved with the root; heights and z did not move
    torch.testing.assert_close(after[..., 0] - before[..., 0], torch.full_like(before[..., 0], 0.5))
    torch.testing.assert_close(after[..., 1:], before[..., 1:])


def test_humanml3d_view_is_one_row_of_263_channels_and_its_geometry_is_the_recovered_motion():
    motion = hml.features_from_positions(turning_walk(41))
    raw = motion.features.float()[None]  # (1, 40, 263)
    mean, std = raw[0].mean(0), raw[0].std(0) + 0.5
    view = HumanML3DView(mean=mean, std=std)
    normalized = (raw - mean) / std
    image = view.to_joints(normalized)
    assert image.shape == (1, 40, 1, 263)
    torch.testing.assert_close(view.from_joints(image), normalized)
    geometry = view.geometry(normalized)
    torch.testing.assert_close(geometry.positions[0], motion.joints.float(), atol=1e-5, rtol=0)
    torch.testing.assert_close(
        geometry.rot6d[0].flatten(-2), raw[0, :, hml.ROTATIONS], atol=1e-5, rtol=0
    )
    torch.testing.assert_close(geometry.contacts[0], raw[0, :, hml.FOOT_CONTACTS])
    assert bool(view.reconstruction_mask(torch.device("cpu")).all())
    with pytest.raises(
        ValueError, match=r"HumanML3DView statistics must have shape \(263,\), got \(262,\)"
    ):
        HumanML3DView(mean=torch.zeros(262), std=torch.ones(262))
