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
        browser.close()
    assert not errors, errors
    img = imread(io.BytesIO(png), format="png")[..., :3]
    # not a blank page: many distinct colours, and the canal's water blue is on screen
    assert img.std() > 0.05
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    water = (b > 0.3) & (b > r + 0.1) & (b > g)
    assert water.mean() > 0.01, f"water covers only {water.mean():.3%} of the view"
    assert len(np.unique((img * 15).astype(int).reshape(-1, 3), axis=0)) > 20
