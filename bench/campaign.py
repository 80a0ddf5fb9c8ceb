"""Benchmark: a Monte Carlo campaign (usvdrake.run.campaign) on 1 and on 2 Dask workers.

The same campaign — river_tracking (Roboat II §VI-B: NMPC + NMHE on the Charles River), 16
randomised runs of 60 simulated seconds, campaign seed 0 — once on a ``LocalCluster`` of one
worker process and once on two (one thread and one BLAS thread each). Each wall time is the
whole :func:`run_campaign` call as a user sees it: randomisation, cluster start, the workers'
first imports, the runs (no report is written). Reported:

* ``wall_1_s``, ``wall_2_s`` and ``ratio`` = wall_2 / wall_1; target ≤ 0.6 (``met``).
* ``run_wall_s_median``: one run's wall time inside a worker; ``overhead_1_s`` /
  ``overhead_2_s``: wall time minus the runs' total wall time divided by the workers.
* ``cpu_per_wall_1`` / ``cpu_per_wall_2``: the runs' CPU time over their wall time (≈ 1: each
  worker had a core to itself; well below 1: something else was using the cores), and
  ``load_average_before``: the 1-minute load average before the benchmark started.
* ``same_metrics``: both campaigns gave the same metrics for every run (wall-time and
  solver-time keys aside): a run does not depend on where or with whom it ran.

The machine has to have 2 free cores for the target to be met. Prints one JSON object.
"""

import argparse
import json
import os
import statistics

from usvdrake.diagrams import load_scenario
from usvdrake.run.campaign import is_timing_key, run_campaign

TARGET_RATIO = 0.6


def _metrics(campaign: dict) -> list:
    return [
        {k: v for k, v in (r["metrics"] or {}).items() if not is_timing_key(k)}
        for r in campaign["rows"]
    ]


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--scenario", default="river_tracking")
    parser.add_argument("--runs", type=int, default=16)
    parser.add_argument("--duration", type=float, default=60.0, help="simulated seconds per run")
    args = parser.parse_args()

    scenario = load_scenario(args.scenario)
    out = {
        "benchmark": "campaign",
        "scenario": scenario.name,
        "runs": args.runs,
        "duration_s": args.duration,
        "cpus": os.cpu_count(),
        "load_average_before": round(os.getloadavg()[0], 2),
    }
    campaigns = {}
    for workers in (1, 2):
        c = run_campaign(
            scenario, args.runs, workers=workers, seed=0, duration=args.duration, progress=False
        )
        campaigns[workers] = c
        run_walls = [r["run_wall_s"] for r in c["rows"] if r.get("run_wall_s") is not None]
        out[f"wall_{workers}_s"] = round(c["wall_time_s"], 2)
        out[f"overhead_{workers}_s"] = round(c["wall_time_s"] - sum(run_walls) / workers, 2)
        out[f"completed_{workers}"] = c["summary"]["completed"]
        run_cpus = [r["run_cpu_s"] for r in c["rows"] if r.get("run_cpu_s") is not None]
        out[f"cpu_per_wall_{workers}"] = round(sum(run_cpus) / sum(run_walls), 3)
        if workers == 1:
            out["run_wall_s_median"] = round(statistics.median(run_walls), 3)
    ratio = out["wall_2_s"] / out["wall_1_s"]
    out |= {
        "ratio": round(ratio, 3),
        "same_metrics": _metrics(campaigns[1]) == _metrics(campaigns[2]),
        "target_ratio": TARGET_RATIO,
        "met": ratio <= TARGET_RATIO,
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
