"""Benchmark: the compiled PLICP (``plicp``, numba) against its numpy reference
(``plicp_reference``) on the same scan pairs in one run, calls alternating (issue 39).

Pairs: the Intel Research Lab log's moving scans (tests/data/carmen, 180-beam real scans) one,
two and five scans apart from the odometry's guess, and 1081-beam scans of the cluttered
synthetic room with 1 cm range noise, 0-0.5 m / 0-10° apart, from the identity and from the truth.

* ``numba_ms_median`` / ``numpy_ms_median``: median time of one match (the compiled one includes
  building its nearest-neighbour grid; the numpy one its cKDTree), ``ratio`` = numba / numpy.
* ``intel_ratio`` / ``room_ratio``: the same ratio of medians over each source's pairs.
* ``max_pose_diff``: max |Δt_x|, |Δt_y| [m], |Δθ| [rad] between the two;
  ``correspondence_mismatches``: pairs whose correspondences, iteration count or convergence
  differ; ``fallbacks``: matches the kernel left to numpy (an ill-conditioned solve).
Prints one JSON object.
"""

import argparse
import json
import statistics
import time
from pathlib import Path

import numpy as np

from usvdrake.logs.carmen import read_carmen
from usvdrake.systems.slam import plicp_kernel as kernel
from usvdrake.systems.slam.graph_slam.poses import between
from usvdrake.systems.slam.plicp import GRID_CELL, plicp, plicp_reference
from usvdrake.worlds.synthetic import noisy_scan_pairs

INTEL = Path(__file__).parent.parent / "tests" / "data" / "carmen" / "intel-first200.clf.bz2"


def intel_pairs() -> list:
    scans = [(s.scan.points(), s.odometry_pose) for s in read_carmen(INTEL)][144:]
    return [
        (scans[k][0], scans[k + gap][0], tuple(between(scans[k][1], scans[k + gap][1])))
        for gap in (1, 2, 5)
        for k in range(len(scans) - gap)
    ]


def room_pairs(count: int, seed: int = 0) -> list:
    out = []
    for a, b, p1, p2 in noisy_scan_pairs(count, seed):
        out += [(a, b, (0.0, 0.0, 0.0)), (a, b, tuple(between(p1, p2)))]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--room-pairs", type=int, default=30)
    args = parser.parse_args()
    intel = intel_pairs()
    pairs = intel + room_pairs(args.room_pairs)
    plicp(*pairs[0])  # compile / load the kernel's cache
    fast, slow, diff, mismatches, fallbacks = [], [], 0.0, 0, 0
    for ref, cur, guess in pairs:
        t0 = time.perf_counter()
        a = plicp(ref, cur, guess)
        t1 = time.perf_counter()
        b = plicp_reference(ref, cur, guess)
        t2 = time.perf_counter()
        fast.append((t1 - t0) * 1e3)
        slow.append((t2 - t1) * 1e3)
        diff = max(diff, float(np.max(np.abs(a.pose - b.pose))))
        same = a.correspondences.shape == b.correspondences.shape and np.array_equal(
            a.correspondences, b.correspondences
        )
        mismatches += not (same and a.iterations == b.iterations and a.converged == b.converged)
        params = np.array([1.0, 1.0, 0.9, 1e-6, 1e-7, 1e-3])  # plicp's defaults
        fallbacks += bool(kernel.run(ref, cur, GRID_CELL, np.array(guess), params, 50, 4)[-1])
    numba_ms, numpy_ms = statistics.median(fast), statistics.median(slow)
    k = len(intel)
    by_source = {
        f"{name}_ratio": round(statistics.median(fast[a:b]) / statistics.median(slow[a:b]), 4)
        for name, a, b in (("intel", 0, k), ("room", k, len(pairs)))
    }
    print(
        json.dumps(
            {
                "benchmark": "plicp_speed",
                "pairs": len(pairs),
                "numba_ms_median": round(numba_ms, 4),
                "numpy_ms_median": round(numpy_ms, 4),
                "ratio": round(numba_ms / numpy_ms, 4),
                **by_source,
                "numba_ms_total": round(sum(fast), 1),
                "numpy_ms_total": round(sum(slow), 1),
                "max_pose_diff": diff,
                "correspondence_mismatches": mismatches,
                "fallbacks": fallbacks,
            }
        )
    )


if __name__ == "__main__":
    main()
