"""The ``usvdrake`` command: ``run`` a scenario, ``campaign`` it over random days, ``bench`` a
benchmark, ``identify`` ξ, run SLAM offline (``slam2d``, ``slam3d``, ``slam3d-ablation``)."""

import argparse
import runpy
import sys
import time
from pathlib import Path

from usvdrake.typed_yaml import ConfigError

BENCH_DIR = Path(__file__).resolve().parents[1] / "bench"


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


def cmd_run(args) -> int:
    from usvdrake.mission import make_meshcat, run_mission
    from usvdrake.scenario import load_scenario, with_overrides

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
        from usvdrake.fleet import fleet_summary

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


def cmd_hil(args) -> int:
    from hardware_io.transport import PortNotFoundError
    from usvdrake.hil import run_hil
    from usvdrake.scenario import load_scenario, with_overrides

    scenario = with_overrides(load_scenario(args.scenario), seed=args.seed)
    try:
        result = run_hil(
            scenario,
            args.out,
            duration=args.duration,
            corruption=args.corrupt,
            cut_link=not args.no_cut,
            compare_sim=not args.no_compare,
            progress=not args.quiet,
            emulated=not args.devices,
        )
    except (PortNotFoundError, ValueError, RuntimeError) as e:
        print(f"usvdrake hil: error: {e}", file=sys.stderr)
        return 2
    m = result.metrics
    keys = [
        "position_rmse_m",
        "sim_position_rmse_m",
        "position_rmse_ratio_vs_sim",
        "heading_rmse_rad",
        "nmpc_failures",
        "watchdog_latency_ms",
        "realtime_lag_s",
    ]
    print(f"usvdrake hil {scenario.name}: {m['tracked_until_s']:.1f} s in real time")
    for key in keys:
        if m.get(key) is not None:
            value = m[key]
            print(
                f"  {key:<28} {value:.4g}" if isinstance(value, float) else f"  {key:<28} {value}"
            )
    for name, path in result.files.items():
        print(f"  {name:<10} {path}")
    return 0


def cmd_campaign(args) -> int:
    """Monte Carlo over random days (usvdrake.campaign): DIR/campaign.json, report.html, runs/."""
    from usvdrake.campaign import run_campaign
    from usvdrake.scenario import load_scenario

    for flag, value in (("--runs", args.runs), ("--workers", args.workers)):
        if value < 1:
            raise ConfigError("command line", flag, "an integer >= 1", value)
    if args.seed < 0:
        raise ConfigError("command line", "--seed", "an integer >= 0", args.seed)
    scenario = load_scenario(args.scenario)
    c = run_campaign(
        scenario,
        args.runs,
        workers=args.workers,
        scheduler=args.scheduler,
        seed=args.seed,
        out_dir=args.out,
        duration=args.duration,
        progress=not args.quiet,
    )
    s = c["summary"]
    print(
        f"usvdrake campaign {c['scenario']}: {s['runs']} runs (seed {c['campaign_seed']}) on "
        f"{c['workers']} workers in {c['wall_time_s']:.1f} s wall\n"
        f"  {s['completed']} completed, {s['failed']} failed; success (mission complete, no "
        f"collision) {s['successes']}/{s['runs']} = {100 * s['success_rate']:.1f} %"
    )
    for key in list(s["metrics"])[:6]:
        st = s["metrics"][key]
        print(f"  {key:<28} median {st['median']:.4g}  p5 {st['p5']:.4g}  p95 {st['p95']:.4g}")
    out = Path(args.out)
    for name in ("campaign.json", "report.html", "runs"):
        print(f"  {name:<14} {out / name}")
    return 0 if s["completed"] else 1


def cmd_bench(args) -> int:
    path = BENCH_DIR / f"{args.name}.py"
    if not path.is_file():
        names = sorted(p.stem for p in BENCH_DIR.glob("*.py")) if BENCH_DIR.is_dir() else []
        raise ConfigError(
            "bench", "name", "one of " + (", ".join(names) or "(no bench/ folder)"), repr(args.name)
        )
    sys.argv = [str(path), *args.args]
    runpy.run_path(str(path), run_name="__main__")
    return 0


def _guess_factors(text: str) -> tuple[float, ...]:
    try:
        factors = tuple(float(x) for x in text.split(","))
    except ValueError:
        factors = ()
    if len(factors) not in (1, 6) or not all(f > 0 for f in factors):
        raise ConfigError(
            "command line", "--initial-guess", "one or six positive factors, comma-separated", text
        )
    return factors * 6 if len(factors) == 1 else factors


def cmd_identify(args) -> int:
    """000 eq. (9) on a log folder: table to stdout, DIR/xi.json and DIR/fit.png."""
    import json

    import numpy as np

    from usvdrake.systems.estimation import identification as ident
    from usvdrake.systems.estimation.identification_data import fixed_thruster_matrix, read_log
    from usvdrake.vessel import load_vessel

    factors = (
        ident.DEFAULT_GUESS_FACTORS
        if args.initial_guess is None
        else _guess_factors(args.initial_guess)
    )
    if args.substeps < 1:
        raise ConfigError("command line", "--substeps", "an integer >= 1", args.substeps)
    vessel = load_vessel(args.vessel) if args.vessel else None
    log = read_log(args.data, vessel)
    vessel = vessel or load_vessel(log.vessel)
    guess = vessel.hydrodynamics.as_vector() * np.array(factors)
    options = ident.IdentificationOptions(substeps=args.substeps)
    result, data = ident.identify_log(log, fixed_thruster_matrix(vessel), guess, options)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    summary = {
        "data": str(args.data),
        "vessel": vessel.name,
        **ident.result_dict(result, log.true_xi),
    }
    (out / "xi.json").write_text(json.dumps(summary, indent=2) + "\n")
    ident.plot_fit(data, result, out / "fit.png", substeps=args.substeps, title=str(args.data))
    print(f"usvdrake identify {args.data}: {len(log.trials)} trials, vessel {vessel.name}")
    print(ident.format_summary(result, log.true_xi))
    print(f"  xi.json    {out / 'xi.json'}\n  fit.png    {out / 'fit.png'}")
    return 0 if result.success else 1


def cmd_identify_data(args) -> int:
    """A synthetic 000 §VI-B data set (true ξ from the vessel file) as a log folder."""
    from usvdrake.systems.estimation.identification_data import (
        ExcitationExperiment,
        simulate_experiment,
        write_log,
    )
    from usvdrake.vessel import load_vessel

    experiment = ExcitationExperiment(trials=args.trials, duration_s=args.duration)
    if experiment.trials < 1 or not experiment.duration_s >= 1.0:
        raise ConfigError(
            "command line",
            "--trials/--duration",
            ">= 1 trial of >= 1 s",
            f"{args.trials} trials of {args.duration} s",
        )
    log = simulate_experiment(load_vessel(args.vessel), args.seed, experiment)
    folder = write_log(log, args.out)
    print(f"wrote {len(log.trials)} trials of ~{args.duration:g} s (seed {args.seed}) to {folder}")
    return 0


def make_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="usvdrake", description="Autonomous surface vessels as Drake diagrams."
    )
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="simulate a scenario and write metrics, replay and report")
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
    r.set_defaults(func=cmd_run)
    h = sub.add_parser(
        "hil",
        help="hardware-in-the-loop: the hardware diagram against emulated devices in real time",
    )
    h.add_argument("scenario", help="shipped scenario name or YAML path")
    h.add_argument("--duration", type=float, default=None, help="tracked time [s] (wall clock)")
    h.add_argument("--seed", type=int, default=None, help="override the scenario seed")
    h.add_argument("--out", default="out/hil", help="output folder (default: out/hil)")
    h.add_argument(
        "--corrupt", type=float, default=0.0, help="fraction of bytes corrupted on every wire"
    )
    h.add_argument("--no-cut", action="store_true", help="do not cut the thruster wire at the end")
    h.add_argument(
        "--no-compare", action="store_true", help="skip the pure-simulation comparison run"
    )
    h.add_argument(
        "--devices",
        action="store_true",
        help="use the real devices on the scenario's hardware ports instead of emulators",
    )
    h.add_argument("--quiet", action="store_true", help="no progress bar")
    h.set_defaults(func=cmd_hil)
    c = sub.add_parser("campaign", help="Monte Carlo: run a scenario over many random days (Dask)")
    c.add_argument("scenario", help="shipped scenario name or YAML path")
    c.add_argument("--runs", type=int, required=True, help="number of randomised runs")
    c.add_argument(
        "--workers", type=int, default=2, help="local Dask worker processes (default: 2)"
    )
    c.add_argument(
        "--scheduler", default=None, help="address of an existing Dask scheduler (tcp://HOST:PORT)"
    )
    c.add_argument("--seed", type=int, default=0, help="campaign seed (run i: its child i)")
    c.add_argument(
        "--duration", type=float, default=None, help="override the simulated duration [s]"
    )
    c.add_argument("--out", default="out/campaign", help="output folder (default: out/campaign)")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_campaign)
    b = sub.add_parser("bench", help="run bench/NAME.py (prints one JSON object)")
    b.add_argument("name")
    b.add_argument("args", nargs=argparse.REMAINDER)
    b.set_defaults(func=cmd_bench)
    i = sub.add_parser("identify", help="fit ξ = [m11 m22 m33 Xu Yv Nr] to a log (000 eq. 9)")
    i.add_argument("data", help="identification log folder (meta.json + trial_NN.csv)")
    i.add_argument("--out", default="out/identify", help="output folder (default: out/identify)")
    i.add_argument("--vessel", default=None, help="vessel name or YAML (default: the log's)")
    i.add_argument(
        "--initial-guess",
        default=None,
        help="start = factor(s) × the vessel file's ξ, one number or six comma-separated "
        "(default: 0.6,1.4,1.5,0.65,1.4,0.6, each component 35-50 %% off)",
    )
    i.add_argument("--substeps", type=int, default=1, help="RK4 steps per sample interval")
    i.set_defaults(func=cmd_identify)
    d = sub.add_parser("identify-data", help="write a synthetic identification log (000 §VI-B)")
    d.add_argument("out", help="output folder")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--vessel", default="roboat2", help="vessel name or YAML (its ξ is the truth)")
    d.add_argument("--trials", type=int, default=5)
    d.add_argument("--duration", type=float, default=150.0, help="nominal trial length [s]")
    d.set_defaults(func=cmd_identify_data)
    m = sub.add_parser(
        "slam2d", help="2D graph SLAM (002) on recorded scans (scan only unless --odometry)"
    )
    m.add_argument(
        "log", help="CARMEN .clf/.log (plain, gzip or bzip2), ROS 1 .bag or ROS 2 bag folder"
    )
    m.add_argument("--out", default="out/slam2d", help="output folder")
    m.add_argument(
        "--reference",
        default=None,
        help="a log whose poses are ground truth (ATE): a corrected CARMEN log pairs with the "
        "raw log's scans by their ranges, anything else by time stamp",
    )
    m.add_argument("--resolution", type=float, default=0.1, help="map cell size [m]")
    m.add_argument("--max-scans", type=int, default=None, help="stop after this many scans")
    m.add_argument(
        "--garbage",
        type=float,
        default=0.0,
        help="robustness test: replace this fraction of scans by garbage (random, half-empty, NaN)",
    )
    m.add_argument("--seed", type=int, default=0, help="which scans --garbage replaces")
    m.add_argument(
        "--full-period",
        type=float,
        default=None,
        help="log time [s] between full-graph optimisations after loops (default 3; 0: every scan)",
    )
    m.add_argument(
        "--full-budget",
        type=float,
        default=None,
        metavar="MS_PER_NODE",
        help="log time a full optimisation in the worker may take before the scans wait for "
        "it: this many ms per graph node, at least the full period (default 2)",
    )
    m.add_argument(
        "--inline",
        action="store_true",
        help="solve each full optimisation in this process when it starts (default: in a worker "
        "process while the scans go on, merged a full period later)",
    )
    m.add_argument(
        "--relink",
        type=float,
        default=None,
        metavar="RADIUS",
        help="after the last scan, link every node to the older ones within RADIUS [m] by PLICP "
        "from the final estimate and optimise again (slow: all pairs; default off)",
    )
    m.add_argument(
        "--odometry",
        action="store_true",
        help="use a raw CARMEN log's wheel odometry as well: a constraint every metre, "
        "scaled by what the scans measured, left out where it contradicts them (not "
        "scan-only; a corrected log's pose fields are its reference, not odometry)",
    )
    m.add_argument("--quiet", action="store_true", help="no progress bar")
    m.set_defaults(func=cmd_slam2d)
    s3 = sub.add_parser("slam3d", help="lidar-IMU-GPS factor-graph SLAM (000 §V) on a recording")
    s3.add_argument("log", help="mission log (.mcap or run folder), ROS 1 .bag or ROS 2 bag folder")
    s3.add_argument("--out", default=None, help="write metrics.json and trajectory.tum here")
    s3.add_argument("--lidar-topic", default=None, help="PointCloud2 / /lidar_points topic")
    s3.add_argument("--imu-topic", default=None, help="Imu / /imu topic")
    s3.add_argument("--gps-topic", default=None, help="NavSatFix / /gps topic")
    s3.add_argument(
        "--datum", default=None, help="origin of the world ENU frame (default: amsterdam)"
    )
    s3.add_argument(
        "--scenario",
        default=None,
        help="take the SLAM config, lidar mount and datum from this scenario (default: defaults)",
    )
    s3.add_argument("--no-gps", action="store_true", help="no GPS factors")
    s3.add_argument("--no-loop", action="store_true", help="no loop closures")
    s3.add_argument("--quiet", action="store_true", help="no progress bar")
    s3.set_defaults(func=cmd_slam3d)
    ab = sub.add_parser(
        "slam3d-ablation",
        help="000 §VI-A ablation: lidar / + GPS / + GPS + loop on a recording or a scenario",
    )
    ab.add_argument(
        "source",
        help="mission log or ROS bag; or a scenario (name or YAML, slam.method factor_graph) "
        "to record first",
    )
    ab.add_argument("--out", default="out/slam3d_ablation", help="output folder")
    ab.add_argument(
        "--duration", type=float, default=None, help="scenario: override the simulated duration"
    )
    ab.add_argument(
        "--scenario", default=None, help="recording: take SLAM config, mount, datum from this"
    )
    ab.add_argument("--datum", default=None, help="origin of the world ENU frame")
    ab.add_argument("--quiet", action="store_true", help="no progress bar")
    ab.set_defaults(func=cmd_slam3d_ablation)
    a = sub.add_parser("analyze", help="analyses of a scenario's closed loop")
    what = a.add_subparsers(dest="analysis", required=True)
    st = what.add_parser(
        "stability",
        help="closed-loop eigenvalues (continuous and sampled), margins, region of attraction",
    )
    st.add_argument("scenario", help="a shipped scenario name or a YAML path")
    st.add_argument("--out", default=None, help="write analysis.json and plots here")
    st.add_argument(
        "--samples", type=int, default=10_000, help="states sampled to check the region (V̇ < 0)"
    )
    st.set_defaults(func=cmd_analyze_stability)
    return p


def cmd_analyze_stability(args) -> int:
    """Table to stdout; with --out, DIR/analysis.json, pole map, Bode plots, region slices."""
    from usvdrake.analysis.stability import analyze_stability, format_table
    from usvdrake.scenario import load_scenario

    if args.samples < 0:
        raise ConfigError("command line", "--samples", "an integer >= 0", args.samples)
    result = analyze_stability(load_scenario(args.scenario), args.out, roa_samples=args.samples)
    print(format_table(result))
    if args.out:
        print(f"  analysis.json and plots in {args.out}")
    unstable = [
        name
        for name, loop in result.get("loops", {}).items()
        if any(loop.get(k, {}).get("stable") is False for k in ("continuous", "sampled"))
    ]
    return 1 if unstable else 0


def cmd_slam2d(args) -> int:
    from usvdrake.systems.slam.offline import run_slam2d

    if not 0.0 <= args.garbage <= 1.0:
        raise ConfigError("command line", "--garbage", "a fraction in [0, 1]", args.garbage)
    if args.full_period is not None and not args.full_period >= 0.0:
        raise ConfigError("command line", "--full-period", "a time >= 0 s", args.full_period)
    if args.full_budget is not None and not args.full_budget >= 0.0:
        raise ConfigError("command line", "--full-budget", "ms per node >= 0", args.full_budget)
    if args.relink is not None and not args.relink >= 0.0:
        raise ConfigError("command line", "--relink", "a radius >= 0 m", args.relink)
    metrics = run_slam2d(
        args.log,
        args.out,
        args.reference,
        args.resolution,
        args.max_scans,
        progress=not args.quiet,
        garbage=args.garbage,
        seed=args.seed,
        full_in_worker=not args.inline,
        relink_radius=args.relink,
        odometry=args.odometry,
        **({} if args.full_period is None else {"full_period": args.full_period}),
        **({} if args.full_budget is None else {"full_budget_ms_per_node": args.full_budget}),
    )
    width = max(len(k) for k in metrics)
    for key, value in metrics.items():
        print(
            f"  {key:<{width}} {value:.4g}"
            if isinstance(value, float)
            else f"  {key:<{width}} {value}"
        )
    files = "trajectory.tum, map.png, metrics.json" + (", ate.png" if args.reference else "")
    print(f"  {files} in {args.out}")
    return 0


def _slam3d_settings(scenario=None):
    """(config, mount, datum) of a scenario's (a Scenario, name or YAML path) factor-graph SLAM;
    None: the scenario defaults (``slam.factor_graph``, the GPS antenna height, the 3D lidar's
    mount) and the datum ``amsterdam``."""
    from dataclasses import replace

    from usvdrake.scenario import Scenario, load_scenario
    from usvdrake.slam3d import settings_from_scenario

    if scenario is None:
        s = Scenario()
        config = replace(s.slam.factor_graph, gps_antenna_height=s.sensors.gps.antenna_height)
        return config, list(s.sensors.lidar3d.mount), "amsterdam"
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    if scenario.slam.method != "factor_graph":
        raise ConfigError(scenario.name, "slam.method", "factor_graph", repr(scenario.slam.method))
    return settings_from_scenario(scenario)


def _is_recording(text: str) -> bool:
    """A mission log (.mcap or a folder with log.mcap) or a ROS bag, as opposed to a scenario."""
    from usvdrake.logs.rosbag import is_bag

    p = Path(text)
    return (p.is_file() and p.suffix in (".mcap", ".bag")) or (
        p.is_dir() and ((p / "log.mcap").is_file() or is_bag(p))
    )


def cmd_slam3d(args) -> int:
    """000 §V's lidar-IMU-GPS SLAM on a recording: metrics JSON to stdout; with --out,
    DIR/metrics.json and DIR/trajectory.tum (keyframes, final estimates)."""
    import json

    from usvdrake.slam3d import run_slam3d, variant_config, write_keyframes_tum

    if not Path(args.log).exists():
        raise ConfigError(
            args.log, "", "a mission log (.mcap or run folder) or a ROS 1/2 bag", "no such file"
        )
    config, mount, datum = _slam3d_settings(args.scenario)
    config = variant_config(
        config,
        config.graph.use_gps and not args.no_gps,
        config.graph.use_loop_closure and not args.no_loop,
    )
    result = run_slam3d(
        args.log,
        config,
        mount=mount,
        datum=args.datum or datum,
        progress=not args.quiet,
        lidar_topic=args.lidar_topic,
        imu_topic=args.imu_topic,
        gps_topic=args.gps_topic,
    )
    text = json.dumps(result.metrics, indent=2)
    print(text)
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "metrics.json").write_text(text + "\n")
        write_keyframes_tum(out / "trajectory.tum", result)
        print(f"  metrics.json, trajectory.tum in {out}", file=sys.stderr)
    return 0


def cmd_slam3d_ablation(args) -> int:
    """000 §VI-A's ablation (lidar / + GPS / + GPS + loop) on a recording, or on a scenario
    recorded first into DIR/recording: table to stdout, DIR/ablation.json, DIR/ablation.png."""
    import json

    from usvdrake.slam3d import ablation_rows, format_table, plot_ablation, run_ablation

    out = Path(args.out)
    source = args.source
    if _is_recording(source):
        config, mount, datum = _slam3d_settings(args.scenario)
        log = Path(source)
    else:
        from usvdrake.mission import run_mission
        from usvdrake.scenario import load_scenario, with_overrides

        if Path(source).suffix in (".mcap", ".bag") and not Path(source).exists():
            raise ConfigError(source, "", "a mission log, a ROS bag or a scenario", "no such file")
        scenario = with_overrides(load_scenario(source), duration=args.duration)
        config, mount, datum = _slam3d_settings(scenario)
        recording = out / "recording"
        print(f"usvdrake slam3d-ablation: recording {scenario.name} into {recording}")
        run_mission(scenario, out_dir=recording, record=False, progress=not args.quiet)
        log = recording / "log.mcap"
    results = run_ablation(
        log, config, mount=mount, datum=args.datum or datum, progress=not args.quiet
    )
    rows = ablation_rows(results)
    out.mkdir(parents=True, exist_ok=True)
    (out / "ablation.json").write_text(
        json.dumps({"log": str(log), "variants": rows}, indent=2) + "\n"
    )
    plot_ablation(results, results[0].truth, out / "ablation.png")
    print(f"usvdrake slam3d-ablation {log} (000 §VI-A)")
    print(format_table(rows))
    print(f"  ablation.json, ablation.png in {out}")
    return 0


def main(argv=None) -> int:
    args = make_parser().parse_args(argv)
    try:
        return args.func(args)
    except ConfigError as e:
        print(f"usvdrake: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
