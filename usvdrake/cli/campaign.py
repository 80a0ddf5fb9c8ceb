"""``usvdrake campaign``: Monte Carlo over many random days (Dask)."""

from pathlib import Path

from usvdrake.diagrams import load_scenario
from usvdrake.errors import ConfigError
from usvdrake.run.campaign import run_campaign


def add_arguments(c) -> None:
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


def run(args) -> int:
    """Monte Carlo over random days (usvdrake.run.campaign):
    DIR/campaign.json, report.html, runs/."""
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
    outcomes = s.get("outcomes", {})
    misses = [f"{n} {k}" for k, n in outcomes.items() if k != "success" and n]
    if misses:
        print("  not successful: " + ", ".join(misses))
        if outcomes.get("timed out") and args.duration is not None:
            print(
                f"  (--duration {args.duration:g} s ended those missions before they completed; "
                f"the scenario's own is {scenario.duration:g} s)"
            )
    for key in list(s["metrics"])[:6]:
        st = s["metrics"][key]
        print(f"  {key:<28} median {st['median']:.4g}  p5 {st['p5']:.4g}  p95 {st['p95']:.4g}")
    out = Path(args.out)
    for name in ("campaign.json", "report.html", "runs"):
        print(f"  {name:<14} {out / name}")
    return 0 if s["completed"] else 1
