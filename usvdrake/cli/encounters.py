"""``usvdrake encounters [DIR_OR_FILES | standard] --out OUT``: a set of traffic situations on
Dask (default: DNV's 40-situation standard encounter set shipped with usvdrake)."""

from pathlib import Path

from usvdrake.cli._format import num, table
from usvdrake.cli.encounter import add_config_arguments, config_from
from usvdrake.errors import ConfigError
from usvdrake.run.encounter import CANAL, STANDARD, run_encounters


def add_arguments(p) -> None:
    p.add_argument(
        "paths", nargs="*", default=[STANDARD],
        help=f"situation files or folders, '{STANDARD}' (default: DNV's 40 shipped situations) "
        f"or '{CANAL}' (the 25 canal-scale ones for Roboat II)",
    )  # fmt: skip
    p.add_argument("--out", default="out/encounters", help="output folder")
    p.add_argument("--workers", type=int, default=2, help="local Dask workers (default: 2)")
    p.add_argument(
        "--scheduler", default=None, help="address of an existing Dask scheduler (tcp://HOST:PORT)"
    )
    add_config_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _row(entry: dict) -> str:
    types = ",".join(entry["encounters"]) or "-"
    ok = sum(entry["compliant"])
    return (
        f"{types:<22} CPA {num(entry['min_cpa_m'], '7.4g', ' m')}  compliant {ok}/"
        f"{len(entry['compliant'])}  collisions {entry['collisions']}  "
        f"{'arrived' if entry['arrived'] else 'NOT arrived'}  path × {entry['path_ratio']:.3f}"
    )


def run(args) -> int:
    if args.workers < 1:
        raise ConfigError("command line", "--workers", "an integer >= 1", args.workers)
    s = run_encounters(
        args.paths,
        args.out,
        args.workers,
        args.scheduler,
        config_from(args),
        not args.quiet,
        own=args.own,
    )
    rows = {
        e["situation"].removeprefix("traffic_situation_").removeprefix("canal_situation_"): _row(e)
        for e in s["entries"]
    }
    print("\n".join(table(rows)))
    for f in s["failed"]:
        print(f"  {f['situation']}: FAILED {f['error']}")
    compliance = s["colreg_compliance"]
    print(
        f"usvdrake encounters: {s['situations']} situations in {s['wall_s']:.1f} s wall on "
        f"{s['workers']} workers; collisions {s['collisions']}, min CPA "
        f"{num(s['min_cpa_m'], '.4g', ' m')} (required {num(s['safety_distance_m'], '.4g')} m), "
        f"COLREG "
        f"compliance {num(None if compliance is None else 100 * compliance, '.1f', ' %')} of "
        f"{s['encounters']} encounters, arrived {s['arrived']}/{s['situations']}, max path × "
        f"{num(s['max_path_ratio'], '.3f')}, SB-MPC median {num(s['colav_ms_median'], '.2f')} ms"
    )
    print(f"  summary.json   {Path(args.out) / 'summary.json'}")
    return 1 if s["failed"] else 0  # verdicts are in the table and summary.json
