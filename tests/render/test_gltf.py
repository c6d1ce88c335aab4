import math
from dataclasses import replace

import numpy as np
import pytest
import torch
from gltf_tools import assert_valid, skinned_frames

from intermask.body.export import body_characters
from intermask.body.fit import BodyParams
from intermask.body.model import full_rotations, load_body_model
from intermask.body.standin import write_standin_model
from intermask.motion.rotations import axis_angle_to_matrix, rotation_about_axis
from intermask.motion.skeleton import JOINT_NAMES, PARENTS
from intermask.render import interhuman_bvh_clips
from intermask.render.bvh import bvh_joint_positions
from intermask.render.gltf import (
    Character,
    continuous_quaternions,
    glb_bytes,
    limb_character,
    read_glb,
    top_weights,
    write_glb,
)


@pytest.fixture(scope="module")
def model(tmp_path_factory: pytest.TempPathFactory):
    path = write_standin_model(tmp_path_factory.mktemp("standin"), "smplx")
    return load_body_model(path, dtype=torch.float64)


def turning_params(frames: int = 24) -> BodyParams:
    """Person 1 turns a full circle about Y (its back to the camera half the time) while
    bending; person 2 lies down on its back and rolls onto its side."""
    generator = torch.Generator().manual_seed(3)
    t = torch.linspace(0.0, 1.0, frames, dtype=torch.float64)
    axis_angle = 0.5 * torch.randn(2, 1, 22, 3, generator=generator, dtype=torch.float64).expand(
        2, frames, 22, 3
    )
    rotations = axis_angle_to_matrix(axis_angle).clone()
    rotations[0, :, 0] = rotation_about_axis(2 * math.pi * t, "y")
    lying = rotation_about_axis(torch.full_like(t, -math.pi / 2), "x")
    rotations[1, :, 0] = rotation_about_axis(math.pi / 2 * t, "z") @ lying
    transl = torch.tensor([[0.0, 1.2, 0.0], [0.8, 0.4, 0.0]], dtype=torch.float64)[:, None].expand(
        2, frames, 3
    )
    return BodyParams(
        torch.randn(2, 10, generator=generator, dtype=torch.float64), rotations, None, transl
    )


def test_body_glb_is_valid_and_skins_like_the_body_model(model, tmp_path):
    """The Khronos validator finds no error; glTF's skinning, read back from the file alone,
    puts every vertex where the body model does (no flipped limbs for the turning and the
    lying character)."""
    params = turning_params()
    path = write_glb(body_characters(model, params), tmp_path / "bodies.glb", fps=30.0)
    report = assert_valid(path)
    assert report["issues"]["numWarnings"] == 0
    assert (
        report["info"]["animationCount"] == 2
        and report["info"]["totalVertexCount"] == 2 * model.num_vertices
    )
    without_correctives = replace(model, posedirs=torch.zeros_like(model.posedirs))  # glTF has none
    for person in range(2):
        vertices, joints = skinned_frames(path, person)
        rotations = full_rotations(model, params.rotations[person])
        expected, expected_joints = without_correctives.pose(
            params.betas[person : person + 1], rotations, params.transl[person]
        )
        np.testing.assert_allclose(vertices, expected.numpy(), atol=2e-6)
        np.testing.assert_allclose(joints, expected_joints.numpy(), atol=2e-6)


def test_glb_document_layout(model):
    document, blob = read_glb_from_bytes(
        glb_bytes(body_characters(model, turning_params(5)), fps=20.0)
    )
    assert document["asset"]["version"] == "2.0"
    times = document["accessors"][document["animations"][0]["samplers"][0]["input"]]
    assert times["min"] == [0.0] and times["max"] == [pytest.approx(4 / 20.0)]
    assert [node["name"] for node in document["nodes"][:2]] == ["person1_pelvis", "person1_l_hip"]
    assert len(blob) % 4 == 0


def read_glb_from_bytes(data: bytes):
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "a.glb"
        path.write_bytes(data)
        return read_glb(path)


def test_quaternion_tracks_never_jump_to_the_other_sign():
    angles = torch.linspace(0.0, 4 * math.pi, 50, dtype=torch.float64)  # two full turns
    quaternions = continuous_quaternions(rotation_about_axis(angles, "y")[:, None].numpy())
    assert ((quaternions[1:] * quaternions[:-1]).sum(-1) > 0).all()
    np.testing.assert_allclose(np.linalg.norm(quaternions, axis=-1), 1.0)


def test_limb_glb_without_a_body_model_is_valid_and_follows_the_bvh_skeleton(
    clip_joints, synth_clip, tmp_path
):
    from intermask.motion.interhuman import assemble_features

    features = assemble_features(synth_clip.positions, torch.zeros(2, synth_clip.frames, 21, 6))
    features = features.clone()
    from intermask.motion.interhuman import ROTATIONS
    from intermask.motion.rotations import matrix_to_rot6d

    rot6d = matrix_to_rot6d(synth_clip.local_rotations[:, :-1, 1:]).reshape(2, -1, 126)
    features[..., ROTATIONS] = rot6d.to(features)
    clips = interhuman_bvh_clips(features, fps=30.0)
    characters = [
        limb_character(
            f"person{k + 1}",
            PARENTS,
            JOINT_NAMES,
            clip.offsets,
            clip.rotations,
            clip.root_positions,
            head=15,
        )
        for k, clip in enumerate(clips)
    ]
    path = write_glb(characters, tmp_path / "skeletons.glb", fps=30.0)
    assert_valid(path)
    for person, clip in enumerate(clips):
        _, joints = skinned_frames(path, person)
        np.testing.assert_allclose(joints, bvh_joint_positions(clip), atol=1e-5)


def test_weights_keep_four_joints_summing_to_one():
    weights = np.array([[0.1, 0.2, 0.3, 0.25, 0.15], [0.0, 1.0, 0.0, 0.0, 0.0]])
    joints, kept = top_weights(weights)
    assert joints.tolist() == [[2, 3, 1, 4], [1, 0, 0, 0]]
    np.testing.assert_allclose(kept.sum(1), 1.0, atol=1e-7)
    assert kept[1].tolist() == [1.0, 0.0, 0.0, 0.0]
    with pytest.raises(ValueError, match="1 vertices have no positive weight"):
        top_weights(np.zeros((1, 3)))


def test_bad_characters_are_refused():
    good = dict(
        name="a", parents=(-1, 0), joint_names=("root", "tip"), rest_joints=np.zeros((2, 3)),
        rotations=np.tile(np.eye(3), (3, 2, 1, 1)), root_positions=np.zeros((3, 3)),
        vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 2]]), weights=np.ones((3, 2)) / 2,
    )  # fmt: skip
    Character(**good)
    with pytest.raises(
        ValueError,
        match=r"Character 'a': inconsistent shapes for 2 joints, 3 frames: root_positions \(2, 3\)",
    ):
        Character(**(good | {"root_positions": np.zeros((2, 3))}))
    with pytest.raises(ValueError, match=r"faces index vertices outside \[0, 3\)"):
        Character(**(good | {"faces": np.array([[0, 1, 3]])}))
    with pytest.raises(ValueError, match="rotations contain NaN"):
        Character(**(good | {"rotations": np.full((3, 2, 3, 3), np.nan)}))
    with pytest.raises(ValueError, match="different frame counts"):
        glb_bytes(
            [
                Character(**good),
                Character(
                    **(
                        good
                        | {"rotations": good["rotations"][:2], "root_positions": np.zeros((2, 3))}
                    )
                ),
            ],
            fps=30,
        )
    with pytest.raises(ValueError, match="fps must be > 0"):
        glb_bytes([Character(**good)], fps=0)


def test_the_validator_reports_errors(model, tmp_path):
    """The check is live: a file claiming another glTF major version is an error to it."""
    from gltf_tools import validate_glb

    data = glb_bytes(body_characters(model, turning_params(3)), fps=30.0)
    broken = tmp_path / "broken.glb"
    broken.write_bytes(data.replace(b'"version":"2.0"', b'"version":"9.0"'))
    messages = validate_glb(broken)["issues"]["messages"]
    assert [m["code"] for m in messages if m["severity"] == 0] == ["UNKNOWN_ASSET_MAJOR_VERSION"]
