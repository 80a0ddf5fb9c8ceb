"""``usvdrake slam2d``: 2D graph SLAM (Pham et al.) on recorded scans."""

import argparse
import json
import sys

from usvdrake.cli._format import table
from usvdrake.errors import ConfigError
from usvdrake.run.slam2d import run_slam2d


def add_arguments(m) -> None:
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
    prior = m.add_mutually_exclusive_group()
    prior.add_argument(
        "--scan-only",
        action="store_true",
        help="ignore the log's wheel odometry (by default it is used where the log has it: a "
        "raw CARMEN log's pose fields, a bag's /odom; a constraint every metre, scaled by what "
        "the scans measured, left out where it contradicts them; a corrected CARMEN log's "
        "pose fields are its reference, not odometry)",
    )
    # the default since issue 38; still accepted so that older command lines run unchanged
    prior.add_argument("--odometry", action="store_true", help=argparse.SUPPRESS)
    m.add_argument(
        "--fast",
        action="store_true",
        help="with odometry, keep up with the robot: search about the odometry's guess, a node "
        "every 0.15 m, loops looked for every 0.3 m (raw CARMEN logs 9-14x real time instead "
        "of 4.2-7.5x; ATE 0.12-0.20 m instead of 0.10-0.17 m; not usable on raw ACES, whose "
        "corridors driven once keep the sparser nodes' heading drift: 3.7 m)",
    )
    m.add_argument("--quiet", action="store_true", help="no progress bar")
    m.add_argument("--json", action="store_true", help="print the metrics as JSON instead")


def run(args) -> int:
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
        progress=not (args.quiet or args.json),
        garbage=args.garbage,
        seed=args.seed,
        full_in_worker=not args.inline,
        relink_radius=args.relink,
        odometry=False if args.scan_only else None,
        fast=args.fast,
        **({} if args.full_period is None else {"full_period": args.full_period}),
        **({} if args.full_budget is None else {"full_budget_ms_per_node": args.full_budget}),
    )
    if args.json:
        print(json.dumps(metrics, indent=2))
    else:
        print("\n".join(table(metrics)))
    files = "trajectory.tum, map.png, metrics.json" + (", ate.png" if args.reference else "")
    print(f"  {files} in {args.out}", file=sys.stderr if args.json else None)
    return 0
