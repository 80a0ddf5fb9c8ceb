"""Benchmark: PLICP (usvdrake.systems.slam.plicp) on noise-free 1081-beam Hokuyo-like scans
(270°, 0.25°, 30 m) of a cluttered synthetic room, cast with raycast.cast.

* ``plicp_ms_median``, ``plicp_iterations_median``, ``max_translation_error_m``,
  ``max_rotation_error_deg``: ``--matches`` random motions up to 0.5 m / 10°, started from
  the identity. Target median ≤ 3 ms.
* ``failure_rate_45deg`` / ``failure_rate_45deg_rotation_search``: the same motions started
  from the true pose with its heading off by U(−45°, 45°), without and with the coarse
  rotation search; a failure is an error > 1 cm or > 0.5°.
Prints one JSON object.
"""

import argparse
import json
import statistics
import time

import numpy as np
from scipy.spatial import cKDTree

from usvdrake.systems.slam.plicp import plicp, rot
from usvdrake.worlds.raycast import Scene, cast
from usvdrake.worlds.synthetic import HOKUYO, cluttered_room


def scan_points(scene: Scene, pose) -> np.ndarray:
    r = cast(scene, HOKUYO, [0.0], np.array(pose[:2]), 1.0, pose[2], 30.0)[0]
    ok = np.isfinite(r)
    a = HOKUYO.azimuths[ok]
    return np.column_stack([r[ok] * np.cos(a), r[ok] * np.sin(a)])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--matches", type=int, default=60)
    parser.add_argument("--starts", type=int, default=100)
    args = parser.parse_args()
    scene, rng = cluttered_room(), np.random.default_rng(0)
    times, iters, et, er = [], [], [], []
    fail, fail_rs = 0, 0
    for k in range(max(args.matches, args.starts)):
        p1 = (rng.uniform(-3, 3), rng.uniform(-2, 2), rng.uniform(-np.pi, np.pi))
        d, ang = rng.uniform(0, 0.5), rng.uniform(0, 2 * np.pi)
        p2 = (p1[0] + d * np.cos(ang), p1[1] + d * np.sin(ang), p1[2] + rng.uniform(-0.17, 0.17))
        t = rot(p1[2]).T @ (np.array(p2[:2]) - np.array(p1[:2]))
        th = p2[2] - p1[2]
        ref, cur = scan_points(scene, p1), scan_points(scene, p2)
        if k < args.matches:
            t0 = time.perf_counter()
            res = plicp(ref, cur)  # includes building the k-d tree
            times.append((time.perf_counter() - t0) * 1e3)
            iters.append(res.iterations)
            et.append(float(np.linalg.norm(res.t - t)))
            er.append(float(np.rad2deg(abs(res.theta - th))))
        if k < args.starts:
            tree = cKDTree(ref)
            start = (t[0], t[1], th + np.deg2rad(rng.uniform(-45, 45)))
            for search in (False, True):
                res = plicp(ref, cur, start, rotation_search=search, tree=tree)
                bad = np.linalg.norm(res.t - t) > 0.01 or abs(res.theta - th) > np.deg2rad(0.5)
                fail_rs += bad and search
                fail += bad and not search
    print(
        json.dumps(
            {
                "plicp_ms_median": round(statistics.median(times), 3),
                "plicp_iterations_median": statistics.median(iters),
                "max_translation_error_m": max(et),
                "max_rotation_error_deg": max(er),
                "matches": args.matches,
                "failure_rate_45deg": fail / args.starts,
                "failure_rate_45deg_rotation_search": fail_rs / args.starts,
                "starts_45deg": args.starts,
                "target_ms": 3.0,
            }
        )
    )


if __name__ == "__main__":
    main()
