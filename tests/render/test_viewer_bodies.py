"""The HTML viewer with meshes: fitted stand-in bodies of the synthetic handshake, skinned and
rasterised by the page itself in headless Chromium."""

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from devtools_pipe import Chromium
from PIL import Image
from render_helpers import color_pixels

from intermask.body.export import body_characters
from intermask.body.fit import fit_bodies
from intermask.body.model import load_body_model
from intermask.body.standin import write_standin_model
from intermask.render import DEFAULT_STYLE, ViewerSample, viewer_html, write_html_viewer

CHROMIUM = Path("/usr/bin/chromium")


@pytest.fixture(scope="module")
def bodies(synth_clip, tmp_path_factory: pytest.TempPathFactory):
    model = load_body_model(write_standin_model(tmp_path_factory.mktemp("standin"), "smplx"))
    fit = fit_bodies(model, synth_clip.positions.float())
    return body_characters(model, fit.params)


@pytest.fixture(scope="module")
def page(clip_joints, bodies, tmp_path_factory: pytest.TempPathFactory) -> Path:
    samples = [
        ViewerSample(
            name="bodies",
            caption="Two bodies shake hands.",
            joints=clip_joints,
            fps=30,
            characters=bodies,
        ),
        ViewerSample(name="sticks", caption="Sticks only.", joints=clip_joints, fps=30),
    ]
    return write_html_viewer(samples, tmp_path_factory.mktemp("viewer") / "viewer.html")


def test_meshes_are_embedded_as_integers(clip_joints, bodies):
    html = viewer_html([ViewerSample("a", "", clip_joints, characters=bodies)])
    assert '"bodies":[{"parents":[-1,0,0,0,1' in html and '"bodies":null' not in html
    with pytest.raises(ValueError, match=r"ViewerSample 0 \('b'\): 1 characters for 2 persons"):
        viewer_html([ViewerSample("b", "", clip_joints, characters=bodies[:1])])
    with pytest.raises(ValueError, match=r"character 'person1' has 132 frames, the joints 10"):
        viewer_html([ViewerSample("c", "", clip_joints[:10], characters=bodies)])


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Chromium]:
    if not CHROMIUM.exists():
        pytest.skip(
            "/usr/bin/chromium is absent (Debian's chromium package; .ci/run installs it as root)"
        )
    with Chromium(CHROMIUM, tmp_path_factory.mktemp("chromium") / "profile") as chromium:
        yield chromium


def shot(browser: Chromium, path: Path) -> Image.Image:
    with Image.open(browser.screenshot(path)) as image:
        return image.convert("RGB")


def hue_pixels(image: Image.Image, channel: int) -> int:
    """Pixels whose `channel` clearly dominates: a shaded person colour at any lighting."""
    array = np.asarray(image, dtype=np.int64)
    others = [array[..., k] for k in range(3) if k != channel]
    main = array[..., channel]
    return int(((main > 60) & (main > 1.35 * others[0]) & (main > 1.35 * others[1])).sum())


def test_chromium_draws_the_meshes_and_toggles_the_skeleton(browser, page, tmp_path):
    browser.open(page.as_uri())
    browser.wait_for("Number(document.body.dataset.meshFramesDrawn) >= 5")
    first = int(browser.evaluate("document.body.dataset.frame"))
    browser.wait_for(f"Number(document.body.dataset.frame) > {first}")  # mesh frames keep coming
    data = browser.evaluate("Object.assign({}, document.body.dataset)")
    assert "error" not in data, data
    assert data["meshes"] == "1" and not browser.evaluate(
        "document.getElementById('skeleton-label').hidden"
    )
    browser.evaluate("document.getElementById('play').click()")  # pause: compare one frame
    bodies = shot(browser, tmp_path / "bodies.png")
    assert hue_pixels(bodies, 0) > 1500 and hue_pixels(bodies, 2) > 1500  # two shaded bodies
    red, blue = DEFAULT_STYLE.person_colors[:2]
    browser.evaluate("document.getElementById('skeleton').click()")
    browser.wait_for("document.body.dataset.skeleton === '1'")
    time_to_draw = "Number(document.body.dataset.meshFramesDrawn) > " + data["meshFramesDrawn"]
    browser.wait_for(time_to_draw)
    both = shot(browser, tmp_path / "bodies_and_skeleton.png")
    assert (
        color_pixels(both, red, 2) + color_pixels(both, blue, 2)
        > color_pixels(bodies, red, 2) + color_pixels(bodies, blue, 2) + 300
    )


def test_chromium_sample_without_meshes_draws_sticks(browser, page):
    browser.open(page.as_uri() + "#sample=sticks")
    browser.wait_for(
        "document.body.dataset.sample === '1' && Number(document.body.dataset.framesDrawn) >= 2"
    )
    data = browser.evaluate("Object.assign({}, document.body.dataset)")
    assert data["meshes"] == "0" and data["meshFramesDrawn"] == "0" and "error" not in data
    assert browser.evaluate("document.getElementById('skeleton-label').hidden")
