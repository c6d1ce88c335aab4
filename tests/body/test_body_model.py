import pickle
from dataclasses import replace

import numpy as np
import pytest
import torch
from body_builders import known_params

from intermask.body.model import (
    BodyModelError,
    find_body_model_file,
    full_rotations,
    gender_of_path,
    load_body_model,
)
from intermask.body.standin import UINT32_ROOT, standin_arrays, write_standin_model
from intermask.motion.rotations import matrix_to_axis_angle
from intermask.motion.skeleton import PARENTS

SMPLX_KEYS = {
    "v_template", "f", "shapedirs", "posedirs", "J_regressor", "weights", "kintree_table",
    "hands_componentsl", "hands_componentsr", "hands_meanl", "hands_meanr", "hands_coeffsl",
    "hands_coeffsr", "lmk_faces_idx", "lmk_bary_coords", "dynamic_lmk_faces_idx",
    "dynamic_lmk_bary_coords", "vt", "ft",
}  # fmt: skip


def test_standin_has_the_release_layout():
    smplx, smplh = standin_arrays("smplx"), standin_arrays("smplh")
    assert set(smplx) == SMPLX_KEYS
    assert {"J_regressor_prior", "weights_prior", "J", "bs_style", "bs_type"} <= set(smplh)
    for arrays, joints, shapes in ((smplx, 55, 400), (smplh, 52, 16)):
        vertices = len(arrays["v_template"])
        assert (
            arrays["kintree_table"].shape == (2, joints)
            and arrays["kintree_table"][0, 0] == UINT32_ROOT
        )
        assert tuple(arrays["kintree_table"][0, 1:22]) == PARENTS[1:]
        assert arrays["f"].dtype == np.uint32 and arrays["kintree_table"].dtype == np.int64
        assert arrays["shapedirs"].shape == (vertices, 3, shapes)
        assert arrays["posedirs"].shape == (vertices, 3, 9 * (joints - 1))
        assert all(
            arrays[k].dtype == np.float64
            for k in ("v_template", "shapedirs", "posedirs", "J_regressor", "weights")
        )
        np.testing.assert_allclose(arrays["weights"].sum(1), 1.0)
        assert vertices < 1000  # few vertices: the tests stay fast


def test_standin_mesh_is_closed_and_its_regressor_finds_the_joints(smplx_model):
    faces = smplx_model.faces.numpy()
    edges = {
        (int(a), int(b)) for face in faces for a, b in zip(face, np.roll(face, -1), strict=True)
    }
    assert all(
        (b, a) in edges for a, b in edges
    )  # every directed edge has its twin: closed, oriented
    rest = smplx_model.rest_joints(torch.zeros(10, dtype=torch.float64))
    # each joint is regressed from the ring of vertices around it in the rest pose
    assert torch.linalg.vector_norm(rest[1] - rest[0]) > 0.05


def test_smplx_package_loads_the_standin_and_poses_it_as_we_do(
    model_folder, smplx_model, monkeypatch
):
    smplx = pytest.importorskip("smplx")
    params = known_params(4)
    # the stand-in has few vertices: the extra joints smplx reads off vertices must exist
    vertex_ids = {name: k for k, name in enumerate(
        ["nose", "reye", "leye", "rear", "lear", "LBigToe", "LSmallToe", "LHeel", "RBigToe",
         "RSmallToe", "RHeel", "lthumb", "lindex", "lmiddle", "lring", "lpinky", "rthumb",
         "rindex", "rmiddle", "rring", "rpinky"])}  # fmt: skip
    monkeypatch.setitem(smplx.body_models.VERTEX_IDS, "smplx", vertex_ids)
    reference = smplx.create(
        str(model_folder / "SMPLX_NEUTRAL.npz"), model_type="smplx", use_pca=False, flat_hand_mean=True,
        num_betas=10, batch_size=4, dtype=torch.float64,
    )  # fmt: skip
    rotations = full_rotations(smplx_model, params.rotations[0, :4], params.hands[0, :4])
    axis_angle = matrix_to_axis_angle(rotations)
    with torch.no_grad():
        expected = reference(
            betas=params.betas[:1].expand(4, -1), global_orient=axis_angle[:, 0],
            body_pose=axis_angle[:, 1:22].reshape(4, -1), jaw_pose=axis_angle[:, 22],
            leye_pose=axis_angle[:, 23], reye_pose=axis_angle[:, 24],
            left_hand_pose=axis_angle[:, 25:40].reshape(4, -1),
            right_hand_pose=axis_angle[:, 40:55].reshape(4, -1), transl=params.transl[0, :4],
        )  # fmt: skip
    vertices, joints = smplx_model.pose(params.betas[:1], rotations, params.transl[0, :4])
    # 1e-6 m: smplx takes axis-angle, our rotations make a round trip through it
    torch.testing.assert_close(vertices, expected.vertices, atol=1e-6, rtol=0)
    torch.testing.assert_close(joints, expected.joints[:, :55], atol=1e-6, rtol=0)


@pytest.mark.parametrize("fixture", ["smplx_model", "smplh_model"])
def test_body_joints_are_the_first_22_posed_joints(fixture, request):
    model = request.getfixturevalue(fixture)
    params = known_params(5)
    body = model.body_joints(params.betas, params.rotations, params.transl)
    for person in range(2):
        rotations = full_rotations(model, params.rotations[person], params.hands[person])
        _, joints = model.pose(params.betas[person : person + 1], rotations, params.transl[person])
        torch.testing.assert_close(body[person], joints[:, :22], atol=1e-10, rtol=0)


def test_finds_the_release_layouts_in_a_folder(model_folder):
    assert find_body_model_file(model_folder, kind="smplx").name == "SMPLX_NEUTRAL.npz"
    assert (
        find_body_model_file(model_folder, kind="smplh")
        == model_folder / "smplh" / "neutral" / "model.npz"
    )
    assert gender_of_path(model_folder / "SMPLX_FEMALE.npz") == "female"
    assert gender_of_path(model_folder / "smplh" / "male" / "model.npz") == "male"
    assert load_body_model(model_folder, kind="smplh").kind == "smplh"


def test_missing_model_says_where_to_get_it(tmp_path):
    with pytest.raises(
        BodyModelError,
        match=r"nowhere/SMPLX_NEUTRAL.npz: body model not found; .*smpl-x.is.tue.mpg.de",
    ):
        load_body_model(tmp_path / "nowhere" / "SMPLX_NEUTRAL.npz")
    with pytest.raises(
        BodyModelError,
        match=r"no smplx body model for gender 'female' in this folder \(looked for SMPLX_FEMALE.npz, .*licensed",
    ):
        load_body_model(tmp_path, kind="smplx", gender="female")


def test_wrong_gender_names_the_file(tmp_path):
    path = write_standin_model(tmp_path, "smplx", gender="male")
    with pytest.raises(
        BodyModelError,
        match=r"SMPLX_MALE.npz: wrong gender: asked for 'female', the file is the 'male' model",
    ):
        load_body_model(path, gender="female")
    assert load_body_model(path).gender == "male"
    with pytest.raises(
        BodyModelError, match="gender must be one of neutral, male, female, got 'other'"
    ):
        load_body_model(path, gender="other")


def test_mismatched_joint_sets_name_the_file(model_folder, tmp_path):
    with pytest.raises(
        BodyModelError,
        match=r"SMPLX_NEUTRAL.npz: mismatched joint set: asked for smplh \(52 joints\), the file is smplx \(55 joints\)",
    ):
        load_body_model(model_folder / "SMPLX_NEUTRAL.npz", kind="smplh")
    arrays = standin_arrays("smplh")
    smpl = {k: v for k, v in arrays.items()} | {
        "kintree_table": arrays["kintree_table"][:, :24],
        "weights": arrays["weights"][:, :24],
        "J_regressor": arrays["J_regressor"][:24],
        "posedirs": arrays["posedirs"][..., : 9 * 23],
    }
    np.savez(tmp_path / "SMPL_NEUTRAL.npz", **smpl)
    with pytest.raises(
        BodyModelError,
        match=r"SMPL_NEUTRAL.npz: mismatched joint set: the model has 24 joints \(SMPL, no hand joints\)",
    ):
        load_body_model(tmp_path / "SMPL_NEUTRAL.npz")
    shuffled = dict(arrays)
    shuffled["kintree_table"] = arrays["kintree_table"].copy()
    shuffled["kintree_table"][0, 4] = 2
    np.savez(tmp_path / "odd.npz", **shuffled)
    with pytest.raises(
        BodyModelError, match=r"odd.npz: mismatched joint set: the first 22 joints' parents"
    ):
        load_body_model(tmp_path / "odd.npz")


def test_malformed_files_name_the_file(tmp_path):
    arrays = standin_arrays("smplh")
    np.savez(tmp_path / "a.npz", **{k: v for k, v in arrays.items() if k != "posedirs"})
    with pytest.raises(
        BodyModelError, match=r"a.npz: not an SMPL-H / SMPL-X body model: missing posedirs"
    ):
        load_body_model(tmp_path / "a.npz")
    np.savez(tmp_path / "b.npz", **(arrays | {"weights": arrays["weights"][:-1]}))
    with pytest.raises(BodyModelError, match=r"b.npz: weights must be \(\d+, 52\)"):
        load_body_model(tmp_path / "b.npz")
    (tmp_path / "c.pkl").write_bytes(b"\x80\x02cchumpy.ch\nCh\nq\x00)\x81q\x01.")
    with pytest.raises(BodyModelError, match=r"c.pkl: this pickle holds chumpy objects"):
        load_body_model(tmp_path / "c.pkl")
    np.save(tmp_path / "e.npy", np.zeros((4, 2, 22, 3)))  # a joints.npy saved under .npz
    (tmp_path / "e.npy").rename(tmp_path / "e.npz")
    with pytest.raises(
        BodyModelError,
        match=r"e.npz: not a body-model archive: it holds one array of shape \(4, 2, 22, 3\)",
    ):
        load_body_model(tmp_path / "e.npz")
    (tmp_path / "d.obj").write_text("v 0 0 0")
    with pytest.raises(BodyModelError, match=r"d.obj: body-model files are .npz or .pkl"):
        load_body_model(tmp_path / "d.obj")


def test_a_pickle_without_chumpy_loads(tmp_path):
    arrays = standin_arrays("smplh")
    with (tmp_path / "SMPLH_MALE.pkl").open("wb") as handle:
        pickle.dump(dict(arrays), handle)
    model = load_body_model(tmp_path / "SMPLH_MALE.pkl")
    assert (model.kind, model.gender, model.num_joints) == ("smplh", "male", 52)
    moved = replace(model)
    assert moved.num_vertices == len(arrays["v_template"])
