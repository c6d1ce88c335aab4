"""AMASS-style ``.npz`` files of fitted bodies, one per person, and reading them back.

AMASS stores bodies in a Z-up world: ``poses`` (T, 3 J) axis-angle, the global orientation first
(SMPL-H: 52 joints = 156 numbers; SMPL-X: 55 = 165, jaw and eyes after the body), ``trans`` (T, 3),
``betas`` (B,), ``gender`` and the frame rate, under both of its spellings (``mocap_framerate``
for SMPL+H, ``mocap_frame_rate`` for SMPL-X). The split keys of AMASS's SMPL-X files
(``root_orient``, ``pose_body``, ``pose_hand``, ``pose_jaw``, ``pose_eye``) and
``surface_model_type`` are written too, so either reader finds what it looks for.

The project's joints are Y up; turning a body to Z up rotates its global orientation, and since
smplx rotates the body about its rest pelvis J0 (which ``trans`` does not include), the
translation becomes ``M (J0 + t) - J0`` for the rotation M, not ``M t``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from intermask.body.fit import BodyParams
from intermask.body.model import FACE_JOINTS, HAND_JOINTS, BodyModel, full_rotations
from intermask.motion.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from intermask.motion.skeleton import NUM_JOINTS

# Y up (x, y, z) -> Z up (x, -z, y): +90 degrees about x (the inverse of motion.zup_to_yup)
YUP_TO_ZUP = torch.tensor([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]], dtype=torch.float64)


def _turn(params: BodyParams, model: BodyModel, rotation: torch.Tensor) -> BodyParams:
    """The same bodies in a world turned by rotation (3, 3)."""
    rotation = rotation.to(params.transl)
    pelvis = model.rest_joints(params.betas.to(model.v_template))[:, None, 0].to(
        params.transl
    )  # (P, 1, 3)
    root = rotation @ params.rotations[:, :, 0]
    transl = (pelvis + params.transl) @ rotation.T - pelvis
    return params._replace(
        rotations=torch.cat((root[:, :, None], params.rotations[:, :, 1:]), 2), transl=transl
    )


def amass_arrays(
    params: BodyParams, model: BodyModel, person: int, *, fps: float
) -> dict[str, np.ndarray]:
    """The arrays of one person's AMASS-style file (module docstring)."""
    if fps <= 0:
        raise ValueError(f"amass_arrays: fps must be > 0, got {fps}")
    turned = _turn(params, model, YUP_TO_ZUP)
    hands = None if turned.hands is None else turned.hands[person]
    rotations = full_rotations(model, turned.rotations[person], hands)  # (T, J, 3, 3)
    axis_angle = matrix_to_axis_angle(rotations.double()).cpu().numpy()  # (T, J, 3)
    frames = axis_angle.shape[0]
    face = FACE_JOINTS[model.kind]
    arrays = {
        "poses": axis_angle.reshape(frames, -1),
        "trans": turned.transl[person].double().cpu().numpy(),
        "betas": params.betas[person].double().cpu().numpy(),
        "num_betas": np.array(params.betas.shape[-1]),
        "gender": np.array(model.gender),
        "surface_model_type": np.array(model.kind),
        "mocap_framerate": np.array(float(fps)),
        "mocap_frame_rate": np.array(float(fps)),
        "root_orient": axis_angle[:, 0],
        "pose_body": axis_angle[:, 1:NUM_JOINTS].reshape(frames, -1),
        "pose_hand": axis_angle[:, NUM_JOINTS + face :].reshape(frames, -1),
    }
    if model.kind == "smplx":
        arrays["pose_jaw"] = axis_angle[:, NUM_JOINTS]
        arrays["pose_eye"] = axis_angle[:, NUM_JOINTS + 1 : NUM_JOINTS + 3].reshape(frames, -1)
    return arrays


def write_amass(
    params: BodyParams, model: BodyModel, folder: str | Path, *, fps: float, stem: str = "body"
) -> list[Path]:
    """Write ``<stem>_person<k>.npz`` per person into folder; returns the paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for person in range(params.betas.shape[0]):
        path = folder / f"{stem}_person{person + 1}.npz"
        np.savez(path, **amass_arrays(params, model, person, fps=fps))
        paths.append(path)
    return paths


def read_amass(paths: list[str | Path], model: BodyModel) -> tuple[BodyParams, float]:
    """Read per-person AMASS-style files back into Y-up BodyParams and their frame rate."""
    people = []
    for path in paths:
        with np.load(path) as archive:
            keys = set(archive.files)
            missing = {"poses", "trans", "betas"} - keys
            if missing:
                raise ValueError(f"{path}: not an AMASS-style body file: missing {sorted(missing)}")
            rate_key = "mocap_framerate" if "mocap_framerate" in keys else "mocap_frame_rate"
            people.append(
                {key: archive[key] for key in ("poses", "trans", "betas", rate_key)}
                | {"fps": float(archive[rate_key])}
            )
        poses = people[-1]["poses"]
        if poses.shape[-1] != 3 * model.num_joints:
            raise ValueError(
                f"{path}: poses has {poses.shape[-1] // 3} joints, the {model.kind} model "
                f"{model.path} has {model.num_joints}"
            )
    frames = {person["poses"].shape[0] for person in people}
    if len(frames) != 1:
        raise ValueError(
            f"read_amass: the persons' files have different frame counts {sorted(frames)}"
        )
    rotations = axis_angle_to_matrix(
        torch.from_numpy(np.stack([p["poses"] for p in people])).reshape(
            len(people), -1, model.num_joints, 3
        )
    )
    face = FACE_JOINTS[model.kind]
    params = BodyParams(
        betas=torch.from_numpy(np.stack([p["betas"] for p in people])),
        rotations=rotations[:, :, :NUM_JOINTS],
        hands=rotations[:, :, NUM_JOINTS + face : NUM_JOINTS + face + 2 * HAND_JOINTS],
        transl=torch.from_numpy(np.stack([p["trans"] for p in people])),
    )
    return _turn(params, model, YUP_TO_ZUP.T), people[0]["fps"]
