"""``usvdrake run``: simulate a scenario and write metrics, replay and report."""

import sys
import time

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.run.fleet import fleet_summary
from usvdrake.run.mission import run_mission
from usvdrake.run.simulate import make_meshcat


def _summary(result, scenario) -> str:
    m = result.metrics
    lines = [
        f"usvdrake run {scenario.name}: {scenario.description}".rstrip(": "),
        f"  vessel {m['vessel']} in world {m['world']} "
        f"(seed {m['seed']}, estimator {m['estimator']})",
        f"  simulated {m['sim_time_s']:.1f} s in {m['wall_time_s']:.1f} s wall "
        f"= {m['realtime_factor']:.1f}x real time",
        f"  mission {'COMPLETE' if m['mission_complete'] else 'NOT complete'}: "
        f"path {m['path_length_m']:.1f} m, "
        f"final distance to goal {m['final_distance_to_goal_m']:.2f} m",
        f"  cross-track RMSE {m['cross_track_rmse_m']:.2f} m (max {m['cross_track_max_m']:.2f} m), "
        f"mean speed {m['mean_speed_mps']:.2f} m/s",
        (
            f"  min clearance to obstacles {m['min_clearance_m']:.2f} m, "
            if m["min_clearance_m"] is not None
            else "  no obstacles, "
        )
        + f"collision samples {m['collision_samples']}, "
        f"thrust saturated {100 * m['thrust_saturated_fraction']:.0f} % of the time",
    ]
    for name, path in result.files.items():
        lines.append(f"  {name:<10} {path}")
    return "\n".join(lines)


def add_arguments(r) -> None:
    r.add_argument(
        "scenario",
        nargs="?",
        default=None,
        help="shipped scenario name or YAML path (default: canal_demo)",
    )
    r.add_argument(
        "--duration", type=float, default=None, help="override the simulated duration [s]"
    )
    r.add_argument("--seed", type=int, default=None, help="override the scenario seed")
    r.add_argument("--out", default="out/run", help="output folder (default: out/run)")
    r.add_argument(
        "--meshcat",
        action="store_true",
        help="serve Meshcat on localhost and pace the run in real time",
    )
    r.add_argument(
        "--port", type=int, default=None, help="Meshcat port (default: first free from 7000)"
    )
    r.add_argument(
        "--realtime-rate", type=float, default=None, help="0: as fast as possible; 1: real time"
    )
    r.add_argument(
        "--no-replay", action="store_true", help="skip the Meshcat recording (replay.html)"
    )
    r.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args) -> int:
    scenario = with_overrides(load_scenario(args.scenario), duration=args.duration, seed=args.seed)
    meshcat = None
    if args.meshcat:
        meshcat = make_meshcat(args.port)
        print(
            f"Meshcat (localhost only): {meshcat.web_url()}  — open it in a browser to watch live"
        )
    rate = args.realtime_rate if args.realtime_rate is not None else (1.0 if args.meshcat else 0.0)
    result = run_mission(
        scenario,
        out_dir=args.out,
        meshcat=meshcat,
        record=not args.no_replay,
        progress=not args.quiet,
        realtime_rate=rate,
    )
    if scenario.controller == "taxi":
        print(fleet_summary(result.metrics, args.out))
    else:
        print(_summary(result, scenario))
    if args.meshcat and sys.stdin.isatty():
        print("Meshcat stays up for the replay; press Ctrl-C to quit.")
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
    return 0
