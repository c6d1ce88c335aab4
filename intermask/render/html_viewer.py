"""A self-contained HTML viewer: one file, no network, its 3D drawing in plain JS on a canvas.

The template (``viewer_template.html`` beside this module, shipped in the wheel as package data)
holds the page and its script; this module fills in the samples as JSON, joints as integer
millimetres (a 4 s two-person clip at 30 fps is about 100 kB). The page plays, pauses, scrubs,
changes speed, orbits (mouse drag) and zooms (wheel) a perspective camera, and switches between
samples. It reports the frame it shows in ``<body data-frame>`` and the number of frames it has
drawn in ``data-frames-drawn``, which is what the headless-browser test reads.

A sample may carry meshes (``ViewerSample.characters``: fitted bodies or limb meshes, the
:class:`intermask.render.gltf.Character` of the .glb export). The page then skins them itself
each frame (linear blend skinning of the rest mesh by the joints' rotations, as glTF does) and
draws them with a small z-buffer rasteriser into the canvas, flat-shaded, so interpenetration
shows as it is; the skeleton becomes a toggle. It counts drawn mesh frames in
``data-mesh-frames-drawn``. Embedded as integers: millimetres, quaternions and weights x 10^4.
"""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from intermask.motion import interhuman
from intermask.motion.skeleton import LEFT_JOINTS, PARENTS
from intermask.render.frames import DEFAULT_STYLE, HEAD_JOINT, Style
from intermask.render.gltf import Character, continuous_quaternions, top_weights
from intermask.render.projection import VIEWS, UpAxis, prepare_joints

TEMPLATE = "viewer_template.html"
DATA_MARK = "/*__INTERMASK_DATA__*/null"
TITLE_MARK = "__INTERMASK_TITLE__"
FOV_DEG = 40.0


@dataclass(frozen=True)
class ViewerSample:
    """One interaction shown in the viewer.

    joints: (T, P, 22, 3) or (T, 22, 3) positions in metres (numpy or torch), Y-up unless
    up_axis="z"; reference_person: reaction mode, that person drawn grey and dashed;
    characters: None, or one mesh per person (Y up, the joints' frames) drawn instead of the
    sticks.
    """

    name: str
    caption: str
    joints: object
    fps: float = float(interhuman.FPS)
    reference_person: int | None = None
    up_axis: UpAxis = "y"
    characters: Sequence[Character] | None = None


_FIXED = 10000  # quaternions and weights as integers x 10^4


def _mesh_payload(
    characters: Sequence[Character], frames: int, persons: int, where: str
) -> list[dict[str, object]]:
    if len(characters) != persons:
        raise ValueError(f"{where}: {len(characters)} characters for {persons} persons")
    bodies = []
    for character in characters:
        if character.rotations.shape[0] != frames:
            raise ValueError(
                f"{where}: character {character.name!r} has {character.rotations.shape[0]} frames, "
                f"the joints {frames}"
            )
        joints, weights = top_weights(character.weights)

        def millimetres(x: np.ndarray) -> list[int]:
            return np.rint(np.asarray(x) * 1000.0).astype(np.int64).reshape(-1).tolist()

        bodies.append(
            {
                "parents": list(character.parents),
                "rest": millimetres(character.rest_joints),
                "vertices": millimetres(character.vertices),
                "faces": character.faces.astype(np.int64).reshape(-1).tolist(),
                "skin": joints.astype(np.int64).reshape(-1).tolist(),
                "weights": np.rint(weights * _FIXED).astype(np.int64).reshape(-1).tolist(),
                "rotations": np.rint(continuous_quaternions(character.rotations) * _FIXED)
                .astype(np.int64)
                .reshape(-1)
                .tolist(),
                "root": millimetres(character.root_positions),
            }
        )
    return bodies


def _sample_payload(sample: ViewerSample, index: int) -> dict[str, object]:
    where = f"ViewerSample {index} ({sample.name!r})"
    joints = prepare_joints(sample.joints, up_axis=sample.up_axis, name=f"{where} joints")
    frames, persons = joints.shape[:2]
    if sample.fps <= 0:
        raise ValueError(f"{where}: fps must be > 0, got {sample.fps}")
    if sample.reference_person is not None and not 0 <= sample.reference_person < persons:
        raise ValueError(
            f"{where}: reference_person must be in [0, {persons - 1}], got {sample.reference_person}"
        )
    millimetres = np.rint(joints * 1000.0).astype(np.int64)
    bodies = (
        None
        if sample.characters is None
        else _mesh_payload(sample.characters, int(frames), int(persons), where)
    )
    return {
        "name": sample.name,
        "caption": sample.caption,
        "fps": float(sample.fps),
        "frames": int(frames),
        "persons": int(persons),
        "reference": sample.reference_person,
        "joints": millimetres.reshape(-1).tolist(),
        "bodies": bodies,
    }


def _script_json(payload: object) -> str:
    """JSON that is safe inside a <script> element: no '</script>', no HTML comment openers."""
    text = json.dumps(payload, separators=(",", ":"), ensure_ascii=True)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def viewer_html(
    samples: Sequence[ViewerSample],
    *,
    title: str = "InterMask interactions",
    style: Style = DEFAULT_STYLE,
) -> str:
    """The viewer page for one or more samples, as a string."""
    if not samples:
        raise ValueError("viewer_html: expected at least one ViewerSample, got none")
    names = [s.name for s in samples]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise ValueError(
            f"viewer_html: sample names must be unique; repeated: {', '.join(duplicates)}"
        )
    payload = {
        "title": title,
        "parents": list(PARENTS),
        "left": list(LEFT_JOINTS),
        "head": HEAD_JOINT,
        "fov": FOV_DEG,
        "views": {name: [c.azimuth_deg, c.elevation_deg] for name, c in VIEWS.items()},
        "style": {
            "background": list(style.background),
            "grid": list(style.grid),
            "shadow": list(style.shadow),
            "persons": [list(c) for c in style.person_colors],
            "reference": list(style.reference_color),
            "left_shade": style.left_shade,
        },
        "samples": [_sample_payload(sample, k) for k, sample in enumerate(samples)],
    }
    template = resources.files("intermask.render").joinpath(TEMPLATE).read_text(encoding="utf-8")
    if DATA_MARK not in template:
        raise RuntimeError(f"the viewer template {TEMPLATE} lost its data marker {DATA_MARK}")
    page = template.replace(TITLE_MARK, html.escape(title))
    return page.replace(DATA_MARK, _script_json(payload))


def write_html_viewer(
    samples: Sequence[ViewerSample],
    path: str | Path,
    *,
    title: str = "InterMask interactions",
    style: Style = DEFAULT_STYLE,
) -> Path:
    """Write the viewer page for samples to path (one file, opens offline in any browser)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(viewer_html(samples, title=title, style=style), encoding="utf-8")
    return path
