"""``usvdrake slam3d``: lidar-IMU-GPS factor-graph SLAM (Roboat II §V) on a recording, or lidar
only (constant-twist prediction, as KISS-ICP) when the recording has no IMU or with --no-imu."""

import json
import sys
from dataclasses import replace
from pathlib import Path

from usvdrake.cli._format import table
from usvdrake.diagrams import load_scenario
from usvdrake.diagrams.slam import settings_from_scenario
from usvdrake.errors import ConfigError
from usvdrake.run.slam3d import run_slam3d, variant_config, write_keyframes_tum
from usvdrake.scenario import Scenario


def slam3d_settings(scenario=None):
    """(config, mount, datum) of a scenario's (a Scenario, name or YAML path) factor-graph SLAM;
    None: the scenario defaults (``slam.factor_graph``, the GPS antenna height, the 3D lidar's
    mount) and the datum ``amsterdam``."""
    if scenario is None:
        s = Scenario()
        config = replace(s.slam.factor_graph, gps_antenna_height=s.sensors.gps.antenna_height)
        return config, list(s.sensors.lidar3d.mount), "amsterdam"
    if not isinstance(scenario, Scenario):
        scenario = load_scenario(scenario)
    if "lidar3d" not in scenario.sensors.enabled:  # its recordings have no sweeps to map
        raise ConfigError(
            scenario.name,
            "sensors.enabled",
            "a scenario with a 3D lidar ('lidar3d' in the list)",
            repr(scenario.sensors.enabled),
        )
    return settings_from_scenario(scenario)


def add_arguments(s3) -> None:
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
    s3.add_argument(
        "--no-imu",
        action="store_true",
        help="withhold the IMU: lidar only (also when the log has none)",
    )
    s3.add_argument("--no-gps", action="store_true", help="no GPS factors")
    s3.add_argument("--no-loop", "--no-loops", action="store_true", help="no loop closures")
    s3.add_argument("--quiet", action="store_true", help="no progress bar")
    s3.add_argument("--json", action="store_true", help="print the metrics as JSON instead")


def run(args) -> int:
    """Roboat II §V's lidar-IMU-GPS SLAM on a recording with the sensors it has (or fewer, by
    --no-imu / --no-gps / --no-loop): a one-screen summary that names them (or the metrics as
    JSON with --json); with --out, DIR/metrics.json and DIR/trajectory.tum (keyframes, final
    estimates)."""
    if not Path(args.log).exists():
        raise ConfigError(
            args.log, "", "a mission log (.mcap or run folder) or a ROS 1/2 bag", "no such file"
        )
    config, mount, datum = slam3d_settings(args.scenario)
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
        use_imu=False if args.no_imu else None,
    )
    if not result.metrics.get("lidar_messages"):
        skipped = result.metrics.get("skipped_records", 0)
        raise ConfigError(
            str(args.log),
            "",
            "a recording with 3D lidar sweeps (/lidar_points or a PointCloud2 topic)",
            f"none ({skipped} damaged records skipped)"
            if skipped
            else "none (a 2D-only log? usvdrake slam2d reads those)",
        )
    text = json.dumps(result.metrics, indent=2)
    if args.json:
        print(text)
    else:
        m = result.metrics
        print(
            f"usvdrake slam3d {args.log}: {m.get('mode')}, {m.get('slam_keyframes', 0)} keyframes"
        )
        print("\n".join(table(result.metrics)))
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "metrics.json").write_text(text + "\n")
        write_keyframes_tum(out / "trajectory.tum", result)
        print(f"  metrics.json, trajectory.tum in {out}", file=sys.stderr if args.json else None)
    return 0
