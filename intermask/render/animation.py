"""GIF and MP4 files of rendered interactions.

GIFs are written by Pillow with one fixed palette built from the style, each frame mapped onto it
exactly (PaletteMapper), so the colours stay exact in every frame (Pillow's per-frame adaptive
palette would shift them, and its fixed-palette lookup rounds).
MP4s go through the ffmpeg binary that ships inside the ``imageio-ffmpeg`` wheel (H.264, yuv420p;
no system ffmpeg is needed). It is imported when an MP4 is written, not with this module: GIFs,
TensorBoard samples and training never need it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from intermask.render.frames import DEFAULT_STYLE, Color, Style, render_frames
from intermask.render.projection import Camera, UpAxis

_BLENDS = (
    0.25,
    0.5,
    0.75,
)  # anti-aliased text and tinted trails fall between a colour and the background
_GREY_LEVELS = 24


def _mix(a: Color, b: Color, weight: float) -> Color:
    return tuple(int(round(a[k] * (1 - weight) + b[k] * weight)) for k in range(3))  # type: ignore[return-value]


def style_palette(style: Style) -> np.ndarray:
    """(K, 3) uint8 colours, K <= 254: every colour the renderer draws, blends towards the
    background (anti-aliased text, tinted trails) and a grey ramp for anything else."""
    base: list[Color] = [
        style.background,
        style.grid,
        style.text,
        style.shadow,
        style.reference_color,
    ]
    for color in style.person_colors:
        base += [color, tuple(int(c * style.left_shade) for c in color)]  # type: ignore[list-item]
    base.append(tuple(int(c * style.left_shade) for c in style.reference_color))  # type: ignore[arg-type]
    colors = list(base)
    for color in base:
        colors += [_mix(color, style.background, w) for w in _BLENDS]
    colors += [(v, v, v) for v in np.linspace(0, 255, _GREY_LEVELS).astype(int).tolist()]
    return np.array(list(dict.fromkeys(colors))[:254], dtype=np.uint8)


class PaletteMapper:
    """Maps RGB images onto a fixed palette (K <= 255, 3): palette colours map to themselves
    exactly, any other colour to the nearest palette colour.

    Pillow's own palette quantization looks colours up in a reduced-precision cache and can move
    an exact palette colour (the background, say) to a neighbouring entry. Here a 2^24-entry table
    (16 MiB) remembers the index of every colour met so far, so after the first frame almost
    every pixel is one table lookup.
    """

    _UNSEEN = 255

    def __init__(self, palette: np.ndarray) -> None:
        if palette.ndim != 2 or palette.shape[1] != 3 or not 1 <= len(palette) < self._UNSEEN:
            raise ValueError(
                f"PaletteMapper: expected (K, 3) colours with 1 <= K <= 254, got {palette.shape}"
            )
        self.colors = palette.astype(np.int64)
        self.table = np.full(1 << 24, self._UNSEEN, dtype=np.uint8)
        keys = (self.colors[:, 0] << 16) | (self.colors[:, 1] << 8) | self.colors[:, 2]
        self.table[keys[::-1]] = np.arange(len(palette))[::-1]  # the first of duplicates wins
        flat = palette.astype(np.uint8).reshape(-1).tolist()
        self.flat_palette = flat + flat[:3] * (256 - len(palette))

    def __call__(self, image: Image.Image) -> Image.Image:
        pixels = np.asarray(image.convert("RGB"))
        keys = (pixels[..., 0].astype(np.uint32) << 16) | (pixels[..., 1].astype(np.uint32) << 8)
        keys |= pixels[..., 2]
        indices = self.table[keys]
        unseen = indices == self._UNSEEN
        if unseen.any():  # anti-aliased text edges of the first frames
            new_keys = np.unique(keys[unseen])
            rgb = np.stack((new_keys >> 16, (new_keys >> 8) & 255, new_keys & 255), -1).astype(
                np.int64
            )
            distance = ((rgb[:, None, :] - self.colors[None]) ** 2).sum(-1)
            self.table[new_keys] = distance.argmin(-1).astype(np.uint8)
            indices = self.table[keys]
        result = Image.fromarray(indices, mode="P")
        result.putpalette(self.flat_palette)
        return result


def quantize_exact(image: Image.Image, palette: np.ndarray) -> Image.Image:
    """One RGB image -> a "P" image on palette (K, 3), see PaletteMapper."""
    return PaletteMapper(palette)(image)


def write_gif(
    images: Sequence[Image.Image], path: str | Path, *, fps: float, style: Style = DEFAULT_STYLE
) -> Path:
    """Write RGB images as a looping GIF. GIF delays are whole centiseconds, so the played rate
    is 100 / round(100 / fps) frames per second (20 fps is exact, 30 fps plays at 33.3)."""
    if not images:
        raise ValueError(f"write_gif: no frames to write to {path}")
    if fps <= 0:
        raise ValueError(f"write_gif: fps must be > 0, got {fps}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    mapper = PaletteMapper(style_palette(style))
    frames = [mapper(image) for image in images]
    duration = 10 * max(1, round(100 / fps))  # milliseconds, a multiple of 10
    frames[0].save(
        path,
        save_all=True,
        append_images=frames[1:],
        duration=duration,
        loop=0,
        optimize=False,
        disposal=1,
    )
    return path


def write_mp4(
    images: Sequence[Image.Image], path: str | Path, *, fps: float, quality: float = 7.0
) -> Path:
    """Write RGB images as an H.264 MP4 (quality 0..10, imageio-ffmpeg's scale).

    yuv420p needs even sizes: odd widths or heights are padded by one pixel of the image's own
    border colour instead of letting ffmpeg rescale the frame.
    """
    if not images:
        raise ValueError(f"write_mp4: no frames to write to {path}")
    if fps <= 0:
        raise ValueError(f"write_mp4: fps must be > 0, got {fps}")
    try:
        import imageio_ffmpeg
    except ImportError as error:
        raise ImportError(
            f"write_mp4: writing {path} needs the imageio-ffmpeg package (a dependency of this "
            "project: `make install`, or `pip install imageio-ffmpeg`); GIFs do not need it"
        ) from error
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    width, height = images[0].size
    padded = (width + width % 2, height + height % 2)
    writer = imageio_ffmpeg.write_frames(
        str(path),
        padded,
        fps=fps,
        codec="libx264",
        quality=quality,
        macro_block_size=1,
        pix_fmt_out="yuv420p",
    )
    writer.send(None)  # start the ffmpeg process
    try:
        for image in images:
            if image.size != (width, height):
                raise ValueError(
                    f"write_mp4: frame size {image.size} differs from the first frame's {(width, height)}"
                )
            frame = np.asarray(image.convert("RGB"))
            if padded != (width, height):
                frame = np.pad(
                    frame, ((0, padded[1] - height), (0, padded[0] - width), (0, 0)), mode="edge"
                )
            writer.send(np.ascontiguousarray(frame))
    finally:
        writer.close()
    return path


def save_gif(
    joints: object,
    path: str | Path,
    *,
    fps: float = 20.0,
    caption: str = "",
    size: tuple[int, int] = (480, 360),
    view: str | Camera | Sequence[str | Camera] = "side",
    trails: bool = False,
    trail_length: int | None = None,
    reference_person: int | None = None,
    up_axis: UpAxis = "y",
    style: Style = DEFAULT_STYLE,
) -> Path:
    """Render (T, P, 22, 3) joints (see render_frames) and write them as a GIF played at fps."""
    images = render_frames(
        joints,
        caption=caption,
        size=size,
        view=view,
        trails=trails,
        trail_length=trail_length,
        reference_person=reference_person,
        fps=fps,
        up_axis=up_axis,
        style=style,
    )
    return write_gif(images, path, fps=fps, style=style)


def save_mp4(
    joints: object,
    path: str | Path,
    *,
    fps: float = 20.0,
    caption: str = "",
    size: tuple[int, int] = (480, 360),
    view: str | Camera | Sequence[str | Camera] = "side",
    trails: bool = False,
    trail_length: int | None = None,
    reference_person: int | None = None,
    up_axis: UpAxis = "y",
    style: Style = DEFAULT_STYLE,
    quality: float = 7.0,
) -> Path:
    """Render (T, P, 22, 3) joints (see render_frames) and write them as an MP4 at fps."""
    images = render_frames(
        joints,
        caption=caption,
        size=size,
        view=view,
        trails=trails,
        trail_length=trail_length,
        reference_person=reference_person,
        fps=fps,
        up_axis=up_axis,
        style=style,
    )
    return write_mp4(images, path, fps=fps, quality=quality)
