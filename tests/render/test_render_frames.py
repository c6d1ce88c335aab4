import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image
from render_helpers import color_pixels

from intermask.render import (
    DEFAULT_STYLE,
    quantize_exact,
    render_frames,
    save_gif,
    save_mp4,
    style_palette,
    write_gif,
    write_mp4,
)

RED, BLUE = DEFAULT_STYLE.person_colors[:2]
GREY = DEFAULT_STYLE.reference_color


@pytest.fixture(scope="module")
def short(clip_joints: np.ndarray) -> np.ndarray:
    return clip_joints[::6]  # 22 frames spanning the whole handshake


def test_frames_count_size_and_both_person_colours(short):
    images = render_frames(short, caption="two people shake hands", size=(200, 150))
    assert len(images) == short.shape[0]
    assert all(image.size == (200, 150) and image.mode == "RGB" for image in images)
    red, blue = color_pixels(images[10], RED, 0), color_pixels(images[10], BLUE, 0)
    assert red > 40 and blue > 40, (red, blue)
    # left limbs use the darker shade of the same colour
    assert color_pixels(images[10], tuple(int(c * DEFAULT_STYLE.left_shade) for c in RED), 0) > 10


def test_side_view_keeps_person_one_on_the_left_when_persons_swap(short):
    for joints in (short[:1], short[:1, ::-1]):
        image = np.asarray(render_frames(joints, size=(240, 160))[0])
        red_columns = np.nonzero((image == RED).all(-1))[1]
        blue_columns = np.nonzero((image == BLUE).all(-1))[1]
        # the camera is framed on the pair axis, so person 1 (red) is left whoever they are
        assert red_columns.mean() < 120 < blue_columns.mean()


def test_several_views_are_tiled_side_by_side(short):
    images = render_frames(short[:2], size=(160, 120), view=["side", "top", "oblique"])
    assert images[0].size == (480, 120)
    for panel in range(3):
        crop = images[1].crop((160 * panel, 0, 160 * (panel + 1), 120))
        assert color_pixels(crop, RED, 0) > 5 and color_pixels(crop, BLUE, 0) > 5


def test_reaction_mode_draws_the_reference_grey_and_dashed(short):
    solid = render_frames(short[5:6], size=(240, 180))[0]
    reaction = render_frames(short[5:6], size=(240, 180), reference_person=0)[0]
    assert color_pixels(reaction, RED, 0) == 0  # person 1 is the reference now
    assert color_pixels(reaction, BLUE, 0) > 40
    grey = color_pixels(reaction, GREY, 0)
    assert 0 < grey < color_pixels(solid, RED, 0)  # dashes cover less than solid bones


def test_trails_draw_the_pelvis_path_on_the_floor(clip_joints):
    joints = clip_joints.copy()
    joints[:, :, :, 0] += np.linspace(0, 1.0, joints.shape[0])[:, None, None]  # walk sideways
    tint = tuple(
        round(c * 0.5 + b * 0.5) for c, b in zip(RED, DEFAULT_STYLE.background, strict=True)
    )
    plain = render_frames(joints[::10], size=(240, 180))[-1]
    trailed = render_frames(joints[::10], size=(240, 180), trails=True)[-1]
    assert color_pixels(plain, tint, 0) == 0 and color_pixels(trailed, tint, 0) > 20


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"size": (20, 100)}, r"size must be at least \(32, 32\) pixels, got \(20, 100\)"),
        ({"reference_person": 2}, r"reference_person must be in \[0, 1\] for 2 persons, got 2"),
        ({"fps": 0}, "fps must be > 0, got 0"),
        ({"trail_length": 0}, "trail_length must be >= 1 or None, got 0"),
    ],
)
def test_render_frames_rejects_bad_options(short, kwargs, message):
    with pytest.raises(ValueError, match=message):
        render_frames(short[:1], **kwargs)


def test_gif_frame_count_size_timing_and_exact_colours(short, tmp_path):
    path = save_gif(short, tmp_path / "clip.gif", fps=20, size=(160, 120), caption="hello")
    with Image.open(path) as gif:
        assert gif.n_frames == short.shape[0] and gif.size == (160, 120)
        assert gif.info["duration"] == 50 and gif.info["loop"] == 0
        gif.seek(10)
        frame = gif.convert("RGB")
    # the fixed palette keeps the colours exact through quantization
    assert color_pixels(frame, RED, 0) > 20 and color_pixels(frame, BLUE, 0) > 20
    assert color_pixels(frame, DEFAULT_STYLE.background, 0) > 160 * 120 // 2


def test_palette_holds_every_style_colour_and_quantization_keeps_them_exact():
    palette = style_palette(DEFAULT_STYLE)
    assert palette.shape[1] == 3 and len(palette) <= 256
    colours = {tuple(int(c) for c in row) for row in palette}
    assert {RED, BLUE, GREY, DEFAULT_STYLE.background, DEFAULT_STYLE.grid} <= colours
    pixels = np.array(
        [[DEFAULT_STYLE.background, RED, (250, 10, 10), DEFAULT_STYLE.grid]], np.uint8
    )
    quantized = np.asarray(quantize_exact(Image.fromarray(pixels), palette).convert("RGB"))
    assert [tuple(int(c) for c in p) for p in quantized[0]] == [
        DEFAULT_STYLE.background,
        RED,
        RED,  # the nearest palette colour
        DEFAULT_STYLE.grid,
    ]


def test_mp4_frame_count_and_odd_sizes_are_padded(short, tmp_path):
    path = save_mp4(short, tmp_path / "clip.mp4", fps=20, size=(161, 121))
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(path))
    assert frames == short.shape[0] and seconds == pytest.approx(short.shape[0] / 20, abs=0.06)
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    assert meta["size"] == (162, 122)
    first = np.frombuffer(next(reader), dtype=np.uint8).reshape(122, 162, 3)
    reader.close()
    # H.264 is lossy: look for the person colours within a tolerance
    assert color_pixels(first, RED, 40) > 20 and color_pixels(first, BLUE, 40) > 20


def test_writers_reject_empty_input_and_mismatched_frames(tmp_path):
    with pytest.raises(ValueError, match=r"write_gif: no frames to write to .*a\.gif"):
        write_gif([], tmp_path / "a.gif", fps=20)
    with pytest.raises(ValueError, match="write_mp4: fps must be > 0, got -1"):
        write_mp4([Image.new("RGB", (32, 32))], tmp_path / "a.mp4", fps=-1)
    frames = [Image.new("RGB", (32, 32)), Image.new("RGB", (34, 32))]
    with pytest.raises(
        ValueError, match=r"frame size \(34, 32\) differs from the first frame's \(32, 32\)"
    ):
        write_mp4(frames, tmp_path / "b.mp4", fps=20)


def test_gifs_need_no_imageio_ffmpeg_and_mp4s_name_it_when_missing(short, tmp_path, monkeypatch):
    """A device image without imageio-ffmpeg killed a training run at its first validation:
    the GIF samples imported it through this module. Only the MP4 writer may need it."""
    import sys

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # `import imageio_ffmpeg` fails
    path = write_gif(render_frames(short[:3], size=(64, 48)), tmp_path / "a.gif", fps=20)
    assert Image.open(path).n_frames == 3
    with pytest.raises(ImportError, match=r"writing .*b\.mp4 needs the imageio-ffmpeg package"):
        write_mp4([Image.new("RGB", (32, 32))], tmp_path / "b.mp4", fps=20)
