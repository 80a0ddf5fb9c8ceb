"""``usvdrake analyze ANALYSIS``: analyses of a scenario's closed loop (today: ``stability``)."""

from usvdrake.analysis.stability import analyze_stability, format_table
from usvdrake.diagrams import load_scenario
from usvdrake.errors import ConfigError


def add_arguments(a) -> None:
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
    st.set_defaults(analyze=stability)


def run(args) -> int:
    return args.analyze(args)


def stability(args) -> int:
    """Table to stdout; with --out, DIR/analysis.json, pole map, Bode plots, region slices."""
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
