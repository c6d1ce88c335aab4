"""``intermask body`` as users run it: the console script in a fresh process, from another
working directory, on a sample folder; a missing body-model file is named, nothing is written."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from body_builders import known_params
from test_fit import interhuman_features
from test_sample_bodies import write_sample


def _intermask(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    script = Path(sys.executable).parent / "intermask"
    return subprocess.run(
        [str(script), *args], cwd=cwd, capture_output=True, text=True, timeout=300, check=False
    )


def test_the_body_console_script_fits_a_sample_from_another_directory(
    smplx_model, model_folder, tmp_path
):
    truth = known_params(24)
    joints = smplx_model.body_joints(truth.betas, truth.rotations, truth.transl)
    sample = write_sample(
        tmp_path / "sample_00-00", joints, interhuman_features(joints, truth.rotations)
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    missing = model_folder / "SMPLX_MISSING.npz"
    done = _intermask("body", str(sample), "--body-model", str(missing), cwd=elsewhere)
    assert done.returncode == 2 and str(missing) in done.stderr and "Traceback" not in done.stderr
    assert not (sample / "bodies.glb").exists() and not (sample / "body_fit.json").exists()
    done = _intermask("body", str(sample), "--body-model", str(model_folder), cwd=elsewhere)
    assert done.returncode == 0, done.stderr
    report = json.loads((sample / "body_fit.json").read_text())
    assert report["persons"] == 2 and report["error_mm"]["mean"] < 5.0
    assert (sample / "bodies.glb").stat().st_size > 1000
    assert list(elsewhere.iterdir()) == []  # nothing written where the command ran
