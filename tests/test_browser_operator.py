"""Ueland 2017 §Operator Interaction in a real browser: headless Chromium opens the live Meshcat of
the exploring vessel, types a goal into the sliders, clicks "Go to goal", and the vessel heads
there. Needs Debian's chromium (`.ci/run` installs it) and playwright (test extra)."""

import numpy as np
import pytest
from _browser import ARGS, BROWSER_TEST, CHROMIUM
from pydrake.geometry import Meshcat
from pydrake.systems.analysis import Simulator

from usvdrake import load_scenario
from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.systems.guidance.operator import GOAL_SLIDERS, OperatorMode
from usvdrake.worlds import make_world

pytestmark = BROWSER_TEST


def open_water_goal(scenario) -> np.ndarray:
    """A goal 5 m east of the start, at the y with the most clearance (obstacles vary by seed)."""
    world = make_world(scenario.world, scenario.seed)
    x = scenario.initial_state[0] + 5.0
    ys = np.linspace(1.0, 5.4, 45)
    return np.array([x, ys[np.argmax(world.clearance(np.full_like(ys, x), ys))]])


def test_the_operator_sends_the_vessel_to_a_location_from_the_browser():
    sync_api = pytest.importorskip("playwright.sync_api")
    scenario = load_scenario("basin_explore")
    goal = open_water_goal(scenario)
    meshcat = Meshcat()
    diagram = build_vessel_diagram(scenario, meshcat=meshcat)
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    simulator.AdvanceTo(3.0)  # exploring by itself

    errors = []
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        page = browser.new_page(viewport={"width": 1000, "height": 700})
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(meshcat.web_url())
        page.wait_for_selector("canvas", timeout=30_000)
        page.get_by_text("Open Controls").click()
        for label, value in zip(GOAL_SLIDERS, goal, strict=True):
            row = page.locator("li.cr.number", has=page.get_by_text(label, exact=True))
            box = row.locator("input[type=text]")
            box.fill(f"{value:.1f}")
            box.press("Enter")
        page.locator("li.cr.function", has=page.get_by_text("Go to goal", exact=True)).click()
        for _ in range(50):  # the click travels over the websocket
            if meshcat.GetButtonClicks("Go to goal") > 0:
                break
            page.wait_for_timeout(100)
        browser.close()
    assert not errors, errors
    assert meshcat.GetButtonClicks("Go to goal") == 1
    np.testing.assert_allclose(
        [meshcat.GetSliderValue(label) for label in GOAL_SLIDERS], goal, atol=0.051
    )

    port = diagram.GetOutputPort("ground_truth_state")
    start = port.Eval(context)[:2].copy()
    simulator.AdvanceTo(60.0)
    command = diagram.GetOutputPort("operator_command").Eval(context)
    assert command[0] == OperatorMode.GOTO
    np.testing.assert_allclose(command[1:], goal, atol=0.051)
    end = port.Eval(context)[:2]
    # it headed there: most of the way covered in under a minute at Ueland 2017's speeds
    assert np.linalg.norm(end - goal) < 0.35 * np.linalg.norm(start - goal)
    destination = diagram.GetOutputPort("destination").Eval(context)
    assert destination[2] == 1.0 and np.linalg.norm(destination[:2] - goal) < 0.5
