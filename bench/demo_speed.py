"""Benchmark: how much faster than real time the demo's closed loop runs.

Runs the default scenario (canal_demo) headless with its error-controlled integrator, without and
with the Meshcat recording, ``--repeats`` times each; prints one JSON object with medians. Target
(issue: foundation): ≥ 20× real time.
"""

import argparse
import json
import platform
import statistics
import time

from usvdrake import load_scenario, run_mission
from usvdrake.run.mission import make_meshcat

TARGET = 20.0


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--scenario", default="canal_demo")
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    plain, recorded, sim_times = [], [], []
    for _ in range(args.repeats):
        r = run_mission(scenario, record=False)
        plain.append(r.metrics["realtime_factor"])
        sim_times.append(r.metrics["sim_time_s"])
    meshcat = make_meshcat()
    for _ in range(args.repeats):
        meshcat.StartRecording()  # what `usvdrake run --out` pays for replay.html
        t0 = time.perf_counter()
        r = run_mission(scenario, meshcat=meshcat, record=False)
        recorded.append(r.metrics["sim_time_s"] / (time.perf_counter() - t0))
        meshcat.StopRecording()
        meshcat.DeleteRecording()
    median = statistics.median(plain)
    print(
        json.dumps(
            {
                "benchmark": "demo_speed",
                "scenario": args.scenario,
                "integrator": scenario.simulation.integrator,
                "target_accuracy": scenario.simulation.accuracy,
                "sim_time_s": statistics.median(sim_times),
                "repeats": args.repeats,
                "realtime_factor_median": round(median, 1),
                f"{args.scenario}_realtime_factor": round(median, 1),  # bench/mission_speed's key
                "realtime_factor_min": round(min(plain), 1),
                "realtime_factor_with_meshcat_median": round(statistics.median(recorded), 1),
                "target_realtime_factor": TARGET,
                "target_met": median >= TARGET,
                "python": platform.python_version(),
            }
        )
    )


if __name__ == "__main__":
    main()
