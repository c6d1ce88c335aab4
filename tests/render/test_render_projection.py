import numpy as np
import pytest
import torch

from intermask.motion.skeleton import rest_pose_positions
from intermask.render.projection import (
    VIEWS,
    Camera,
    clip_segment,
    place_camera,
    prepare_joints,
    project,
    resolve_views,
    scene_of,
)


def two_people(gap: float = 1.5, frames: int = 3) -> np.ndarray:
    """(T, 2, 22, 3): two rest poses on the floor, person 2 at +x, facing each other's side."""
    rest = rest_pose_positions().double().numpy()
    rest = rest - np.array([0.0, rest[:, 1].min(), 0.0])
    pair = np.stack((rest, rest + np.array([gap, 0.0, 0.0])))
    return np.broadcast_to(pair, (frames, *pair.shape)).copy()


def test_prepare_joints_accepts_torch_single_person_and_converts_z_up():
    joints = torch.randn(5, 22, 3)
    prepared = prepare_joints(joints)
    assert prepared.shape == (5, 1, 22, 3) and prepared.dtype == np.float64
    z_up = prepare_joints(joints, up_axis="z")
    x, y, z = joints.double().numpy().transpose(2, 0, 1)
    np.testing.assert_allclose(z_up[:, 0], np.stack((x, z, -y), axis=-1))


@pytest.mark.parametrize(
    ("joints", "kwargs", "message"),
    [
        (
            np.zeros((4, 2, 21, 3)),
            {},
            r"expected shape \(T, P, 22, 3\) or \(T, 22, 3\), got \(4, 2, 21, 3\)",
        ),
        (np.zeros((0, 2, 22, 3)), {}, "at least one frame"),
        (
            np.full((2, 22, 3), np.nan),
            {},
            r"non-finite value at \(frame, person, joint, axis\) \(0, 0, 0, 0\)",
        ),
        (np.zeros((2, 22, 3)), {"up_axis": "x"}, "up_axis must be 'y' or 'z', got 'x'"),
    ],
)
def test_prepare_joints_rejects_bad_input(joints, kwargs, message):
    with pytest.raises(ValueError, match=message):
        prepare_joints(joints, **kwargs)


def test_resolve_views_names_cameras_and_errors():
    custom = Camera(azimuth_deg=30.0, elevation_deg=10.0)
    resolved = resolve_views(["side", custom])
    assert resolved[0] == ("side", VIEWS["side"]) and resolved[1] == ("az 30 el 10", custom)
    with pytest.raises(ValueError, match="unknown view 'front'; expected a Camera or one of side"):
        resolve_views("front")
    with pytest.raises(ValueError, match="empty sequence"):
        resolve_views([])
    with pytest.raises(ValueError, match=r"elevation_deg must be in \[-89.9, 89.9\], got 90"):
        Camera(elevation_deg=90)


@pytest.mark.parametrize("heading", [0.0, 1.0, 2.5, -2.0])
def test_side_view_shows_person_one_left_of_person_two_for_any_heading(heading):
    joints = two_people()
    rotation = np.array(
        [[np.cos(heading), 0, np.sin(heading)], [0, 1, 0], [-np.sin(heading), 0, np.cos(heading)]]
    )
    joints = joints @ rotation.T + np.array([3.0, 0.0, -2.0])
    scene = scene_of(joints)
    pose = place_camera(VIEWS["side"], scene, (480, 360))
    pixels, depth = project(pose, joints[0, :, 0])
    assert pixels[0, 0] < 240 < pixels[1, 0]  # person 1 left of centre, person 2 right
    assert (depth > 0).all() and abs(depth[0] - depth[1]) < 1e-6  # side on: equal depths
    every_joint, _ = project(pose, joints)
    assert (every_joint >= 0).all() and (every_joint[..., 0] <= 480).all()
    assert (every_joint[..., 1] <= 360).all()  # the framing keeps every joint in the picture


def test_scene_floor_and_single_person_axis():
    joints = two_people()[:, :1] + np.array([0.0, 0.3, 0.0])
    scene = scene_of(joints)
    assert scene.floor == pytest.approx(0.3)
    np.testing.assert_allclose(scene.pair_axis, [-1.0, 0.0, 0.0], atol=1e-9)  # r_hip - l_hip


def test_clip_segment_cuts_at_the_near_plane():
    scene = scene_of(two_people())
    pose = place_camera(VIEWS["side"], scene, (200, 100))
    behind = pose.eye - 2.0 * pose.basis[2]
    assert clip_segment(pose, behind, behind + 0.1 * pose.basis[0]) is None
    ahead = pose.eye + 3.0 * pose.basis[2]
    segment = clip_segment(pose, behind, ahead)
    assert segment is not None and np.isfinite(segment).all()
    np.testing.assert_allclose(segment[1], project(pose, ahead)[0])
