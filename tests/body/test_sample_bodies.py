"""Body files for sample folders: ``python -m intermask.body`` (and ``intermask body``)."""

import json

import numpy as np
import pytest
import torch
from body_builders import known_params
from gltf_tools import assert_valid
from test_fit import interhuman_features

from intermask.body.command import main
from intermask.motion.interhuman import yup_to_zup
from intermask.motion.interx import person_representation
from intermask.motion.rotations import matrix_to_axis_angle


def write_sample(folder, joints, features, **record):
    folder.mkdir(parents=True)
    np.save(folder / "joints.npy", joints.permute(1, 0, 2, 3).numpy().astype(np.float32))
    np.save(folder / "features.npy", features.numpy().astype(np.float32))
    (folder / "sample.json").write_text(
        json.dumps({"caption": "two bodies", "settings": {"fps": 20.0}, **record})
    )
    return folder


@pytest.fixture
def interhuman_sample(smplx_model, tmp_path):
    truth = known_params(24)
    joints = smplx_model.body_joints(truth.betas, truth.rotations, truth.transl)
    return write_sample(
        tmp_path / "sample_00-00", joints, interhuman_features(joints, truth.rotations)
    )


def test_body_command_writes_npz_glb_report_and_viewer(interhuman_sample, model_folder, capsys):
    assert (
        main([str(interhuman_sample), "--body-model", str(model_folder), "--model-type", "smplx"])
        == 0
    )
    names = {"body_person1.npz", "body_person2.npz", "bodies.glb", "body_fit.json", "viewer.html"}
    assert names <= {p.name for p in interhuman_sample.iterdir()}
    assert "bodies.glb" in capsys.readouterr().out
    report = json.loads((interhuman_sample / "body_fit.json").read_text())
    assert (
        report["start"] == "interhuman rotations"
        and report["frames"] == 24
        and report["persons"] == 2
    )
    assert report["error_mm"]["mean"] < 5.0 and set(report["error_mm"]["per_joint_mean"]) >= {
        "pelvis",
        "r_wrist",
    }
    assert report["threads"] == 1 and report["seconds_per_100_frames_per_person"] > 0
    with np.load(interhuman_sample / "body_person1.npz") as archive:
        assert archive["poses"].shape == (24, 165) and float(archive["mocap_framerate"]) == 20.0
    assert_valid(interhuman_sample / "bodies.glb")
    assert '"bodies":[{' in (interhuman_sample / "viewer.html").read_text()


def test_without_a_body_model_the_glb_holds_limb_meshes(interhuman_sample):
    assert main([str(interhuman_sample)]) == 0
    assert not (interhuman_sample / "body_fit.json").exists()
    report = assert_valid(interhuman_sample / "bodies.glb")
    assert report["info"]["animationCount"] == 2


def test_interx_sample_starts_from_its_rotations(smplh_model, model_folder, tmp_path):
    truth = known_params(12)
    joints = smplh_model.body_joints(truth.betas, truth.rotations, truth.transl)
    zup = truth.rotations.clone()
    zup[:, :, 0] = (
        torch.tensor([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]], dtype=torch.float64) @ zup[:, :, 0]
    )
    rows = torch.cat(
        (zup, torch.eye(3, dtype=torch.float64).expand(2, 12, 3, 3, 3), truth.hands), 2
    )
    features = person_representation(
        torch.cat((matrix_to_axis_angle(rows), yup_to_zup(truth.transl)[:, :, None]), 2)
    )
    sample = write_sample(tmp_path / "interx", joints, features, mode="reaction")
    assert (
        main([str(sample), "--body-model", str(model_folder / "smplh" / "neutral" / "model.npz")])
        == 0
    )
    report = json.loads((sample / "body_fit.json").read_text())
    assert report["start"] == "inter-x rotations" and report["body_model"]["kind"] == "smplh"
    assert report["error_mm"]["mean"] < 5.0
    assert_valid(sample / "bodies.glb")


def test_clear_errors_name_the_file(interhuman_sample, model_folder, tmp_path, capsys):
    assert main([str(interhuman_sample), "--body-model", str(tmp_path / "missing.npz")]) == 2
    assert "missing.npz: body model not found" in capsys.readouterr().err
    assert (
        main(
            [
                str(interhuman_sample),
                "--body-model",
                str(model_folder / "SMPLX_NEUTRAL.npz"),
                "--gender",
                "male",
            ]
        )
        == 2
    )
    assert "SMPLX_NEUTRAL.npz: wrong gender: asked for 'male'" in capsys.readouterr().err
    np.save(interhuman_sample / "joints.npy", np.zeros((24, 2, 24, 3), dtype=np.float32))
    assert main([str(interhuman_sample), "--body-model", str(model_folder)]) == 2
    assert (
        "joints.npy: mismatched joint set: 24 joints, the body fit reads the 22 SMPL body joints"
        in capsys.readouterr().err
    )
    (interhuman_sample / "features.npy").unlink()
    assert main([str(interhuman_sample)]) == 2
    assert "features.npy: not found" in capsys.readouterr().err


def test_generate_options_add_bodies_to_the_written_folders(interhuman_sample, model_folder):
    """What ``intermask generate --body-model`` does after writing its sample folders."""
    import argparse

    from intermask.body.command import add_generate_body_options, generate_bodies

    parser = argparse.ArgumentParser()
    add_generate_body_options(parser)
    args = parser.parse_args(["--body-model", str(model_folder), "--body-model-type", "smplx"])
    generate_bodies(args, [interhuman_sample])
    assert (interhuman_sample / "body_fit.json").is_file() and (
        interhuman_sample / "bodies.glb"
    ).is_file()
    generate_bodies(parser.parse_args([]), [interhuman_sample])  # no --body-model: nothing to do


def test_the_console_script_runs_body_and_generate_takes_a_body_model(
    interhuman_sample, model_folder, capsys
):
    from intermask.cli import build_parser
    from intermask.cli import main as cli_main

    assert (
        cli_main(
            [
                "body",
                str(interhuman_sample),
                "--body-model",
                str(model_folder / "SMPLX_NEUTRAL.npz"),
            ]
        )
        == 0
    )
    assert (interhuman_sample / "body_fit.json").is_file()
    assert (
        cli_main(["body", str(interhuman_sample), "--body-model", str(model_folder / "nope.npz")])
        == 2
    )
    assert "intermask body: error: " in capsys.readouterr().err
    args = build_parser().parse_args(
        [
            "generate",
            "--checkpoint",
            "run",
            "--text",
            "hi",
            "--body-model",
            "m",
            "--body-gender",
            "female",
        ]
    )
    assert (
        str(args.body_model) == "m"
        and args.body_gender == "female"
        and args.body_model_type is None
    )


def test_the_parsers_defaults_are_the_models():
    from intermask.body import command
    from intermask.body.fit import FitSettings
    from intermask.body.model import DEFAULT_BETAS, GENDERS, NUM_MODEL_JOINTS

    assert command.KINDS == tuple(sorted(NUM_MODEL_JOINTS)) and command.GENDERS == GENDERS
    assert command.DEFAULT_BETAS == DEFAULT_BETAS
    assert (command.DEFAULT_ITERATIONS, command.DEFAULT_THREADS) == (
        FitSettings.iterations,
        FitSettings.threads,
    )
