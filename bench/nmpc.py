"""Benchmark: the NMPC of Roboat II §IV-B — our real-time iteration on Drake's MathematicalProgram
against the same OCP solved by CasADi + IPOPT (a benchmark-only extra: ``pip install casadi``).

Both controllers close the loop on the same simulated Roboat II (RK4 at 10 ms, no model error)
tracking a 20 m-radius turn at 0.6 m/s from a 0.5 m / 0.3 rad offset, 10 Hz, 40 s. Reported:
solve time median / p95 of each, ``nmpc_vs_casadi_ratio`` = our median / CasADi's median, and
the closed-loop tracking cost (eq. 10a's stage cost summed over the run) of each with their
relative difference. Prints one JSON object.
"""

import argparse
import json
import time

import numpy as np

from usvdrake.systems.control.nmpc_problem import NmpcConfig, NmpcProblem, wrap_reference
from usvdrake.systems.vessel.vessel_discrete import rk4
from usvdrake.vessel import load_vessel

RADIUS, SPEED = 20.0, 0.6


def circle_reference(times: np.ndarray):
    w = SPEED / RADIUS
    q = np.zeros((len(times), 6))
    q[:, 0], q[:, 1] = RADIUS * np.sin(w * times), RADIUS * (1 - np.cos(w * times))
    q[:, 2], q[:, 3], q[:, 5] = w * times, SPEED, w
    return q, np.zeros((len(times), 3))


def make_casadi_solver(p: NmpcProblem):
    """The OCP of eqs. (10)-(14) in CasADi (SX, multiple shooting, RK4), solved by IPOPT."""
    import casadi as ca

    n, nu, dt, xi = p.N, p.nu, p.dt, p.xi
    b_thr = ca.DM(p.B_thr)

    def f(q, tau):
        c, s = ca.cos(q[2]), ca.sin(q[2])
        u, v, r = q[3], q[4], q[5]
        return ca.vertcat(
            c * u - s * v,
            s * u + c * v,
            r,
            (tau[0] + xi.m22 * v * r - xi.Xu * u) / xi.m11,
            (tau[1] - xi.m11 * u * r - xi.Yv * v) / xi.m22,
            (tau[2] - (xi.m22 - xi.m11) * u * v - xi.Nr * r) / xi.m33,
        )

    qs = ca.SX.sym("q", 6, n + 1)
    us = ca.SX.sym("u", nu, n)
    q_hat = ca.SX.sym("q_hat", 6)
    q_ref = ca.SX.sym("q_ref", 6, n + 1)
    u_ref = ca.SX.sym("u_ref", nu, n)
    cost, g = 0, [qs[:, 0] - q_hat]
    for k in range(n):
        tau = b_thr @ us[:, k]
        q = qs[:, k]
        k1 = f(q, tau)
        k2 = f(q + dt / 2 * k1, tau)
        k3 = f(q + dt / 2 * k2, tau)
        k4 = f(q + dt * k3, tau)
        g.append(qs[:, k + 1] - (q + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)))
        e, du = qs[:, k] - q_ref[:, k], us[:, k] - u_ref[:, k]
        cost += 0.5 * (ca.dot(ca.DM(p.Wq) * e, e) + ca.dot(ca.DM(p.Wu) * du, du))
    e = qs[:, n] - q_ref[:, n]
    cost += 0.5 * ca.dot(ca.DM(p.WN) * e, e)
    z = ca.vertcat(ca.vec(qs), ca.vec(us))
    par = ca.vertcat(q_hat, ca.vec(q_ref), ca.vec(u_ref))
    opts = {
        "ipopt.print_level": 0,
        "print_time": 0,
        "ipopt.sb": "yes",
        "ipopt.warm_start_init_point": "yes",
    }
    solver = ca.nlpsol("nmpc", "ipopt", {"x": z, "f": cost, "g": ca.vertcat(*g), "p": par}, opts)
    vb = np.asarray(p.cfg.velocity_bounds)
    qlo = np.tile(np.concatenate([np.full(3, -np.inf), -vb]), n + 1)
    lbx = np.concatenate([qlo, np.tile(p.u_min, n)])
    ubx = np.concatenate([-qlo, np.tile(p.u_max, n)])

    def solve(qh, qr, ur, warm):
        z0 = np.concatenate([warm[0].ravel(), warm[1].ravel()])
        t0 = time.perf_counter()
        sol = solver(
            x0=z0, p=np.concatenate([qh, qr.ravel(), ur.ravel()]), lbx=lbx, ubx=ubx, lbg=0, ubg=0
        )
        ms = (time.perf_counter() - t0) * 1e3
        zs = np.asarray(sol["x"]).ravel()
        return (
            zs[: 6 * (n + 1)].reshape(n + 1, 6),
            zs[6 * (n + 1) :].reshape(n, nu),
            ms,
            solver.stats()["success"],
        )

    return solve


def closed_loop(p: NmpcProblem, solve, steps: int):
    """Run the loop; returns solve times [ms], tracking cost, failures."""
    q = np.array([0.0, 0.5, 0.3, 0.0, 0.0, 0.0])
    warm, times, cost, failures = None, [], 0.0, 0
    for j in range(steps):
        t = j * p.dt + p.dt * np.arange(p.N + 1)
        q_ref, nd = circle_reference(t)
        q_ref = wrap_reference(q_ref, q[2])
        u_ref = p.feedforward(q_ref, nd)
        if warm is None:
            warm = p.initial_guess(q, u_ref)
        qs, us, ms, ok = solve(q, q_ref, u_ref, warm)
        times.append(ms)
        failures += 0 if ok else 1
        u0 = np.clip(us[0], p.u_min, p.u_max)
        e, du = q - q_ref[0], u0 - u_ref[0]
        cost += 0.5 * float(np.sum(p.Wq * e**2) + np.sum(p.Wu * du**2))
        warm = p.shift(qs, us)
        for _ in range(10):
            q = rk4(p.xi, q[None], (p.B_thr @ u0)[None], p.dt / 10)[0]
    return np.array(times), cost, failures


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=40.0)
    args = parser.parse_args()
    vessel = load_vessel("roboat2")
    steps = int(args.seconds / 0.1)
    ours = NmpcProblem(vessel, NmpcConfig())

    def solve_ours(qh, qr, ur, warm):
        s = ours.solve(qh, qr, ur, warm)
        return s.q, s.u, s.solve_ms, s.success

    t_ours, j_ours, f_ours = closed_loop(ours, solve_ours, steps)
    out = {
        "benchmark": "nmpc",
        "horizon_s": ours.cfg.horizon,
        "steps": steps,
        "qp_solver": ours.cfg.solver,
        "nmpc_solve_ms_median": round(float(np.median(t_ours)), 3),
        "nmpc_solve_ms_p95": round(float(np.percentile(t_ours, 95)), 3),
        "nmpc_failures": f_ours,
        "tracking_cost": round(j_ours, 4),
    }
    try:
        solve_casadi = make_casadi_solver(ours)
    except ImportError:
        out["casadi"] = "not installed (pip install casadi)"
    else:
        t_ca, j_ca, f_ca = closed_loop(ours, solve_casadi, steps)
        out.update(
            casadi_solve_ms_median=round(float(np.median(t_ca)), 3),
            casadi_solve_ms_p95=round(float(np.percentile(t_ca, 95)), 3),
            casadi_failures=f_ca,
            casadi_tracking_cost=round(j_ca, 4),
            nmpc_vs_casadi_ratio=round(float(np.median(t_ours) / np.median(t_ca)), 3),
            tracking_cost_rel_diff=round(abs(j_ours - j_ca) / j_ca, 5),
        )
    print(json.dumps(out))


if __name__ == "__main__":
    main()
