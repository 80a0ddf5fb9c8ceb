"""``usvdrake run``: simulate a scenario and write metrics, replay and report."""

import cProfile
import io
import pstats
import sys
import time
from pathlib import Path

from usvdrake.cli._format import num
from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.errors import ConfigError
from usvdrake.logs.mission_log.live import FoxgloveLive
from usvdrake.run.fleet import fleet_summary
from usvdrake.run.interrupt import stop_reason, stop_signal
from usvdrake.run.mission import run_mission
from usvdrake.run.simulate import make_meshcat


def _summary(result, scenario) -> str:
    """One screen: what ran, how fast, whether the mission completed (and why not), how well it
    went, what was written where."""
    m = result.metrics
    complete = m["mission_complete"]
    why = ""
    if not complete and m["sim_time_s"] >= scenario.duration - 1e-6:
        why = f" (stopped at the duration, {scenario.duration:g} s)"
    elif m.get("interrupted"):
        why = f" (interrupted by {m.get('interrupted_by')})"
    mission = f"  mission {'COMPLETE' if complete else 'NOT complete'}{why}: "
    mission += f"path {num(m['path_length_m'], '.1f', ' m')}"
    if m.get("final_distance_to_goal_m") is not None:
        mission += f", final distance to goal {num(m['final_distance_to_goal_m'], '.2f', ' m')}"
    lines = [
        f"usvdrake run {scenario.name}: {scenario.description}".rstrip(": "),
        f"  vessel {m['vessel']} in world {m['world']} "
        f"(seed {m['seed']}, estimator {m['estimator']})",
        f"  simulated {m['sim_time_s']:.1f} s in {m['wall_time_s']:.1f} s wall "
        f"= {m['realtime_factor']:.1f}x real time",
        mission,
    ]
    if m.get("cross_track_rmse_m") is not None:
        lines.append(
            f"  cross-track RMSE {num(m['cross_track_rmse_m'], '.2f', ' m')} "
            f"(max {num(m.get('cross_track_max_m'), '.2f', ' m')}), "
            f"mean speed {num(m.get('mean_speed_mps'), '.2f', ' m/s')}"
        )
    if m.get("position_rmse_m") is not None:
        lines.append(
            f"  tracking RMSE {num(m['position_rmse_m'], '.3f', ' m')}, heading "
            f"{num(m.get('heading_rmse_rad'), '.3f', ' rad')}; NMPC "
            f"{m.get('nmpc_solves', 0)} solves, {m.get('nmpc_failures', 0)} failed, median "
            f"{num(m.get('nmpc_solve_ms_median'), '.1f', ' ms')}"
        )
    if m.get("nmhe_velocity_rmse_mps") is not None:
        lines.append(
            f"  NMHE velocity RMSE {num(m['nmhe_velocity_rmse_mps'], '.4f', ' m/s')}, "
            f"{m.get('nmhe_failures', 0)} failed solves"
        )
    if m.get("ate_m") is not None:
        lines.append(
            f"  SLAM ATE {num(m['ate_m'], '.3f', ' m')} online"
            + (f", {num(m['ate_final_m'], '.3f', ' m')} final" if "ate_final_m" in m else "")
            + (f", RPE {num(m['rpe_m'], '.3f', ' m')} per metre" if m.get("rpe_m") else "")
        )
    if m.get("explored_fraction") is not None:
        lines.append(
            f"  explored {100 * m['explored_fraction']:.0f} % of the reachable water "
            f"({num(m.get('explored_area_m2'), '.0f', ' m²')} of "
            f"{num(m.get('reachable_free_area_m2'), '.0f', ' m²')})"
            + (
                f" in {num(m['exploration_time_s'], '.0f', ' s')}"
                if m.get("exploration_time_s") is not None
                else ""
            )
        )
    clearance = (
        f"  min clearance to obstacles {num(m['min_clearance_m'], '.2f', ' m')}, "
        if m.get("min_clearance_m") is not None
        else "  no obstacles, "
    )
    lines.append(
        clearance + f"collision samples {m.get('collision_samples', 0)}, thrust saturated "
        f"{100 * (m.get('thrust_saturated_fraction') or 0.0):.0f} % of the time"
    )
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
        "--foxglove",
        type=int,
        nargs="?",
        const=8765,
        default=None,
        metavar="PORT",
        help="stream the run to Foxglove (WebSocket on localhost:PORT, default 8765) and pace "
        "it in real time",
    )
    r.add_argument(
        "--realtime-rate", type=float, default=None, help="0: as fast as possible; 1: real time"
    )
    r.add_argument(
        "--no-replay", action="store_true", help="skip the Meshcat recording (replay.html)"
    )
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument(
        "--profile",
        action="store_true",
        help="profile the run: OUT/profile.prof (open with snakeviz) and the top functions",
    )


def _profiled(out: Path, call):
    """``call()`` under cProfile: the profile goes to OUT/profile.prof (snakeviz, or
    ``python -m pstats``) and the 15 functions with the most own time to stderr."""
    profiler = cProfile.Profile()
    try:
        return profiler.runcall(call)
    finally:
        out.mkdir(parents=True, exist_ok=True)
        profiler.dump_stats(out / "profile.prof")
        text = io.StringIO()
        pstats.Stats(profiler, stream=text).sort_stats("tottime").print_stats(15)
        body = text.getvalue()
        print(body[body.find("   ncalls") :].rstrip(), file=sys.stderr)
        print(f"profile: {out / 'profile.prof'} (snakeviz {out / 'profile.prof'})", file=sys.stderr)


def run(args) -> int:
    scenario = with_overrides(load_scenario(args.scenario), duration=args.duration, seed=args.seed)
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise ConfigError("command line", "--out", "a folder or a new path", f"a file {args.out}")
    meshcat = None
    if args.meshcat:
        meshcat = make_meshcat(args.port)
        print(
            f"Meshcat (localhost only): {meshcat.web_url()}  — open it in a browser to watch live"
        )
    live = None
    if args.foxglove is not None:
        if scenario.controller == "taxi":
            raise ConfigError("command line", "--foxglove", "a single-vessel scenario", "a fleet")
        try:
            live = FoxgloveLive(args.foxglove)
        except RuntimeError as e:  # the SDK's error when the port is taken
            got = f"{args.foxglove} ({e})"
            raise ConfigError("command line", "--foxglove", "a free port", got) from None
        print(f"Foxglove (localhost only): {live.url}  — in Foxglove: Open connection, that URL")
    watched = args.meshcat or live is not None
    rate = args.realtime_rate if args.realtime_rate is not None else (1.0 if watched else 0.0)

    def mission():
        return run_mission(
            scenario,
            out_dir=args.out,
            meshcat=meshcat,
            record=not args.no_replay,
            progress=not args.quiet,
            realtime_rate=rate,
            live=live,
        )

    try:
        result = _profiled(Path(args.out), mission) if args.profile else mission()
    finally:
        if live is not None:
            live.close()
    if scenario.controller == "taxi":
        print(fleet_summary(result.metrics, args.out))
    else:
        print(_summary(result, scenario))
    if result.metrics.get("interrupted"):
        print(
            f"usvdrake run: interrupted by {stop_reason()} at t = "
            f"{result.metrics['sim_time_s']:.1f} s; outputs written",
            file=sys.stderr,
        )
        return 128 + stop_signal()
    if args.meshcat and sys.stdin.isatty():
        print("Meshcat stays up for the replay; press Ctrl-C to quit.")
        while stop_signal() is None:  # Ctrl-C only asks to stop (usvdrake.run.interrupt)
            time.sleep(0.2)
    return 0
