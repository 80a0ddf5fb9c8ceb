"""Benchmark: how much faster than real time every shipped scenario runs (issue: simulation speed).

Runs each shipped scenario for ``--duration`` simulated seconds (or until its mission ends) the
way ``usvdrake run NAME --out DIR`` does — mission log, replay and report written — unless
``--no-outputs`` (what a campaign pays: no files). ``realtime_factor`` is the simulated time over
the wall time spent advancing the simulator (``metrics.json``'s own number), so building the
diagram and writing the reports are outside it. Prints one JSON object with
``<scenario>_realtime_factor`` per scenario and the targets of the issue: ≥ 10× for every
scenario, ≥ 5× for the SLAM surveys.
"""

import argparse
import json
import tempfile
from pathlib import Path

from tqdm import tqdm

from usvdrake.run.mission import run_mission
from usvdrake.scenario import available_scenarios, override, read_scenario

SLAM_SURVEYS = ("valley_survey", "lake_survey", "canal_survey")
TARGET, TARGET_SLAM = 10.0, 5.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=60.0, help="[s] simulated per scenario")
    parser.add_argument("--only", nargs="*", help="these scenarios (default: every shipped one)")
    parser.add_argument("--no-outputs", action="store_true", help="no log, replay or report")
    args = parser.parse_args()
    names = args.only or available_scenarios()
    out: dict = {"benchmark": "mission_speed", "duration_s": args.duration}
    missed = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in tqdm(names, desc="scenarios", leave=False):
            scenario = read_scenario(name)
            scenario = override(scenario, duration=min(args.duration, scenario.duration))
            result = run_mission(
                scenario,
                out_dir=None if args.no_outputs else Path(tmp) / name,
                record=not args.no_outputs,
            )
            factor = float(result.metrics["realtime_factor"])
            out[f"{name}_realtime_factor"] = round(factor, 2)
            if factor < (TARGET_SLAM if name in SLAM_SURVEYS else TARGET):
                missed.append(name)
    out["target_realtime_factor"] = TARGET
    out["target_realtime_factor_slam_surveys"] = TARGET_SLAM
    out["below_target"] = missed
    out["targets_met"] = not missed
    print(json.dumps(out))


if __name__ == "__main__":
    main()
