"""``usvdrake hil``: the hardware diagram against emulated (or real) devices in real time."""

import sys

from hardware_io.transport import PortNotFoundError
from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.run.hil import run_hil


def add_arguments(h) -> None:
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


def run(args) -> int:
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
