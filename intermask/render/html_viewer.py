"""A self-contained HTML viewer: one file, no network, its 3D drawing in plain JS on a canvas.

The template (``viewer_template.html`` beside this module, shipped in the wheel as package data)
holds the page and its script; this module fills in the samples as JSON, joints as integer
millimetres (a 4 s two-person clip at 30 fps is about 100 kB). The page plays, pauses, scrubs,
changes speed, orbits (mouse drag) and zooms (wheel) a perspective camera, and switches between
samples. It reports the frame it shows in ``<body data-frame>`` and the number of frames it has
drawn in ``data-frames-drawn``, which is what the headless-browser test reads.
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
from intermask.render.projection import VIEWS, UpAxis, prepare_joints

TEMPLATE = "viewer_template.html"
DATA_MARK = "/*__INTERMASK_DATA__*/null"
TITLE_MARK = "__INTERMASK_TITLE__"
FOV_DEG = 40.0


@dataclass(frozen=True)
class ViewerSample:
    """One interaction shown in the viewer.

    joints: (T, P, 22, 3) or (T, 22, 3) positions in metres (numpy or torch), Y-up unless
    up_axis="z"; reference_person: reaction mode, that person drawn grey and dashed.
    """

    name: str
    caption: str
    joints: object
    fps: float = float(interhuman.FPS)
    reference_person: int | None = None
    up_axis: UpAxis = "y"


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
    return {
        "name": sample.name,
        "caption": sample.caption,
        "fps": float(sample.fps),
        "frames": int(frames),
        "persons": int(persons),
        "reference": sample.reference_person,
        "joints": millimetres.reshape(-1).tolist(),
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
