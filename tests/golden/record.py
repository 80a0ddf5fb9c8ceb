"""Re-record the golden metrics (see README.md): run every shipped scenario for 30 s."""

import json
import sys
from pathlib import Path

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.run.mission import run_mission
from usvdrake.scenario import available_scenarios

DURATION = 30.0  # [s] long enough that every subsystem acts (SLAM keyframes, NMPC, NMHE, A*)


def main(names: list[str]) -> None:
    here = Path(__file__).parent
    for name in names or available_scenarios():
        scenario = with_overrides(load_scenario(name), duration=DURATION, seed=0)
        metrics = run_mission(scenario, record=False).metrics
        (here / f"{name}.json").write_text(json.dumps(metrics, indent=2) + "\n")
        print(f"{name}: recorded")


if __name__ == "__main__":
    main(sys.argv[1:])
