"""Skeleton frames drawn with PIL: two coloured people on a floor grid, caption, trails, views.

``render_frames`` is the one renderer behind GIF, MP4 and the TensorBoard sample callback. In
reaction mode (``reference_person`` set) the given person is the conditioning motion: drawn grey
and dashed, while the generated reaction keeps its colour.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from intermask.motion.skeleton import BONES, LEFT_JOINTS
from intermask.render.projection import (
    NEAR_PLANE,
    Camera,
    CameraPose,
    Scene,
    UpAxis,
    clip_segment,
    floor_grid,
    place_camera,
    prepare_joints,
    project,
    resolve_views,
    scene_of,
)

Color = tuple[int, int, int]
HEAD_JOINT = 15
ROOT_JOINT = 0


@dataclass(frozen=True)
class Style:
    """Colours and line widths. Person colours are indexed by person; left limbs use a darker
    shade of the same colour so that the two sides can be told apart."""

    background: Color = (247, 247, 244)
    grid: Color = (206, 208, 204)
    text: Color = (40, 40, 40)
    person_colors: tuple[Color, ...] = (
        (214, 69, 65),
        (38, 110, 196),
        (46, 158, 90),
        (150, 90, 190),
    )
    reference_color: Color = (140, 140, 140)
    shadow: Color = (222, 222, 218)
    left_shade: float = 0.72  # left-limb colour = person colour x this factor
    bone_width: int = 4
    joint_radius: int = 3
    head_radius: int = 8
    dash_length: float = 9.0  # pixels, reference person's dashes (and the gaps between them)
    font_size: int = 15


DEFAULT_STYLE = Style()
_LEFT = frozenset(LEFT_JOINTS)


def person_color(style: Style, person: int, reference_person: int | None) -> Color:
    """The main drawing colour of a person (grey for the reference in reaction mode)."""
    if reference_person is not None and person == reference_person:
        return style.reference_color
    return style.person_colors[person % len(style.person_colors)]


def _shade(color: Color, factor: float) -> Color:
    return (int(color[0] * factor), int(color[1] * factor), int(color[2] * factor))


def _tint(color: Color, background: Color, weight: float) -> Color:
    """color moved towards background by weight (0: color, 1: background)."""
    return tuple(
        int(round(c * (1 - weight) + b * weight)) for c, b in zip(color, background, strict=True)
    )  # type: ignore[return-value]


@lru_cache(maxsize=8)
def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    return ImageFont.load_default(size=size)


def _dashed(
    draw: ImageDraw.ImageDraw,
    a: np.ndarray,
    b: np.ndarray,
    *,
    color: Color,
    width: int,
    dash: float,
) -> None:
    length = float(np.hypot(*(b - a)))
    steps = max(1, int(length // (2 * dash)) + 1)
    for k in range(steps):
        start, stop = 2 * k * dash / max(length, 1e-9), (2 * k + 1) * dash / max(length, 1e-9)
        if start >= 1:
            break
        p, q = a + (b - a) * start, a + (b - a) * min(stop, 1.0)
        draw.line([tuple(p), tuple(q)], fill=color, width=width)


def _trail_points(pixels: np.ndarray, frame: int, length: int | None) -> list[tuple[float, float]]:
    first = 0 if length is None else max(0, frame - length)
    return [tuple(p) for p in pixels[first : frame + 1]]


class _ViewRenderer:
    """Draws the frames of one clip seen through one camera (static over the clip)."""

    def __init__(
        self,
        joints: np.ndarray,
        scene: Scene,
        camera: Camera,
        size: tuple[int, int],
        style: Style,
        reference_person: int | None,
    ) -> None:
        self.joints, self.style, self.reference = joints, style, reference_person
        self.pose: CameraPose = place_camera(camera, scene, size)
        self.pixels, self.depth = project(self.pose, joints)  # (T, P, 22, 2), (T, P, 22)
        floor_roots = joints[:, :, ROOT_JOINT].copy()
        floor_roots[..., 1] = scene.floor
        self.root_pixels, _ = project(self.pose, floor_roots)  # (T, P, 2) for trails
        ring = np.linspace(0, 2 * math.pi, 17)[:-1]
        self._ring = np.stack((0.22 * np.cos(ring), np.zeros_like(ring), 0.22 * np.sin(ring)), -1)
        self.floor = scene.floor
        self.background = Image.new("RGB", size, style.background)
        draw = ImageDraw.Draw(self.background)
        for start, end in floor_grid(scene):
            segment = clip_segment(self.pose, start, end)
            if segment is not None:
                draw.line([tuple(segment[0]), tuple(segment[1])], fill=style.grid, width=1)

    def draw(self, frame: int, *, trails: bool, trail_length: int | None) -> Image.Image:
        image = self.background.copy()
        draw = ImageDraw.Draw(image)
        style, persons = self.style, self.joints.shape[1]
        for person in range(persons):  # floor shadow: a disc under the pelvis
            centre = self.joints[frame, person, ROOT_JOINT] * np.array([1.0, 0.0, 1.0])
            disc = centre + self._ring + np.array([0.0, self.floor, 0.0])
            pixels, depth = project(self.pose, disc)
            if (depth > 0).all():
                draw.polygon([tuple(p) for p in pixels], fill=style.shadow)
        if trails and frame > 0:
            for person in range(persons):
                color = person_color(style, person, self.reference)
                points = _trail_points(self.root_pixels[:, person], frame, trail_length)
                draw.line(points, fill=_tint(color, style.background, 0.5), width=2)
        segments = []  # (depth, person, parent, child): painter's order, far first
        for person in range(persons):
            for parent, child in BONES:
                depth = (self.depth[frame, person, parent] + self.depth[frame, person, child]) / 2
                segments.append((depth, person, parent, child))
        segments.sort(key=lambda s: -s[0])
        for _depth, person, parent, child in segments:
            if (
                min(self.depth[frame, person, parent], self.depth[frame, person, child])
                <= NEAR_PLANE
            ):
                continue  # behind the camera: only possible with a custom zoomed-in Camera
            color = person_color(style, person, self.reference)
            if child in _LEFT:
                color = _shade(color, style.left_shade)
            a, b = self.pixels[frame, person, parent], self.pixels[frame, person, child]
            if person == self.reference:
                _dashed(draw, a, b, color=color, width=style.bone_width, dash=style.dash_length)
            else:
                draw.line([tuple(a), tuple(b)], fill=color, width=style.bone_width)
            radius = style.head_radius if child == HEAD_JOINT else style.joint_radius
            u, v = b
            draw.ellipse([u - radius, v - radius, u + radius, v + radius], fill=color)
        return image


def _legend(persons: int, reference_person: int | None) -> list[str]:
    if reference_person is None:
        return [f"person {p + 1}" for p in range(persons)]
    return ["reference" if p == reference_person else "reaction" for p in range(persons)]


def _overlay(
    image: Image.Image,
    *,
    caption: str,
    labels: Sequence[tuple[int, str]],
    frame: int,
    fps: float,
    legend: list[tuple[str, Color]],
    style: Style,
) -> None:
    draw = ImageDraw.Draw(image)
    font = _font(style.font_size)
    small = _font(max(10, style.font_size - 3))
    if caption:
        chars = max(20, int(image.width / (0.55 * style.font_size)))
        for row, line in enumerate(textwrap.wrap(caption, chars)[:3]):
            draw.text((10, 8 + row * (style.font_size + 4)), line, fill=style.text, font=font)
    for left, label in labels:
        draw.text((left + 10, image.height - 22), label, fill=style.text, font=small)
    stamp = f"{frame / fps:5.2f} s  #{frame}"
    draw.text(
        (image.width - 10, image.height - 22), stamp, fill=style.text, font=small, anchor="ra"
    )
    y = image.height - 44
    for name, color in reversed(legend):  # person 1 on top
        draw.rectangle([image.width - 110, y + 3, image.width - 98, y + 15], fill=color)
        draw.text((image.width - 92, y), name, fill=style.text, font=small)
        y -= 18


def render_frames(
    joints: object,
    *,
    caption: str = "",
    size: tuple[int, int] = (480, 360),
    view: str | Camera | Sequence[str | Camera] = "side",
    trails: bool = False,
    trail_length: int | None = None,
    reference_person: int | None = None,
    fps: float = 20.0,
    up_axis: UpAxis = "y",
    style: Style = DEFAULT_STYLE,
) -> list[Image.Image]:
    """Draw every frame of an interaction.

    joints: (T, P, 22, 3) or (T, 22, 3) positions in metres (numpy or torch), Y-up unless
        up_axis="z".
    size: (width, height) of one view panel; several views are laid side by side, so the image is
        (width * number of views, height).
    view: a preset name ("side", "oblique", "along", "top"), a Camera, or a sequence of them.
    trails: draw each person's pelvis path on the floor, the last trail_length frames (None: all).
    reference_person: reaction mode; that person is drawn grey and dashed.
    fps: only for the time stamp.
    Returns T RGB images.
    """
    positions = prepare_joints(joints, up_axis=up_axis)
    frames, persons = positions.shape[:2]
    width, height = size
    if width < 32 or height < 32:
        raise ValueError(f"render_frames: size must be at least (32, 32) pixels, got {size}")
    if reference_person is not None and not 0 <= reference_person < persons:
        raise ValueError(
            f"render_frames: reference_person must be in [0, {persons - 1}] for {persons} persons, "
            f"got {reference_person}"
        )
    if fps <= 0:
        raise ValueError(f"render_frames: fps must be > 0, got {fps}")
    if trail_length is not None and trail_length < 1:
        raise ValueError(f"render_frames: trail_length must be >= 1 or None, got {trail_length}")
    views = resolve_views(view)
    scene = scene_of(positions)
    renderers = [
        _ViewRenderer(positions, scene, camera, size, style, reference_person)
        for _, camera in views
    ]
    legend = [
        (name, person_color(style, p, reference_person))
        for p, name in enumerate(_legend(persons, reference_person))
    ]
    labels = [(k * width, label) for k, (label, _) in enumerate(views)] if len(views) > 1 else []
    images = []
    for frame in range(frames):
        panels = [r.draw(frame, trails=trails, trail_length=trail_length) for r in renderers]
        if len(panels) == 1:
            image = panels[0]
        else:
            image = Image.new("RGB", (width * len(panels), height), style.background)
            for k, panel in enumerate(panels):
                image.paste(panel, (k * width, 0))
        _overlay(
            image, caption=caption, labels=labels, frame=frame, fps=fps, legend=legend, style=style
        )
        images.append(image)
    return images
