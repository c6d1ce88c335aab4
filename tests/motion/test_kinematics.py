import math

import pytest
import torch

from intermask.motion import skeleton
from intermask.motion.kinematics import bone_lengths, forward_kinematics
from intermask.motion.rotations import axis_angle_to_matrix, rotation_about_axis


def test_rest_pose_faces_plus_z_with_left_at_plus_x():
    rest = skeleton.rest_pose_positions()
    l_hip, r_hip = rest[1], rest[2]
    assert l_hip[0] > 0 > r_hip[0]
    across = r_hip - l_hip
    forward = torch.linalg.cross(torch.tensor([0.0, 1.0, 0.0]), across)
    assert forward[2] > 0 and forward[0].abs() < 1e-6
    # feet are below the pelvis, the head above, the skeleton is 1.5-1.7 m tall to the head joint
    assert 1.4 < rest[15, 1] - rest[[10, 11], 1].min() < 1.7


def test_mirror_permutation_swaps_pairs_and_is_an_involution():
    permutation = torch.tensor(skeleton.MIRROR_PERMUTATION)
    assert (
        permutation[1] == 2
        and permutation[20] == 21
        and permutation[0] == 0
        and permutation[15] == 15
    )
    assert torch.equal(permutation[permutation], torch.arange(skeleton.NUM_JOINTS))
    rest = skeleton.rest_pose_positions()
    mirrored = rest[permutation] * torch.tensor([-1.0, 1.0, 1.0])
    torch.testing.assert_close(mirrored, rest)


def test_identity_pose_reproduces_rest_pose():
    identity = torch.eye(3).expand(skeleton.NUM_JOINTS, 3, 3)
    result = forward_kinematics(identity, torch.tensor([1.0, 2.0, 3.0]), skeleton.REST_OFFSETS)
    torch.testing.assert_close(
        result.positions, skeleton.rest_pose_positions() + torch.tensor([1.0, 2.0, 3.0])
    )


def test_root_rotation_turns_the_whole_body():
    yaw = rotation_about_axis(torch.tensor(math.pi / 2), "y")
    local = torch.eye(3).repeat(skeleton.NUM_JOINTS, 1, 1)
    local[0] = yaw
    positions = forward_kinematics(local, torch.zeros(3), skeleton.REST_OFFSETS).positions
    torch.testing.assert_close(positions, skeleton.rest_pose_positions() @ yaw.T)


def test_elbow_bend_moves_only_the_forearm():
    local = torch.eye(3).repeat(skeleton.NUM_JOINTS, 1, 1)
    local[18] = rotation_about_axis(torch.tensor(math.pi / 2), "y")  # bend the left elbow
    positions = forward_kinematics(local, torch.zeros(3), skeleton.REST_OFFSETS).positions
    rest = skeleton.rest_pose_positions()
    moved = (positions - rest).norm(dim=-1) > 1e-6
    assert moved.nonzero().flatten().tolist() == [20]  # the wrist, child of the elbow
    forearm = skeleton.REST_OFFSETS[20]
    expected_wrist = rest[18] + rotation_about_axis(torch.tensor(math.pi / 2), "y") @ forearm
    torch.testing.assert_close(positions[20], expected_wrist)


def test_bone_lengths_are_invariant_under_any_pose():
    generator = torch.Generator().manual_seed(1)
    local = axis_angle_to_matrix(torch.randn(4, 30, skeleton.NUM_JOINTS, 3, generator=generator))
    root = torch.randn(4, 30, 3, generator=generator)
    positions = forward_kinematics(local, root, skeleton.REST_OFFSETS).positions
    assert positions.shape == (4, 30, 22, 3)
    expected = skeleton.REST_OFFSETS[1:].norm(dim=-1)
    torch.testing.assert_close(bone_lengths(positions), expected.expand(4, 30, 21))


def test_wrong_shapes_are_rejected():
    with pytest.raises(
        ValueError, match=r"local_rotations: expected \(\.\.\., 22, 3, 3\), got \(21, 3, 3\)"
    ):
        forward_kinematics(torch.eye(3).repeat(21, 1, 1), torch.zeros(3), skeleton.REST_OFFSETS)
