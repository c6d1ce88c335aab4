"""BVH of single-person HumanML3D features: posed from recover_from_ric by positional IK."""

from pathlib import Path

import numpy as np
import pytest
import torch

from intermask.motion.humanml3d import features_from_positions, recover_from_ric
from intermask.motion.kinematics import bone_lengths
from intermask.motion.skeleton import JOINT_NAMES, PARENTS, REST_OFFSETS
from intermask.render import bvh_joint_positions, humanml3d_bvh_clips, read_bvh, write_bvh
from intermask.render.bvh_export import CHILDREN
from tests.data.test_humanml3d import turning_walk

# Files hold 6 decimals; a rigid body comes back within ~2.5 um, so 0.1 mm hides no wrong bone.
ROUND_TRIP_TOLERANCE_M = 1e-4


def round_trip(features: torch.Tensor, tmp_path: Path, **kwargs: object) -> np.ndarray:
    """Joint error (T, 22) of features -> BVH file -> read_bvh -> FK, against recover_from_ric."""
    (clip,) = humanml3d_bvh_clips(features, **kwargs)
    parsed = read_bvh(write_bvh(tmp_path / "sample.bvh", clip))
    assert sorted(parsed.names) == sorted(JOINT_NAMES)  # the file lists them depth first
    order = [parsed.names.index(name) for name in JOINT_NAMES]
    expected = recover_from_ric(features.double()).reshape(-1, 22, 3).numpy()
    return np.linalg.norm(bvh_joint_positions(parsed)[:, order] - expected, axis=-1)


@pytest.fixture(scope="module")
def rigid_features(synth_clip) -> torch.Tensor:
    """(131, 263) features of a rigid body with its own proportions (the synthetic person 1)."""
    return features_from_positions(synth_clip.positions[0].double()).features


def test_rigid_body_round_trips_through_a_bvh_file(rigid_features, synth_clip, tmp_path):
    error = round_trip(rigid_features, tmp_path)
    assert error.shape == (131, 22)
    assert error.max() < ROUND_TRIP_TOLERANCE_M, error.max()
    # the estimated body has the person's bone lengths, the template's single-bone directions
    (clip,) = humanml3d_bvh_clips(rigid_features)
    np.testing.assert_allclose(
        np.linalg.norm(clip.offsets[1:], axis=-1),
        np.linalg.norm(synth_clip.offsets[0, 1:].numpy(), axis=-1),
        atol=1e-6,
    )
    template = REST_OFFSETS.double().numpy()
    for child in (c for children in CHILDREN if len(children) == 1 for c in children):
        cosine = clip.offsets[child] @ template[child]
        cosine /= np.linalg.norm(clip.offsets[child]) * np.linalg.norm(template[child])
        assert cosine == pytest.approx(1.0, abs=1e-12), JOINT_NAMES[child]
    assert clip.parents == PARENTS and clip.frames == 131


def test_batched_float32_tensor_and_given_offsets(rigid_features, synth_clip, tmp_path):
    error = round_trip(rigid_features.float()[None], tmp_path)
    assert error.max() < ROUND_TRIP_TOLERANCE_M, error.max()  # float32 costs ~0.1 um
    body = synth_clip.offsets[0].numpy()
    (clip,) = humanml3d_bvh_clips(rigid_features, offsets=body)
    np.testing.assert_array_equal(clip.offsets, body)
    assert round_trip(rigid_features, tmp_path, offsets=body).max() < ROUND_TRIP_TOLERANCE_M


def test_stretching_body_keeps_the_error_within_the_stretch(tmp_path):
    # turning_walk wiggles every joint on its own, so its bones change length by up to 8.7 cm,
    # which no fixed skeleton can follow; measured error: 8.1 cm at most, 2.3 cm on average.
    features = features_from_positions(turning_walk(81)).features
    lengths = bone_lengths(recover_from_ric(features))
    stretch = float((lengths - lengths.median(0).values).abs().max())
    assert stretch == pytest.approx(0.087, abs=1e-3)
    error = round_trip(features, tmp_path)
    assert error[:, 0].max() < 1e-5  # the root is written as it is
    assert error.max() <= stretch and error.mean() < 0.03, (error.max(), error.mean())


def test_fps_sets_the_frame_time(rigid_features, tmp_path):
    assert humanml3d_bvh_clips(rigid_features)[0].frame_time == pytest.approx(0.05)
    (clip,) = humanml3d_bvh_clips(rigid_features, fps=30.0)
    text = write_bvh(tmp_path / "thirty.bvh", clip).read_text()
    assert "Frames: 131\nFrame Time: 0.03333333\n" in text
    assert read_bvh(tmp_path / "thirty.bvh").fps == pytest.approx(30.0)
    with pytest.raises(ValueError, match=r"fps must be > 0, got 0"):
        humanml3d_bvh_clips(rigid_features, fps=0)


@pytest.mark.parametrize(
    ("shape", "message"),
    [
        ((2, 10, 263), r"expected \(T, 263\) or \(1, T, 263\), got \(2, 10, 263\)"),
        ((10, 262), r"expected \(T, 263\) or \(1, T, 263\), got \(10, 262\)"),
        ((0, 263), r"expected \(T, 263\) or \(1, T, 263\), got \(0, 263\)"),
        ((263,), r"expected \(T, 263\) or \(1, T, 263\), got \(263,\)"),
    ],
)
def test_wrong_feature_shapes_are_refused(shape, message):
    with pytest.raises(ValueError, match=rf"humanml3d_bvh_clips: {message}"):
        humanml3d_bvh_clips(np.zeros(shape))


def test_bad_values_and_offsets_are_refused(rigid_features):
    broken = rigid_features.clone()
    broken[3, 7] = float("nan")
    with pytest.raises(ValueError, match="humanml3d_bvh_clips: features contain NaN or infinite"):
        humanml3d_bvh_clips(broken)
    with pytest.raises(
        ValueError, match=r"humanml3d_bvh_clips: offsets must be \(22, 3\), got \(21, 3\)"
    ):
        humanml3d_bvh_clips(rigid_features, offsets=np.zeros((21, 3)))
