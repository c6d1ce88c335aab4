import numpy as np
import pytest
import torch

from intermask.data.synthetic.writers import interhuman_raw, interx_raw
from intermask.motion.interhuman import interaction_features, split_features
from intermask.motion.interx import interx_joint_positions, person_representation, split_persons
from intermask.motion.rotations import rot6d_to_matrix
from intermask.motion.skeleton import JOINT_NAMES, PARENTS
from intermask.render.bvh import (
    BvhClip,
    bvh_joint_positions,
    euler_to_matrix,
    matrix_to_euler,
    read_bvh,
    write_bvh,
)
from intermask.render.bvh_export import (
    estimate_offsets,
    interhuman_bvh_clips,
    interx_bvh_clips,
    read_bvh_joints,
    root_rotation_from_joints,
    write_interaction_bvh,
)

ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
# Positions are written with 6 decimals (1 um) and angles with 6 decimals of a degree; the joint
# error of a round trip is a few um, so 0.1 mm leaves room without hiding a wrong axis or order.
ROUND_TRIP_TOLERANCE_M = 1e-4


def random_rotations(count: int, seed: int = 0) -> np.ndarray:
    q, _ = torch.linalg.qr(
        torch.randn(count, 3, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(seed))
    )
    return (q * torch.sign(torch.det(q))[:, None, None]).numpy()


@pytest.mark.parametrize("order", ORDERS)
def test_euler_angles_round_trip_every_order_including_gimbal_lock(order):
    rotations = random_rotations(200)
    np.testing.assert_allclose(
        euler_to_matrix(matrix_to_euler(rotations, order), order), rotations, atol=1e-12
    )
    locked = euler_to_matrix(np.array([[30.0, 90.0, 20.0], [-10.0, -90.0, 45.0]]), order)
    np.testing.assert_allclose(
        euler_to_matrix(matrix_to_euler(locked, order), order), locked, atol=1e-9
    )


def test_euler_order_is_applied_left_to_right():
    # ZXY: R = Rz(90) @ Rx(90): the x axis goes to y, the y axis first to z (by Rx) and stays there
    matrix = euler_to_matrix(np.array([90.0, 90.0, 0.0]), "ZXY")
    np.testing.assert_allclose(matrix @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(matrix @ [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], atol=1e-12)
    with pytest.raises(
        ValueError, match="Euler order must be one of XYZ, YZX, ZXY, XZY, YXZ, ZYX, got 'XXY'"
    ):
        matrix_to_euler(matrix, "XXY")


def clip_of(synth_clip, person: int) -> BvhClip:
    return BvhClip(
        names=JOINT_NAMES,
        parents=PARENTS,
        offsets=synth_clip.offsets[person].numpy(),
        root_positions=synth_clip.positions[person, :, 0].numpy(),
        rotations=synth_clip.local_rotations[person].numpy(),
        frame_time=1 / 30,
    )


@pytest.mark.parametrize(("order", "scale"), [("ZXY", 1.0), ("YXZ", 100.0)])
def test_write_read_round_trip_reproduces_the_generator_joints(synth_clip, tmp_path, order, scale):
    path = write_bvh(tmp_path / "p1.bvh", clip_of(synth_clip, 0), euler_order=order, scale=scale)
    text = path.read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis\n{\n\tOFFSET 0.000000 0.000000 0.000000\n")
    assert text.count("End Site") == 5  # head, both wrists, both feet
    assert f"Frames: {synth_clip.frames}\nFrame Time: 0.03333333\n" in text
    parsed = read_bvh(path, scale=scale)
    assert parsed.fps == pytest.approx(30.0) and parsed.frames == synth_clip.frames
    joints = read_bvh_joints(path, scale=scale)  # back in JOINT_NAMES order
    error = np.linalg.norm(joints - synth_clip.positions[0].numpy(), axis=-1)
    assert error.max() < ROUND_TRIP_TOLERANCE_M, error.max()


def test_angles_are_unwrapped_over_time(tmp_path):
    angles = np.linspace(0.0, 720.0, 50)  # two full turns about y
    rotations = np.broadcast_to(np.eye(3), (50, 22, 3, 3)).copy()
    rotations[:, 0] = euler_to_matrix(np.stack((0 * angles, 0 * angles, angles), -1), "ZXY")
    clip = BvhClip(JOINT_NAMES, PARENTS, np.ones((22, 3)) * 0.1, np.zeros((50, 3)), rotations, 0.05)
    rows = write_bvh(tmp_path / "spin.bvh", clip).read_text().split("Frame Time: 0.05000000\n")[1]
    yaw = np.array([float(row.split()[5]) for row in rows.strip().splitlines()])
    assert np.abs(np.diff(yaw)).max() < 20 and yaw[-1] - yaw[0] == pytest.approx(720.0, abs=1e-4)


def test_root_rotation_from_the_pelvis_children_is_exact_with_the_body_offsets(synth_clip):
    derived = root_rotation_from_joints(
        synth_clip.positions[1].numpy(), synth_clip.offsets[1].numpy()
    )
    np.testing.assert_allclose(derived, synth_clip.local_rotations[1, :, 0].numpy(), atol=1e-9)


def interhuman_features(synth_clip) -> torch.Tensor:
    raw = [torch.from_numpy(interhuman_raw(synth_clip, p)).double() for p in range(2)]
    return interaction_features(raw[0], raw[1]).permute(1, 0, 2)  # (2, T-1, 262)


def test_interhuman_features_round_trip_through_bvh_files_with_estimated_offsets(
    synth_clip, tmp_path
):
    features = interhuman_features(synth_clip)
    clips = interhuman_bvh_clips(features, fps=30)
    paths = write_interaction_bvh(tmp_path, clips, stem="sample")
    assert [p.name for p in paths] == ["sample_person1.bvh", "sample_person2.bvh"]
    positions = split_features(features).positions.numpy()
    for person, path in enumerate(paths):
        error = np.linalg.norm(read_bvh_joints(path) - positions[person], axis=-1)
        assert error.max() < ROUND_TRIP_TOLERANCE_M, (person, error.max())
    # the estimate recovers the body's bone lengths
    lengths = np.linalg.norm(clips[0].offsets[1:], axis=-1)
    np.testing.assert_allclose(
        lengths, np.linalg.norm(synth_clip.offsets[0, 1:].numpy(), axis=-1), atol=1e-5
    )


def test_estimated_offsets_match_the_generator_bodies(synth_clip):
    features = interhuman_features(synth_clip)
    parts = split_features(features[0])
    offsets = estimate_offsets(parts.positions.numpy(), rot6d_to_matrix(parts.rot6d).numpy())
    np.testing.assert_allclose(offsets[1:], synth_clip.offsets[0, 1:].numpy(), atol=1e-5)


def test_interx_representation_round_trip_through_bvh(synth_clip, tmp_path):
    release = torch.from_numpy(interx_raw(synth_clip)).double()  # (T, 56, 6) Z-up
    representation = person_representation(
        split_persons(release).permute(1, 0, 2, 3)
    )  # (2, T, 56, 6)
    expected = interx_joint_positions(representation).numpy()  # (T, 2, 22, 3) Y-up
    paths = write_interaction_bvh(tmp_path, interx_bvh_clips(representation, fps=30), stem="x")
    for person, path in enumerate(paths):
        error = np.linalg.norm(read_bvh_joints(path) - expected[:, person], axis=-1)
        assert error.max() < ROUND_TRIP_TOLERANCE_M, (person, error.max())


def test_input_errors_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match=r"expected \(P, T, 262\) or \(T, 262\), got \(4, 261\)"):
        interhuman_bvh_clips(np.zeros((4, 261)), fps=30)
    with pytest.raises(ValueError, match="fps must be > 0, got 0"):
        interhuman_bvh_clips(np.zeros((4, 262)), fps=0, offsets=np.ones((22, 3)))
    with pytest.raises(ValueError, match=r"expected \(P, T, 56, 6\) or \(T, 56, 6\)"):
        interx_bvh_clips(np.zeros((4, 55, 6)), fps=30)
    with pytest.raises(ValueError, match=r"rotations must be \(3, 22, 3, 3\), got \(3, 21, 3, 3\)"):
        BvhClip(
            JOINT_NAMES, PARENTS, np.zeros((22, 3)), np.zeros((3, 3)), np.zeros((3, 21, 3, 3)), 0.1
        )
    with pytest.raises(ValueError, match="joint names must be unique and free of whitespace"):
        BvhClip(
            ("a b",) + JOINT_NAMES[1:],
            PARENTS,
            np.zeros((22, 3)),
            np.zeros((1, 3)),
            np.zeros((1, 22, 3, 3)),
            0.1,
        )


def test_parser_reports_broken_files(synth_clip, tmp_path):
    good = write_bvh(tmp_path / "good.bvh", clip_of(synth_clip, 0)).read_text()
    truncated = tmp_path / "truncated.bvh"
    truncated.write_text(good[: len(good) - 40])
    with pytest.raises(
        ValueError,
        match=r"truncated\.bvh: expected 132 frames x 69 channels = 9108 numbers, got 910[0-9]",
    ):
        read_bvh(truncated)
    not_bvh = tmp_path / "notes.bvh"
    not_bvh.write_text("hello")
    with pytest.raises(ValueError, match=r"notes\.bvh: not a BVH file \(no MOTION section\)"):
        read_bvh(not_bvh)
    moving_joint = tmp_path / "moving.bvh"
    moving_joint.write_text(
        good.replace(
            "CHANNELS 3 Zrotation Xrotation Yrotation",
            "CHANNELS 3 Xposition Xrotation Yrotation",
            1,
        )
    )
    with pytest.raises(
        ValueError, match="position channels on the non-root joint 'l_hip' are not supported"
    ):
        read_bvh(moving_joint)
    renamed = tmp_path / "renamed.bvh"
    renamed.write_text(good.replace("JOINT head", "JOINT skull"))
    with pytest.raises(ValueError, match=r"renamed\.bvh: joints head are missing"):
        read_bvh_joints(renamed)
    assert bvh_joint_positions(read_bvh(tmp_path / "good.bvh")).shape == (132, 22, 3)
