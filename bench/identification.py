"""Benchmark: grey-box identification of Roboat II's ξ by SQP (Roboat II §IV-A eq. 9, §VI-B).

Simulates Roboat II's experiment (5 trials of ~150 s of remote-controlled sinusoidal thrust, 10 Hz,
noisy velocities and thrusts; ``--seed``), round-trips it through the log format, and fits
ξ = [m11 m22 m33 Xu Yv Nr] with SNOPT from a start each component of which is 35-50 % off the
truth. Prints one JSON object. Target: every component within 3 % of the truth.
"""

import argparse
import json
import platform
import tempfile
import time

import numpy as np

from usvdrake.systems.estimation.identification import (
    DEFAULT_GUESS_FACTORS,
    IdentificationOptions,
    identify_log,
)
from usvdrake.systems.estimation.identification_data import (
    XI_NAMES,
    fixed_thruster_matrix,
    read_log,
    simulate_experiment,
    write_log,
)
from usvdrake.vessel import load_vessel

TARGET = 0.03


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--vessel", default="roboat2")
    args = parser.parse_args()
    vessel = load_vessel(args.vessel)
    t0 = time.perf_counter()
    simulated = simulate_experiment(vessel, args.seed)
    data_time = time.perf_counter() - t0
    with tempfile.TemporaryDirectory() as tmp:
        log = read_log(write_log(simulated, tmp), vessel)
    truth = log.true_xi.as_vector()
    guess = truth * np.array(DEFAULT_GUESS_FACTORS)
    result, _ = identify_log(log, fixed_thruster_matrix(vessel), guess, IdentificationOptions())
    rel = np.abs(result.xi.as_vector() - truth) / truth

    def named(values, digits):
        return {n: round(float(x), digits) for n, x in zip(XI_NAMES, values, strict=True)}

    print(
        json.dumps(
            {
                "benchmark": "identification",
                "vessel": vessel.name,
                "seed": args.seed,
                "trials": len(log.trials),
                "samples": int(sum(len(t.t) for t in log.trials)),
                "initial_max_rel_error": round(float(np.max(np.abs(guess - truth) / truth)), 4),
                "xi_max_rel_error": round(float(rel.max()), 5),
                **{f"{n}_rel_error": e for n, e in named(rel, 5).items()},
                "xi": named(result.xi.as_vector(), 3),
                "std": named(result.std, 3),
                "solve_time_s": round(result.solve_time_s, 3),
                "iterations": result.iterations,
                "evaluations": result.evaluations,
                "cost": round(result.cost, 2),
                "initial_cost": round(result.initial_cost, 1),
                "n_residuals": result.n_residuals,
                "residual_variance": round(result.residual_variance, 4),
                "converged": result.success,
                "data_time_s": round(data_time, 3),
                "target_max_rel_error": TARGET,
                "target_met": bool(rel.max() <= TARGET),
                "python": platform.python_version(),
            }
        )
    )


if __name__ == "__main__":
    main()
