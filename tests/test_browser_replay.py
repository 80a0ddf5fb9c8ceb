"""The replay a person opens: render replay.html in headless Chromium and look at the pixels.

Needs Debian's chromium (``apt-get install chromium``; `.ci/run` installs it) and the Python
``playwright`` package (test extra; it drives the system browser, no browser download).
"""

import io

import numpy as np
import pytest
from _browser import ARGS, BROWSER_TEST, CHROMIUM

from usvdrake import load_scenario, run_mission

pytestmark = BROWSER_TEST


def test_replay_renders_the_canal_and_the_vessel(tmp_path):
    sync_api = pytest.importorskip("playwright.sync_api")
    from matplotlib.image import imread

    run_mission(load_scenario("canal_demo"), out_dir=tmp_path)
    errors = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_page(viewport={"width": 900, "height": 600})
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto((tmp_path / "replay.html").as_uri())
        page.wait_for_selector("canvas", timeout=30_000)
        page.wait_for_timeout(4000)  # let the scene load and the animation start
        png = page.screenshot()
        (tmp_path / "replay.png").write_bytes(png)
        legend = page.locator("#usv-legend").inner_text()
        overlay = page.locator("#usv-overlay").bounding_box()
        clock = page.locator("#usv-clock").inner_text()
        browser.close()
    assert not errors, errors
    img = imread(io.BytesIO(png), format="png")[..., :3]
    # not a blank page: many distinct colours, and the canal's water blue is on screen
    assert img.std() > 0.05
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    water = (b > 0.3) & (b > r + 0.1) & (b > g)
    assert water.mean() > 0.01, f"water covers only {water.mean():.3%} of the view"
    assert len(np.unique((img * 15).astype(int).reshape(-1, 3), axis=0)) > 20

    # the legend overlay explains the drawn lines, and the clock runs with the replay
    assert "path sailed" in legend and "planned route" in legend and "thrust" in legend, legend
    assert clock.startswith("t = ") and "speed" in clock and "m/s" in clock, clock
    x0, y0 = int(overlay["x"]), int(overlay["y"])
    x1, y1 = x0 + int(overlay["width"]), y0 + int(overlay["height"])
    assert overlay["width"] > 100 and overlay["height"] > 50
    panel = img[y0 + 2 : y1 - 2, x0 + 2 : x1 - 2]
    assert (panel.min(axis=-1) > 0.85).mean() > 0.5, "the legend's light panel is not on screen"
    # the vessel is in the first frame: the hull's violet (used by nothing else) outside the legend
    scene = np.ones(img.shape[:2], bool)
    scene[y0:y1, x0:x1] = False
    hull = (g < 0.08) & (b > 0.6) & (r > 0.35) & (b > r + 0.1) & scene
    assert hull.sum() >= 30, f"only {hull.sum()} hull-coloured pixels on screen"
    # lit like daylight, not Meshcat's dark default scene (mean brightness ~0.14 before)
    assert img.mean() > 0.35, f"mean brightness {img.mean():.2f}"
