"""``usvdrake hil``: the hardware diagram against emulated (or real) devices in real time.

Exit 0 when the run ended with every device there, 2 on a bad argument or a missing port, and 2
with every output written when a device (or the emulator rig) was gone at the end of the run.
"""

import sys

from hardware_io.transport import PortNotFoundError
from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.run.hil import parse_rig_event, run_hil
from usvdrake.run.interrupt import stop_reason, stop_signal


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
    h.add_argument(
        "--rig-event",
        action="append",
        default=[],
        metavar="T:COMMAND",
        help="at T s of simulated time tell the rig COMMAND: unplug DEVICE, replug DEVICE, "
        "cut thrusters, or kill (the rig dies); repeatable, e.g. '3:unplug gps' '6:replug gps'",
    )
    h.add_argument("--quiet", action="store_true", help="no progress bar")


def run(args) -> int:
    scenario = with_overrides(load_scenario(args.scenario), seed=args.seed)
    try:
        events = [parse_rig_event(text) for text in args.rig_event]
        result = run_hil(
            scenario,
            args.out,
            duration=args.duration,
            corruption=args.corrupt,
            cut_link=not args.no_cut,
            compare_sim=not args.no_compare,
            progress=not args.quiet,
            emulated=not args.devices,
            rig_events=events,
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
        "watchdog_trips",
        "device_disconnects",
        "device_reconnects",
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
    if m.get("interrupted"):
        print(f"usvdrake hil: interrupted by {stop_reason()}; outputs written", file=sys.stderr)
        return 128 + stop_signal()
    lost = m.get("devices_disconnected") or []
    if lost or m.get("rig_error"):
        why = m.get("rig_error") or "device(s) " + ", ".join(lost) + " gone at the end of the run"
        print(f"usvdrake hil: error: {why}", file=sys.stderr)
        return 2
    return 0
