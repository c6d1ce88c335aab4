"""Test helpers for .glb files (tests/render, tests/body): the Khronos glTF validator (npm's gltf-validator, run by node) and
glTF's own skinning, evaluated from the file, to compare with what was exported."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from intermask.motion.rotations import quaternion_to_matrix
from intermask.render.gltf import accessor_array, read_glb

# .ci/run installs the validator here (npm install --prefix /opt/gltf-validator gltf-validator)
VALIDATOR_PREFIX = Path(os.environ.get("GLTF_VALIDATOR_PREFIX", "/opt/gltf-validator"))
_SCRIPT = """
const validator = require('gltf-validator');
const fs = require('fs');
const data = new Uint8Array(fs.readFileSync(process.argv[1]));
validator.validateBytes(data, {maxIssues: 100}).then(
  (report) => { console.log(JSON.stringify(report)); },
  (error) => { console.error(String(error)); process.exit(2); });
"""


def validator_available() -> bool:
    return (
        shutil.which("node") is not None
        and (VALIDATOR_PREFIX / "node_modules" / "gltf-validator").is_dir()
    )


def validate_glb(path: Path) -> dict:
    """The Khronos validator's report of path (skips the test where the validator is absent)."""
    if not validator_available():
        pytest.skip(
            f"the Khronos glTF validator is absent ({VALIDATOR_PREFIX}/node_modules/gltf-validator: "
            ".ci/run installs it with npm as root)"
        )
    result = subprocess.run(
        ["node", "-e", _SCRIPT, str(path)],
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "NODE_PATH": str(VALIDATOR_PREFIX / "node_modules")},
        check=False,
    )
    if result.returncode != 0:
        raise RuntimeError(f"gltf-validator failed on {path}: {result.stderr}")
    return json.loads(result.stdout)


def assert_valid(path: Path) -> dict:
    report = validate_glb(path)
    issues = report["issues"]
    errors = [m for m in issues["messages"] if m["severity"] == 0]
    assert issues["numErrors"] == 0, errors
    return report


def skinned_frames(path: Path, character: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """glTF skinning of one character at every keyframe, from the file alone:
    -> vertices (T, V, 3) and joint world positions (T, J, 3)."""
    document, blob = read_glb(path)
    skin = document["skins"][character]
    nodes = document["nodes"]
    joints = skin["joints"]
    parent = {child: k for k, node in enumerate(nodes) for child in node.get("children", [])}
    animation = document["animations"][character]
    frames = accessor_array(document, blob, animation["samplers"][0]["input"]).shape[0]
    rotation = {n: np.tile([0.0, 0.0, 0.0, 1.0], (frames, 1)) for n in joints}
    translation = {
        n: np.tile(nodes[n].get("translation", [0.0, 0.0, 0.0]), (frames, 1)) for n in joints
    }
    for channel in animation["channels"]:
        values = accessor_array(document, blob, animation["samplers"][channel["sampler"]]["output"])
        target = channel["target"]
        (rotation if target["path"] == "rotation" else translation)[target["node"]] = values.astype(
            np.float64
        )
    world = {}
    for n in joints:  # parents come first in our files
        local = np.tile(np.eye(4), (frames, 1, 1))
        xyzw = rotation[n]
        local[:, :3, :3] = quaternion_to_matrix(
            __import__("torch").from_numpy(np.concatenate((xyzw[:, 3:], xyzw[:, :3]), 1))
        ).numpy()
        local[:, :3, 3] = translation[n]
        world[n] = world[parent[n]] @ local if n in parent and parent[n] in world else local
    inverse_bind = accessor_array(document, blob, skin["inverseBindMatrices"]).reshape(-1, 4, 4)
    inverse_bind = np.swapaxes(inverse_bind, 1, 2).astype(np.float64)  # column-major
    matrices = np.stack([world[n] for n in joints], 1) @ inverse_bind  # (T, J, 4, 4)
    primitive = document["meshes"][
        nodes[[k for k, node in enumerate(nodes) if node.get("skin") == character][0]]["mesh"]
    ]["primitives"][0]
    attributes = primitive["attributes"]
    positions = accessor_array(document, blob, attributes["POSITION"]).astype(np.float64)
    index = accessor_array(document, blob, attributes["JOINTS_0"]).astype(np.int64)
    weight = accessor_array(document, blob, attributes["WEIGHTS_0"]).astype(np.float64)
    blended = (matrices[:, index] * weight[None, :, :, None, None]).sum(2)  # (T, V, 4, 4)
    homogeneous = np.concatenate((positions, np.ones((len(positions), 1))), 1)
    vertices = np.einsum("tvij,vj->tvi", blended, homogeneous)[..., :3]
    joint_positions = np.stack([world[n][:, :3, 3] for n in joints], 1)
    return vertices, joint_positions
