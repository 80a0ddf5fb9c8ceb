"""Benchmark: the weighted multi-connection A* of Ueland 2017 §Path Planner (numba kernel).

A 400 × 400 grid at 0.2 m (an 80 m square) with random rectangular obstacles (fixed seed),
inflated by 0.4 m (Ueland 2017 §Map Processing) and weighted by Ueland 2017 eq. (1),
w = 1 + 5 / (0.1 + d_obj) with d_obj [m] the distance transform to the obstacles; a start and
goal ~75 m apart (Nav2's Smac 2D A* took 243 ms for a ~75 m path). Reported:

* ``astar_ms_median`` / ``astar_ms_p95``: :func:`weighted_astar` with connection distance 4
  (48 headings, as Ueland 2017 flies), after one warm-up call (numba compilation), ≥ 20 timed runs;
  target ≤ 50 ms median. ``expanded``, ``path_length_m``, ``path_cost_m`` of that plan.
* the same for connection distance 1 (8 headings), and ``length_ratio_d4_d1`` (Ueland 2017 Fig. 8:
  the d = 4 path is shorter).
* ``preprocess_ms_median``: the explorer's map processing (``process_map``: inflation,
  reachability, eq. 1 weights).

Prints one JSON object.
"""

import argparse
import json
import statistics
import time

import numpy as np

from usvdrake.systems.guidance.map_processing import process_map
from usvdrake.systems.guidance.weighted_astar import path_length, weighted_astar
from usvdrake.worlds.world import OccupancyGrid

SIZE, RESOLUTION = 400, 0.2  # cells, [m]
INFLATION = 0.4  # [m] Ueland 2017 §Map Processing
START_XY, GOAL_XY = (5.0, 20.0), (75.0, 47.0)  # [m], 75.0 m apart
TARGET_MS = 50.0


def make_map(seed: int = 0) -> np.ndarray:
    """Occupied cells (SIZE, SIZE) bool: 60 random rectangles 1-10 m on a side, none within
    3 m of the start or the goal."""
    rng = np.random.default_rng(seed)
    occ = np.zeros((SIZE, SIZE), bool)
    occ[[0, -1], :] = occ[:, [0, -1]] = True  # the walls of the square
    rows, cols = np.mgrid[0:SIZE, 0:SIZE]
    keep_clear = np.zeros_like(occ)
    for x, y in (START_XY, GOAL_XY):
        keep_clear |= np.hypot(cols - x / RESOLUTION, rows - y / RESOLUTION) < 3.0 / RESOLUTION
    for _ in range(60):
        h, w = rng.uniform(1.0, 10.0, 2) / RESOLUTION
        r, c = rng.uniform(0, SIZE, 2)
        box = np.zeros_like(occ)
        box[int(r) : int(r + h), int(c) : int(c + w)] = True
        if not (box & keep_clear).any():
            occ |= box
    return occ


def preprocess(occ: np.ndarray):
    """The explorer's own map processing (inflation, reachability, Ueland 2017 eq. 1 weights) on the
    map as an occupancy grid: what each planning cycle does before its A*."""
    grid = OccupancyGrid((0.0, 0.0), RESOLUTION, np.where(occ, 100, 0).astype(np.int8))
    return process_map(grid, START_XY, INFLATION)


def timed(fn, repeats: int) -> tuple[list[float], object]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append((time.perf_counter() - t0) * 1e3)
    return times, out


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    repeats = max(args.repeats, 20)

    occ = make_map()
    t_pre, pmap = timed(lambda: preprocess(occ), repeats)
    trav, weights, start = pmap.traversable, pmap.weights, pmap.start
    goal = (int(GOAL_XY[1] / RESOLUTION), int(GOAL_XY[0] / RESOLUTION))

    out = {"benchmark": "astar", "grid": [SIZE, SIZE], "resolution_m": RESOLUTION}
    lengths = {}
    for d, tag in ((4, "astar"), (1, "astar_d1")):
        weighted_astar(trav, weights, start, goal, d)  # warm-up: compiles or loads the cache
        times, res = timed(lambda d=d: weighted_astar(trav, weights, start, goal, d), repeats)
        assert res is not None, "benchmark map must connect start and goal"
        lengths[d] = path_length(res.cells) * RESOLUTION
        out |= {
            f"{tag}_ms_median": round(statistics.median(times), 3),
            f"{tag}_ms_p95": round(float(np.percentile(times, 95)), 3),
            f"{tag}_expanded" if d != 4 else "expanded": res.expanded,
            f"{tag}_path_length_m" if d != 4 else "path_length_m": round(lengths[d], 3),
            f"{tag}_path_cost_m" if d != 4 else "path_cost_m": round(res.cost * RESOLUTION, 3),
        }
    med = out["astar_ms_median"]
    out |= {
        "straight_line_m": round(float(np.hypot(*np.subtract(GOAL_XY, START_XY))), 3),
        "length_ratio_d4_d1": round(lengths[4] / lengths[1], 4),
        "preprocess_ms_median": round(statistics.median(t_pre), 3),
        "traversable_fraction": round(float(trav.mean()), 3),
        "samples": repeats,
        "target_ms": TARGET_MS,
        "met": med <= TARGET_MS,
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
