"""``usvdrake identify-data``: write a synthetic identification log (Roboat II §VI-B)."""

from usvdrake.errors import ConfigError
from usvdrake.systems.estimation.identification_data import (
    ExcitationExperiment,
    simulate_experiment,
    write_log,
)
from usvdrake.vessel import load_vessel


def add_arguments(d) -> None:
    d.add_argument("out", help="output folder")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--vessel", default="roboat2", help="vessel name or YAML (its ξ is the truth)")
    d.add_argument("--trials", type=int, default=5)
    d.add_argument("--duration", type=float, default=150.0, help="nominal trial length [s]")


def run(args) -> int:
    """A synthetic Roboat II §VI-B data set (true ξ from the vessel file) as a log folder."""
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
