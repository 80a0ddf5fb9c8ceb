"""``finish_replay``: make Meshcat's static HTML replay readable on its own.

Meshcat draws no text, so the legend (what each drawn line and colour means) and the run's clock
and speed are a small fixed-position HTML overlay inserted into the page. The clock follows the
replay's animation time (``viewer.animator.time``, also moved by the time scrubber); the speed
is looked up in the run's (t, speed) samples embedded as JSON. Everything stays in the one file:
no network URLs.
"""

import base64
import html as html_lib
import json
import re

import numpy as np
from pydrake.geometry import Rgba

from usvdrake.viz.exploration_visualizer import FRONTIER_COLOR, PATH_COLOR, SETPOINT_COLOR
from usvdrake.viz.lidar_visualizer import HIT_COLOR
from usvdrake.viz.meshcat_world import DENIED
from usvdrake.viz.trajectory_visualizer import PREDICTION_COLOR, REFERENCE_COLOR
from usvdrake.viz.vessel_visualizer import (
    ARROW_COLOR,
    FLEET_COLORS,
    HULL_COLOR,
    ROUTE_COLOR,
    TRAIL_COLOR,
)

OCCUPIED_COLOR = Rgba(0.9, 0.1, 0.1, 1.0)
MAX_SAMPLES = 2000  # speed samples embedded per vessel

# (a Meshcat path fragment, the colour it is drawn in, the legend's words, line or dot)
LEGEND = (
    ("/vessels/", HULL_COLOR, "vessel (white mark: bow; disc: where to look)", "dot"),
    ("/thrusters/", ARROW_COLOR, "thrust per thruster (length ∝ force)", "bar"),
    ("/trail/", TRAIL_COLOR, "path sailed", "line"),
    ("/route", ROUTE_COLOR, "planned route: start → waypoints (dots)", "line"),
    ("/reference", REFERENCE_COLOR, "reference path the controller tracks", "line"),
    ("/nmpc/prediction", PREDICTION_COLOR, "NMPC predicted path", "line"),
    ("/exploration/path", PATH_COLOR, "exploration plan", "line"),
    ("/exploration/frontiers", FRONTIER_COLOR, "frontier cells", "dot"),
    ("/exploration/setpoint", SETPOINT_COLOR, "setpoint", "dot"),
    ("/lidar/", HIT_COLOR, "lidar hits", "dot"),
    ("/slam/map", OCCUPIED_COLOR, "SLAM map (occupied cells)", "dot"),
    ("/world/occupancy", OCCUPIED_COLOR, "occupancy grid", "dot"),
    ("/world/gps_denied", Rgba(1.0, 0.1, 0.1, 0.5), "GPS-denied zone", "box"),
)
assert DENIED.r() == 1.0  # the GPS-denied entry above is DENIED, drawn more opaque to be seen


def _css(c: Rgba) -> str:
    return f"rgba({round(255 * c.r())},{round(255 * c.g())},{round(255 * c.b())},{c.a():.2f})"


def drawn_paths(html: str) -> bytes:
    """The decoded Meshcat commands embedded in ``html`` (msgpack bytes, concatenated)."""
    chunks = re.findall(r'"data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"', html)
    return b"".join(base64.b64decode(c) for c in chunks)


def legend_entries(html: str, fleet_colors: bool = False) -> list[tuple[str, str, str]]:
    """``(css colour, words, mark)`` for each kind of thing the replay draws."""
    data = drawn_paths(html)
    entries = []
    for fragment, color, words, mark in LEGEND:
        if fragment.encode() in data:
            if fragment == "/vessels/" and fleet_colors:
                words = "vessels (one colour each; white mark: bow)"
                stops = ",".join(_css(Rgba(*c, 1.0)) for c in FLEET_COLORS)
                entries.append((f"linear-gradient(90deg,{stops})", words, mark))
                continue
            entries.append((_css(color), words, mark))
    return entries


def _speed_samples(times, speeds: dict) -> dict:
    times = np.asarray(times, float)
    step = max(1, int(np.ceil(len(times) / MAX_SAMPLES)))
    return {
        "t": [round(float(t), 3) for t in times[::step]],
        "speed": {
            name: [round(float(v), 3) for v in np.asarray(s, float)[::step]]
            for name, s in speeds.items()
        },
    }


_STYLE = """
#usv-overlay { position: fixed; left: 10px; top: 10px; z-index: 10; max-width: 340px;
  padding: 8px 10px; background: rgba(255,255,255,0.88); color: #222; border-radius: 6px;
  font: 12px/1.45 system-ui, sans-serif; box-shadow: 0 1px 4px rgba(0,0,0,0.3);
  pointer-events: none; }
#usv-overlay .clock { font: bold 14px/1.4 ui-monospace, monospace; margin-bottom: 4px;
  white-space: pre; }
#usv-overlay .row { display: flex; align-items: center; gap: 6px; }
#usv-overlay .mark { flex: 0 0 22px; }
#usv-overlay .line { height: 3px; }
#usv-overlay .bar { height: 6px; }
#usv-overlay .dot { height: 10px; width: 10px; flex-basis: 10px; margin: 0 6px;
  border-radius: 50%; }
#usv-overlay .box { height: 10px; }
"""

_SCRIPT = """
(function () {
  var S = JSON.parse(document.getElementById("usv-samples").textContent);
  var clock = document.getElementById("usv-clock");
  var names = Object.keys(S.speed);
  function at(series, t) {
    var ts = S.t, lo = 0, hi = ts.length - 1;
    if (hi < 0) return NaN;
    if (t <= ts[0]) return series[0];
    if (t >= ts[hi]) return series[hi];
    while (hi - lo > 1) { var mid = (lo + hi) >> 1; if (ts[mid] <= t) lo = mid; else hi = mid; }
    var f = (t - ts[lo]) / (ts[hi] - ts[lo]);
    return series[lo] + f * (series[hi] - series[lo]);
  }
  var start = performance.now();
  function tick() {
    var t;
    var a = window.viewer && window.viewer.animator;
    if (a && a.duration > 0) t = a.time;  // the replay's own clock (and its scrubber)
    else t = Math.min((performance.now() - start) / 1000, S.t.length ? S.t[S.t.length - 1] : 0);
    var parts = names.map(function (n) {
      var v = at(S.speed[n], t);
      return (names.length > 1 ? n + " " : "speed ") + (isNaN(v) ? "–" : v.toFixed(2)) + " m/s";
    });
    clock.textContent = "t = " + t.toFixed(1) + " s   " + parts.join("   ");
    requestAnimationFrame(tick);
  }
  tick();
})();
"""


def finish_replay(
    html: str, times=(), speeds: dict | None = None, title: str = "", fleet_colors: bool = False
) -> str:
    """``html`` (``Meshcat.StaticHtml()``) with the legend and clock overlay added.

    ``times`` [s] and ``speeds`` (``{vessel name: speed over ground [m/s] at times}``) feed the
    "t = …, speed = …" line; ``fleet_colors``: the vessels are drawn each in its own colour.
    """
    rows = []
    for color, words, mark in legend_entries(html, fleet_colors):
        rows.append(
            f'<div class="row"><span class="mark {mark}" style="background:{color}"></span>'
            f"<span>{html_lib.escape(words)}</span></div>"
        )
    head = f"<div><b>{html_lib.escape(title)}</b></div>" if title else ""
    samples = json.dumps(_speed_samples(times, speeds or {}), separators=(",", ":"))
    overlay = (
        f"<style>{_STYLE}</style>\n"
        f'<div id="usv-overlay">{head}<div class="clock" id="usv-clock">t = 0.0 s</div>'
        f'<div id="usv-legend">{"".join(rows)}</div></div>\n'
        f'<script type="application/json" id="usv-samples">{samples}</script>\n'
        f"<script>{_SCRIPT}</script>\n"
    )
    i = html.rfind("</body>")
    return html[:i] + overlay + html[i:] if i >= 0 else html + overlay
