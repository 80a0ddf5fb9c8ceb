"""``report.html``: one offline file with zoomable plots (plotly inlined once), a cross-track
error plot, and the metrics as a person reads them (rounded, names without quotes)."""

import re

import numpy as np

from usvdrake.vessel import load_vessel
from usvdrake.viz.report import format_value, write_report
from usvdrake.worlds import make_world


def test_format_value_reads_as_a_person_writes():
    assert format_value(3.235936759000026) == "3.236"
    assert format_value("canal_demo") == "canal_demo"
    assert format_value(None) == "–" and format_value(True) == "yes"
    assert format_value([1.23456, "a"]) == "[1.235, a]"
    assert format_value(0.0) == "0" and format_value(12345678.0) == "1.235e+07"


def test_report_is_one_offline_file_with_three_interactive_plots(tmp_path):
    t = np.linspace(0.0, 10.0, 101)
    states = np.column_stack([t, 0.1 * np.sin(t), 0 * t, 1 + 0 * t, 0 * t, 0 * t])
    reference = np.column_stack([0 * t, 1 + 0 * t, 0.1 * np.sin(t)])
    vessel = load_vessel("roboat2")
    thrust = np.zeros((len(t), 4))
    metrics = {"scenario": "canal_demo", "cross_track_rmse_m": 3.235936759000026}
    path = tmp_path / "report.html"
    world = make_world("canal_demo", 0)
    write_report(path, "a run", metrics, t, states, reference, thrust, vessel, world, [[10, 0]])
    page = path.read_text()
    assert page.count('class="plotly-graph-div"') == 3
    assert page.count("plotly.js v") == 1  # the library once, inline: nothing fetched
    assert not re.search(r'<script[^>]+src="http', page)
    rmse = np.sqrt(np.mean(reference[:, 2] ** 2))
    assert "Cross-track error" in page and f"RMSE {rmse:.3f} m" in page
    assert "<td>3.236</td>" in page and "<td>canal_demo</td>" in page
