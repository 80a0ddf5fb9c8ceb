"""Benchmark: the NMPC's QP solved by the Riccati interior point (``solver="riccati"``, the
default) against the sparse Clarabel QP on Drake's MathematicalProgram (the reference), on the
same real-time-iteration steps.

Roboat II (RK4 at 10 ms, no model error) tracks a 20 m-radius turn at 0.6 m/s from a 10 m /
2.5 rad offset at 10 Hz for 40 s (the start saturates the thrusters, so the boxes are active in
the transient, then the plan is interior); the loop is closed with the Riccati plan. Every step,
both problems solve the SAME QP (same estimate, references and warm start) and each whole
``NmpcProblem.solve`` call is timed (linearisation + QP + overhead: what a control step costs).
Reported: the medians, ``ratio`` = riccati / clarabel (same run), the largest difference of the
two plans (``max_solution_diff``: inputs in N, states in m, m/s, rad), which Clarabel's default
tolerances limit (a 1e-8 gap relative to a cost of ~1e5), hence also the difference to the same
QP in deviations from the linearisation point solved by Clarabel at 1e-12 (untimed), the
interior point's iteration counts and the number of steps with an active bound. Prints one
JSON object.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions

from usvdrake.systems.control.nmpc_problem import NmpcConfig, NmpcProblem
from usvdrake.systems.vessel.vessel_discrete import rk4
from usvdrake.vessel import load_vessel

sys.path.insert(0, str(Path(__file__).parent))
from nmpc import circle_reference  # noqa: E402 - bench/nmpc.py, the same 20 m turn


class Recording(NmpcProblem):
    """Keeps the data of the last Riccati QP (for the untimed reference solve)."""

    def _riccati_step(self, *args):
        self.last = args
        return super()._riccati_step(*args)


def tight_reference(p: NmpcProblem, solver, opts) -> tuple[np.ndarray, np.ndarray]:
    """The Riccati path's last QP, in the same deviations from (q̄, ū), as a sparse
    MathematicalProgram solved by Clarabel at 1e-12: an independent solution of that QP."""
    q_hat, q_ref, u_ref, q_bar, u_bar, q_next, a, b = p.last
    n, nu = p.N, p.nu
    prog = MathematicalProgram()
    dq = prog.NewContinuousVariables(n + 1, 6, "dq")
    du = prog.NewContinuousVariables(n, nu, "du")
    z = np.concatenate([dq.ravel(), du.ravel()])
    h = np.concatenate([p._Qd.ravel(), p._Rd.ravel()])
    g = np.concatenate([(p._Qd * (q_bar - q_ref)).ravel(), (p._Rd * (u_bar - u_ref)).ravel()])
    prog.AddQuadraticCost(np.diag(h), g, z, is_convex=True)
    prog.AddLinearEqualityConstraint(np.eye(6), q_hat - q_bar[0], dq[0])
    for k in range(n):
        prog.AddLinearEqualityConstraint(
            np.hstack([a[k], b[k], -np.eye(6)]),
            q_bar[k + 1] - q_next[k],
            np.concatenate([dq[k], du[k], dq[k + 1]]),
        )
    prog.AddBoundingBoxConstraint((-p._ubx - q_bar)[1:], (p._ubx - q_bar)[1:], dq[1:])
    prog.AddBoundingBoxConstraint(p._lbu - u_bar, p._ubu - u_bar, du)
    result = solver.Solve(prog, None, opts)
    return q_bar + result.GetSolution(dq), u_bar + result.GetSolution(du)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--duration", type=float, default=40.0, help="closed-loop time [s]")
    args = ap.parse_args()
    vessel = load_vessel("roboat2")
    ric = Recording(vessel, NmpcConfig(solver="riccati"))
    cla = NmpcProblem(vessel, NmpcConfig(solver="clarabel"))
    q = np.array([0.0, 10.0, 2.5, 0.0, 0.0, 0.0])
    times = ric.dt * np.arange(ric.N + 1)
    # compile / warm up both outside the timing
    q_ref, nd = circle_reference(times)
    u_ref = ric.feedforward(q_ref, nd)
    ric.solve(q, q_ref, u_ref)
    cla.solve(q, q_ref, u_ref)
    # the same QP once more at 1e-12 (untimed): how close the Riccati solution really is
    tight, opts = ClarabelSolver(), SolverOptions()
    for key in ("tol_gap_abs", "tol_gap_rel", "tol_feas", "tol_ktratio"):
        opts.SetOption(tight.id(), key, 1e-12)
    t_ric, t_cla, iters, active = [], [], [], 0
    diff_u, diff_q, tight_u, tight_q = 0.0, 0.0, 0.0, 0.0
    warm = None
    vb = np.asarray(ric.cfg.velocity_bounds)
    for j in range(int(round(args.duration / ric.dt))):
        q_ref, nd = circle_reference(j * ric.dt + times)
        u_ref = ric.feedforward(q_ref, nd)
        a = ric.solve(q, q_ref, u_ref, warm)
        b = cla.solve(q, q_ref, u_ref, warm)
        if not (a.success and b.success):
            raise SystemExit(f"step {j}: riccati {a.status!r}, clarabel {b.status!r}")
        t_ric.append(a.solve_ms)
        t_cla.append(b.solve_ms)
        iters.append(ric.qp_iterations)
        diff_u = max(diff_u, float(np.max(np.abs(a.u - b.u))))
        diff_q = max(diff_q, float(np.max(np.abs(a.q - b.q))))
        ref_q, ref_u = tight_reference(ric, tight, opts)
        tight_u = max(tight_u, float(np.max(np.abs(a.u - np.clip(ref_u, -50.0, 50.0)))))
        tight_q = max(tight_q, float(np.max(np.abs(a.q - ref_q))))
        active += bool(
            np.any(np.abs(a.u) > ric.u_max - 1e-6) or np.any(np.abs(a.q[1:, 3:]) > vb - 1e-6)
        )
        warm = ric.shift(a.q, a.u)
        for _ in range(10):
            q = rk4(ric.xi, q[None], (ric.B_thr @ a.u[0])[None], 0.01)[0]
    r_ms, c_ms = float(np.median(t_ric)), float(np.median(t_cla))
    print(
        json.dumps(
            {
                "steps": len(t_ric),
                "riccati_ms_median": round(r_ms, 3),
                "clarabel_ms_median": round(c_ms, 3),
                "ratio": round(r_ms / c_ms, 3),
                "riccati_ms_p95": round(float(np.percentile(t_ric, 95)), 3),
                "clarabel_ms_p95": round(float(np.percentile(t_cla, 95)), 3),
                "max_solution_diff": max(diff_u, diff_q),
                "max_solution_diff_u_N": diff_u,
                "max_solution_diff_q": diff_q,
                "max_solution_diff_vs_tight_clarabel": max(tight_u, tight_q),
                "riccati_iterations_median": float(np.median(iters)),
                "riccati_iterations_max": int(max(iters)),
                "steps_with_active_bounds": active,
            }
        )
    )


if __name__ == "__main__":
    main()
