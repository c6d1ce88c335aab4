import re
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from devtools_pipe import Chromium
from PIL import Image
from render_helpers import color_pixels

from intermask.render import DEFAULT_STYLE, ViewerSample, viewer_html, write_html_viewer

CHROMIUM = Path("/usr/bin/chromium")


@pytest.fixture(scope="module")
def page(clip_joints: np.ndarray, tmp_path_factory: pytest.TempPathFactory) -> Path:
    samples = [
        ViewerSample(
            name="handshake", caption="Two people shake hands.", joints=clip_joints, fps=30
        ),
        ViewerSample(
            name="reaction",
            caption="A reaction </script> to <b>person 1</b>",
            joints=clip_joints[:60],
            fps=30,
            reference_person=0,
        ),
    ]
    return write_html_viewer(samples, tmp_path_factory.mktemp("viewer") / "viewer.html")


def test_page_is_one_self_contained_file(page):
    text = page.read_text(encoding="utf-8")
    assert not re.search(r"https?:", text, flags=re.IGNORECASE)
    assert not re.search(
        r"<(script|link|img|iframe)[^>]*\b(src|href)\s*=", text, flags=re.IGNORECASE
    )
    assert "@import" not in text and "url(" not in text
    assert text.count("<script>") == 1
    # the caption's markup cannot close the script element; it arrives escaped as data
    assert "</script> to" not in text and "\\u003c/script\\u003e to" in text
    assert "/*__INTERMASK_DATA__*/" not in text and "__INTERMASK_TITLE__" not in text


def test_joints_are_embedded_in_millimetres(clip_joints):
    html = viewer_html([ViewerSample(name="a", caption="", joints=clip_joints[:2], fps=20)])
    data = re.search(r'"joints":\[([-\d,]+)\]', html)
    assert data is not None
    values = np.array([int(v) for v in data.group(1).split(",")])
    np.testing.assert_array_equal(values, np.rint(clip_joints[:2] * 1000).reshape(-1))


@pytest.mark.parametrize(
    ("samples", "message"),
    [
        ([], "expected at least one ViewerSample, got none"),
        (
            [
                ViewerSample("a", "", np.zeros((3, 2, 22, 3))),
                ViewerSample("a", "", np.zeros((3, 2, 22, 3))),
            ],
            "sample names must be unique; repeated: a",
        ),
        (
            [ViewerSample("b", "", np.zeros((3, 2, 22, 3)), fps=0)],
            r"ViewerSample 0 \('b'\): fps must be > 0",
        ),
        (
            [ViewerSample("c", "", np.zeros((3, 2, 22, 3)), reference_person=3)],
            r"ViewerSample 0 \('c'\): reference_person must be in \[0, 1\], got 3",
        ),
        (
            [ViewerSample("d", "", np.zeros((3, 2, 21, 3)))],
            r"ViewerSample 0 \('d'\) joints: expected shape",
        ),
    ],
)
def test_viewer_rejects_bad_samples(samples, message):
    with pytest.raises(ValueError, match=message):
        viewer_html(samples)


@pytest.fixture(scope="module")
def browser(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Chromium]:
    if not CHROMIUM.exists():
        pytest.skip(
            "/usr/bin/chromium is absent (Debian's chromium package; .ci/run installs it as root)"
        )
    with Chromium(CHROMIUM, tmp_path_factory.mktemp("chromium") / "profile") as chromium:
        yield chromium


def body_data(browser: Chromium) -> dict[str, str]:
    return browser.evaluate("Object.assign({}, document.body.dataset)")


def test_chromium_plays_the_page_and_screenshots_both_people(browser, page, tmp_path):
    browser.open(page.as_uri())
    browser.wait_for("Number(document.body.dataset.framesDrawn) >= 5")
    first = int(body_data(browser)["frame"])
    # frames advance by themselves
    browser.wait_for(f"Number(document.body.dataset.frame) > {first}")
    data = body_data(browser)
    assert "error" not in data, data
    assert int(data["frame"]) > first and data["sample"] == "0"
    assert (
        browser.evaluate("document.getElementById('caption').textContent")
        == "Two people shake hands."
    )
    shot = browser.screenshot(tmp_path / "viewer.png")
    with Image.open(shot) as image:
        screenshot = image.convert("RGB")
    red, blue = DEFAULT_STYLE.person_colors[:2]
    assert color_pixels(screenshot, red) > 200 and color_pixels(screenshot, blue) > 200


def test_chromium_pause_scrub_speed_and_orbit(browser, page):
    browser.open(page.as_uri())
    browser.wait_for("Number(document.body.dataset.framesDrawn) >= 2")
    browser.evaluate("document.getElementById('play').click()")
    assert browser.evaluate("document.getElementById('play').textContent") == "Play"
    paused = body_data(browser)["frame"]
    time.sleep(0.2)
    assert body_data(browser)["frame"] == paused
    browser.evaluate(
        "const s = document.getElementById('scrub'); s.value = '100';"
        "s.dispatchEvent(new Event('input'))"
    )
    assert body_data(browser)["frame"] == "100"
    status = browser.evaluate("document.getElementById('status').textContent")
    assert status.startswith("frame 101 / 132")
    azimuth = float(body_data(browser)["azimuth"])
    box = browser.evaluate(
        "(() => { const r = document.getElementById('view').getBoundingClientRect();"
        " return [r.left + r.width / 2, r.top + r.height / 2]; })()"
    )
    browser.drag((box[0], box[1]), (box[0] + 150, box[1] + 40))
    browser.wait_for(f"Number(document.body.dataset.azimuth) !== {azimuth}")
    data = body_data(browser)
    assert float(data["azimuth"]) == pytest.approx(azimuth - 0.4 * 150, abs=0.5)
    assert float(data["elevation"]) > 15.0 and data["frame"] == "100"  # orbiting keeps the frame
    browser.evaluate(
        "const v = document.getElementById('speed'); v.value = '2'; v.dispatchEvent(new Event('change'));"
        "document.getElementById('play').click()"
    )
    browser.wait_for("document.body.dataset.frame !== '100'")  # playing again


def test_chromium_switches_samples_and_opens_one_by_name(browser, page):
    browser.open(page.as_uri() + "#sample=reaction")
    browser.wait_for("document.body.dataset.sample === '1'")
    legend = browser.evaluate("document.getElementById('legend').textContent")
    assert legend == "referencereaction"
    caption = browser.evaluate("document.getElementById('caption').textContent")
    assert caption == "A reaction </script> to <b>person 1</b>"  # shown as text, not markup
    browser.evaluate(
        "const s = document.getElementById('sample'); s.value = '0'; s.dispatchEvent(new Event('change'))"
    )
    assert body_data(browser)["sample"] == "0"
    assert browser.evaluate("document.getElementById('legend').textContent") == "person 1person 2"
    assert "error" not in body_data(browser)
