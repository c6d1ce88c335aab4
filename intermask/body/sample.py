"""Body output for a sample folder written by ``intermask generate`` (or any folder holding
``joints.npy`` (T, P, 22, 3) and ``features.npy`` (P, T, *F), with ``sample.json``'s frame rate).

With a body model: per person ``body_person<k>.npz`` (AMASS style, Z up), ``bodies.glb`` (both
persons as skinned meshes), ``body_fit.json`` (the fit's per-joint error against the sample's
joints, its time and settings) and ``viewer.html`` drawing the meshes. Without one:
``bodies.glb`` holds skeletons with simple limb meshes (the BVH export's rotations), and
``viewer.html`` draws those.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from intermask.body.amass import write_amass
from intermask.body.export import body_characters, person_color
from intermask.body.fit import FitResult, FitSettings, fit_bodies, representation_of
from intermask.body.model import BodyModel
from intermask.motion.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS
from intermask.render.frames import HEAD_JOINT
from intermask.render.gltf import Character, limb_character, write_glb

DEFAULT_FPS = 30.0


def _load(folder: Path) -> tuple[np.ndarray, np.ndarray, dict[str, Any]]:
    joints_path, features_path = folder / "joints.npy", folder / "features.npy"
    for path in (joints_path, features_path):
        if not path.is_file():
            raise FileNotFoundError(
                f"{path}: not found (a sample folder of intermask generate holds it)"
            )
    joints, features = np.load(joints_path), np.load(features_path)
    if joints.ndim != 4 or joints.shape[-1] != 3:
        raise ValueError(f"{joints_path}: expected joints (T, P, 22, 3), got {joints.shape}")
    if joints.shape[2] != NUM_JOINTS:
        raise ValueError(
            f"{joints_path}: mismatched joint set: {joints.shape[2]} joints, the body fit reads the "
            f"{NUM_JOINTS} SMPL body joints"
        )
    try:
        representation_of(features)
    except ValueError as error:
        raise ValueError(f"{features_path}: {error}") from error
    if features.shape[0] != joints.shape[1] or features.shape[1] < joints.shape[0]:
        raise ValueError(
            f"{features_path}: {features.shape[0]} persons x {features.shape[1]} frames do not match "
            f"{joints_path}'s {joints.shape[1]} persons x {joints.shape[0]} frames"
        )
    record_path = folder / "sample.json"
    record = json.loads(record_path.read_text()) if record_path.is_file() else {}
    return joints, features, record


def sample_fps(record: dict[str, Any]) -> float:
    """The frame rate a sample.json records (Inter-M: settings.fps; MoMask: fps)."""
    return float(record.get("fps") or record.get("settings", {}).get("fps") or DEFAULT_FPS)


def limb_characters(features: np.ndarray, fps: float) -> list[Character]:
    """Skeletons with limb meshes from a representation (no body model): the BVH export's
    offsets and rotations."""
    from intermask.render.bvh_export import (
        humanml3d_bvh_clips,
        interhuman_bvh_clips,
        interx_bvh_clips,
    )

    kind = representation_of(features)
    if kind == "interhuman":
        clips = interhuman_bvh_clips(features, fps=fps)
    elif kind == "interx":
        clips = interx_bvh_clips(features, fps=fps)
    else:
        clips = humanml3d_bvh_clips(features, fps=fps)
    return [
        limb_character(
            f"person{k + 1}",
            PARENTS,
            JOINT_NAMES,
            clip.offsets,
            clip.rotations,
            clip.root_positions,
            color=person_color(k),
            head=HEAD_JOINT,
        )  # fmt: skip
        for k, clip in enumerate(clips)
    ]


def fit_report(fit: FitResult, model: BodyModel, *, settings: FitSettings) -> dict[str, Any]:
    """body_fit.json: the per-joint error of the fitted bodies against the sample's joints."""
    error = fit.error.double() * 1000.0  # (P, T, 22) mm
    persons, frames = error.shape[:2]
    return {
        "body_model": {"path": str(model.path), "kind": model.kind, "gender": model.gender},
        "start": fit.start,
        "persons": persons,
        "frames": frames,
        "error_mm": {
            "mean": round(float(error.mean()), 3),
            "max": round(float(error.max()), 3),
            "per_person_mean": [round(float(e), 3) for e in error.mean((1, 2))],
            "per_joint_mean": dict(
                zip(JOINT_NAMES, (round(float(e), 3) for e in error.mean((0, 1))), strict=True)
            ),
        },
        "seconds": round(fit.seconds, 3),
        "seconds_per_100_frames_per_person": round(fit.seconds * 100.0 / (frames * persons), 3),
        "device": str(model.v_template.device),
        "threads": settings.threads if model.v_template.device.type == "cpu" else None,
        "settings": asdict(settings),
    }


def body_outputs(
    folder: str | Path,
    model: BodyModel | None,
    *,
    settings: FitSettings | None = None,
    viewer: bool = True,
) -> dict[str, Path]:
    """Write a sample folder's body files (module docstring) -> {kind: path}."""
    from intermask.render.html_viewer import ViewerSample, write_html_viewer

    folder = Path(folder)
    settings = settings or FitSettings()
    joints, features, record = _load(folder)
    fps = sample_fps(record)
    paths: dict[str, Path] = {}
    if model is None:
        characters = limb_characters(features, fps)
    else:
        device, dtype = model.v_template.device, model.v_template.dtype
        target = torch.from_numpy(joints).permute(1, 0, 2, 3).to(device=device, dtype=dtype)
        feature_tensor = torch.from_numpy(features).to(device=device, dtype=dtype)
        started = time.perf_counter()
        fit = fit_bodies(model, target, feature_tensor, settings=settings)
        for k, path in enumerate(write_amass(fit.params, model, folder, fps=fps)):
            paths[f"npz{k + 1}"] = path
        report = fit_report(fit, model, settings=settings)
        report["seconds_with_io"] = round(time.perf_counter() - started, 3)
        paths["fit"] = folder / "body_fit.json"
        paths["fit"].write_text(json.dumps(report, indent=2) + "\n")
        characters = body_characters(model, fit.params)
    paths["glb"] = write_glb(characters, folder / "bodies.glb", fps=fps)
    if viewer:
        reference = 0 if record.get("mode") == "reaction" else None
        paths["html"] = write_html_viewer(
            [
                ViewerSample(
                    name=folder.name,
                    caption=record.get("caption") or "(no text)",
                    joints=joints,
                    fps=fps,
                    reference_person=reference,
                    characters=characters,
                )
            ],
            folder / "viewer.html",
        )
    return paths
