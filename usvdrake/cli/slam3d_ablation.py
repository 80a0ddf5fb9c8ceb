"""``usvdrake slam3d-ablation``: Roboat II §VI-A's ablation (lidar / + GPS / + GPS + loop) on a
recording or on a scenario recorded first."""

import json
from pathlib import Path

from usvdrake.cli.slam3d import slam3d_settings
from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.errors import ConfigError
from usvdrake.logs.rosbag import is_bag
from usvdrake.run.mission import run_mission
from usvdrake.run.slam3d import ablation_rows, format_table, plot_ablation, run_ablation


def _is_recording(text: str) -> bool:
    """A mission log (.mcap or a folder with log.mcap) or a ROS bag, as opposed to a scenario."""
    p = Path(text)
    return (p.is_file() and p.suffix in (".mcap", ".bag")) or (
        p.is_dir() and ((p / "log.mcap").is_file() or is_bag(p))
    )


def add_arguments(ab) -> None:
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


def run(args) -> int:
    """Roboat II §VI-A's ablation (lidar / + GPS / + GPS + loop) on a recording, or on a scenario
    recorded first into DIR/recording: table to stdout, DIR/ablation.json, DIR/ablation.png."""
    out = Path(args.out)
    source = args.source
    if _is_recording(source):
        config, mount, datum = slam3d_settings(args.scenario)
        log = Path(source)
    else:
        if Path(source).suffix in (".mcap", ".bag") and not Path(source).exists():
            raise ConfigError(source, "", "a mission log, a ROS bag or a scenario", "no such file")
        scenario = with_overrides(load_scenario(source), duration=args.duration)
        config, mount, datum = slam3d_settings(scenario)
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
    print(f"usvdrake slam3d-ablation {log} (Roboat II §VI-A)")
    print(format_table(rows))
    print(f"  ablation.json, ablation.png in {out}")
    return 0
