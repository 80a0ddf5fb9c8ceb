"""``usvdrake identify``: fit ξ = [m11 m22 m33 Xu Yv Nr] to a log (Roboat II eq. 9)."""

import json
from pathlib import Path

import numpy as np

from usvdrake.errors import ConfigError
from usvdrake.systems.estimation import identification as ident
from usvdrake.systems.estimation.identification_data import fixed_thruster_matrix, read_log
from usvdrake.vessel import load_vessel


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


def add_arguments(i) -> None:
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


def run(args) -> int:
    """Roboat II eq. (9) on a log folder: table to stdout, DIR/xi.json and DIR/fit.png."""
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
