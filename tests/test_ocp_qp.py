"""The Riccati interior point (ocp_qp) against independent solutions: the closed-form KKT solve
without bounds (numpy), Clarabel on the same QP as a sparse MathematicalProgram with bounds, and
the NMPC's own Clarabel path; infinite bounds; infeasible boxes reported, not papered over."""

from pathlib import Path

import numpy as np
import pytest
from pydrake.solvers import ClarabelSolver, MathematicalProgram, SolverOptions

from usvdrake import ConfigError
from usvdrake.scenario import read_scenario, validate_scenario
from usvdrake.systems.control.nmpc_problem import NmpcConfig, NmpcProblem
from usvdrake.systems.control.ocp_qp import (
    CONVERGED,
    INFEASIBLE,
    STALLED,
    _ipm,
    solve_ocp_qp,
)
from usvdrake.vessel import load_vessel

N, NX, NU = 30, 6, 4
VEL = np.array([-np.inf] * 3 + [-1.0] * 3), np.array([np.inf] * 3 + [1.0] * 3)


def random_ocp(seed: int, n: int = N):
    """A well-posed instance that is feasible with bounds |x| ≤ 1, |u| ≤ 0.5: ‖A_k‖₂ = 0.95,
    ‖x_0‖₂ = 0.9 and ‖c_k‖₂ ≤ 0.04, so u = 0 keeps ‖x_k‖₂ ≤ 0.9. The linear terms pull the
    unconstrained optimum to |x|, |u| ~ 3, so many bounds are active."""
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((n, NX, NX))
    a *= 0.95 / np.linalg.norm(a, 2, axis=(1, 2))[:, None, None]
    b = rng.standard_normal((n, NX, NU))
    c = rng.standard_normal((n, NX))
    c *= 0.04 / np.linalg.norm(c, axis=1)[:, None]
    x0 = rng.standard_normal(NX)
    x0 *= 0.9 / np.linalg.norm(x0)
    q_diag, r_diag = rng.uniform(0.5, 2.0, (n + 1, NX)), rng.uniform(0.1, 1.0, (n, NU))
    q_lin, r_lin = 3.0 * rng.standard_normal((n + 1, NX)), rng.standard_normal((n, NU))
    return a, b, c, x0, q_diag, q_lin, r_diag, r_lin


def tight_clarabel() -> tuple[ClarabelSolver, SolverOptions]:
    """Clarabel at 1e-12 (its defaults stop at a 1e-8 gap relative to a cost that can be 1e5:
    solutions then differ by up to 1e-2 N in the NMPC, which tells nothing about either)."""
    solver, opts = ClarabelSolver(), SolverOptions()
    for key in ("tol_gap_abs", "tol_gap_rel", "tol_feas", "tol_ktratio"):
        opts.SetOption(solver.id(), key, 1e-12)
    return solver, opts


def clarabel_ocp(a, b, c, x0, q_diag, q_lin, r_diag, r_lin, lbx, ubx, lbu, ubu):
    """The same QP as one sparse MathematicalProgram (bounds on x_1..x_N, as ocp_qp)."""
    n = len(a)
    prog = MathematicalProgram()
    x = prog.NewContinuousVariables(n + 1, NX, "x")
    u = prog.NewContinuousVariables(n, NU, "u")
    z = np.concatenate([x.ravel(), u.ravel()])
    h = np.concatenate([q_diag.ravel(), r_diag.ravel()])
    prog.AddQuadraticCost(np.diag(h), np.concatenate([q_lin.ravel(), r_lin.ravel()]), z, True)
    prog.AddLinearEqualityConstraint(np.eye(NX), x0, x[0])
    for k in range(n):
        prog.AddLinearEqualityConstraint(
            np.hstack([a[k], b[k], -np.eye(NX)]), -c[k], np.concatenate([x[k], u[k], x[k + 1]])
        )
    lbx, ubx = (np.broadcast_to(v, (n + 1, NX))[1:].ravel() for v in (lbx, ubx))
    prog.AddBoundingBoxConstraint(lbx, ubx, x[1:].ravel())
    lbu, ubu = (np.broadcast_to(v, (n, NU)).ravel() for v in (lbu, ubu))
    prog.AddBoundingBoxConstraint(lbu, ubu, u.ravel())
    solver, opts = tight_clarabel()
    result = solver.Solve(prog, None, opts)
    return result.is_success(), result.GetSolution(x), result.GetSolution(u)


def kkt_solve(a, b, c, x0, q_diag, q_lin, r_diag, r_lin):
    """Closed form without bounds: the dense KKT system [[H, Eᵀ], [E, 0]] [z; ν] = [−g; e]."""
    n = len(a)
    nz = (n + 1) * NX + n * NU
    h = np.diag(np.concatenate([q_diag.ravel(), r_diag.ravel()]))
    g = np.concatenate([q_lin.ravel(), r_lin.ravel()])
    e = np.zeros(((n + 1) * NX, nz))
    rhs = np.concatenate([x0, c.ravel()])
    e[:NX, :NX] = np.eye(NX)
    for k in range(n):
        rows = slice(NX * (k + 1), NX * (k + 2))
        e[rows, NX * (k + 1) : NX * (k + 2)] = np.eye(NX)  # x_{k+1} − A x_k − B u_k = c_k
        e[rows, NX * k : NX * (k + 1)] = -a[k]
        e[rows, (n + 1) * NX + NU * k : (n + 1) * NX + NU * (k + 1)] = -b[k]
    kkt = np.block([[h, e.T], [e, np.zeros((len(e), len(e)))]])
    sol = np.linalg.solve(kkt, np.concatenate([-g, rhs]))
    z, nu = sol[:nz], sol[nz:]
    return z[: (n + 1) * NX].reshape(n + 1, NX), z[(n + 1) * NX :].reshape(n, NU), nu[NX:]


def test_unconstrained_equals_the_closed_form_kkt_solve():
    ocp = random_ocp(0)
    sol = solve_ocp_qp(*ocp)
    x, u, nu = kkt_solve(*ocp)
    assert sol.status == CONVERGED and sol.iterations == 1  # one Newton step solves a QP
    np.testing.assert_allclose(sol.x, x, atol=1e-9)
    np.testing.assert_allclose(sol.u, u, atol=1e-9)
    # the dynamics multipliers are the KKT system's (opposite sign convention there)
    np.testing.assert_allclose(sol.pi, -nu.reshape(N, NX), atol=1e-8)


@pytest.mark.parametrize("seed", range(6))
def test_bounded_random_instances_match_clarabel(seed):
    ocp = random_ocp(seed)
    sol = solve_ocp_qp(*ocp, lbx=VEL[0], ubx=VEL[1], lbu=-0.5, ubu=0.5)
    ok, x, u = clarabel_ocp(*ocp, VEL[0], VEL[1], -0.5, 0.5)
    assert ok and sol.status == CONVERGED, sol.status_text
    active_u = np.abs(np.abs(u) - 0.5) < 1e-6
    active_x = np.abs(np.abs(x[1:, 3:]) - 1.0) < 1e-6
    assert active_u.any() and active_x.any() and not active_u.all()  # a real mix
    np.testing.assert_allclose(sol.x, x, atol=1e-6)
    np.testing.assert_allclose(sol.u, u, atol=1e-6)
    assert np.all(np.abs(sol.u) <= 0.5 + 1e-8) and np.all(np.abs(sol.x[1:, 3:]) <= 1.0 + 1e-8)
    assert max(sol.res_stat, sol.res_eq, sol.res_ineq) < 1e-7


def test_infinite_bounds_are_masked_per_component_and_stage():
    """One-sided and per-stage absent bounds; all-infinite bounds give the unconstrained
    solution (a big-number encoding would not be exact there)."""
    ocp = random_ocp(1)
    lbx = np.full((N + 1, NX), -np.inf)
    ubx = np.full((N + 1, NX), np.inf)
    lbx[:, 3], ubx[:, 4] = -0.8, 0.7  # surge from below only, sway from above only
    ubx[10:20, 0] = 0.2  # a position bound on some stages only
    lbu = np.full((N, NU), -np.inf)
    ubu = np.full((N, NU), 0.4)
    lbu[::2, 1] = -0.3
    sol = solve_ocp_qp(*ocp, lbx=lbx, ubx=ubx, lbu=lbu, ubu=ubu)
    ok, x, u = clarabel_ocp(*ocp, lbx, ubx, lbu, ubu)
    assert ok and sol.status == CONVERGED
    np.testing.assert_allclose(sol.x, x, atol=1e-6)
    np.testing.assert_allclose(sol.u, u, atol=1e-6)
    assert np.any(np.abs(sol.x[10:20, 0] - 0.2) < 1e-6)  # that bound is active
    inf = np.full((N + 1, NX), np.inf)
    free = solve_ocp_qp(*ocp, lbx=-inf, ubx=inf, lbu=-inf[:N, :NU], ubu=inf[:N, :NU])
    x_kkt, u_kkt, _ = kkt_solve(*ocp)
    assert free.status == CONVERGED and free.iterations == 1
    np.testing.assert_allclose(free.u, u_kkt, atol=1e-9)


def test_a_bound_violated_by_x0_is_not_applied_to_stage_0():
    ocp = list(random_ocp(2))
    ocp[3] = np.array([0.0, 0.0, 0.0, 1.5, -0.2, 0.1])  # surge 1.5 > its bound 1
    sol = solve_ocp_qp(*ocp, lbx=VEL[0], ubx=VEL[1], lbu=-3.0, ubu=3.0)
    assert sol.status == CONVERGED
    np.testing.assert_array_equal(sol.x[0], ocp[3])
    assert np.all(np.abs(sol.x[1:, 3:]) <= 1.0 + 1e-8)


@pytest.mark.parametrize("case", ["state box unreachable", "input box too small"])
def test_infeasible_boxes_return_a_failure_status(case):
    """Clarabel agrees that these are infeasible; ours must say so too rather than return a
    point that violates the bounds with status 'converged'."""
    ocp = list(random_ocp(3))
    if case == "state box unreachable":
        ocp[1] = ocp[1].copy()
        ocp[1][0] = 0.0  # u_0 cannot act: x_1 = A_0 x_0 + c_0 ...
        ocp[2] = ocp[2].copy()
        ocp[2][0, 3] = 5.0  # ... and its surge is far outside |x| ≤ 1
        bounds = dict(lbx=VEL[0], ubx=VEL[1], lbu=-0.5, ubu=0.5)
    else:
        ocp[2] = np.tile([0.0, 0.0, 0.0, 3.0, 0.0, 0.0], (N, 1))  # a drift of 3 per step
        bounds = dict(lbx=VEL[0], ubx=VEL[1], lbu=-0.01, ubu=0.01)
    ok, _, _ = clarabel_ocp(*ocp, bounds["lbx"], bounds["ubx"], bounds["lbu"], bounds["ubu"])
    sol = solve_ocp_qp(*ocp, **bounds)
    assert not ok
    assert not sol.success and sol.status == INFEASIBLE, sol.status_text
    assert sol.iterations < 50  # detected, not run into the iteration limit


def test_a_stalled_start_is_retried_with_multipliers_at_the_gradients_scale():
    """The QP of a river_tracking HIL step (tests/data, written by this repository's NMPC with
    a 45 N sway disturbance estimate): from λ = 1/s, Mehrotra's heuristic cycles (μ ~ 20 for 50
    iterations); the retry from λ at the gradient's scale converges to Clarabel's solution."""
    d = np.load(Path(__file__).parent / "data" / "ocp_qp_hil_stall.npz")
    names = ("A", "B", "c", "x0", "Q", "q", "R", "r", "lbx", "ubx", "lbu", "ubu")
    qp = [np.ascontiguousarray(d[k]) for k in names]
    n, nx, nu = qp[1].shape
    first = _ipm(*qp, np.zeros((n + 1, nx)), np.zeros((n, nu)), np.zeros((n, nx)), 1e-8, 50, 1.0)
    assert first[0] == STALLED  # the cycle the retry exists for
    sol = solve_ocp_qp(*qp)
    ok, x, u = clarabel_ocp(*qp)
    assert sol.status == CONVERGED and ok
    np.testing.assert_allclose(sol.u, u, atol=1e-5)  # inputs of ±50 N
    np.testing.assert_allclose(sol.x, x, atol=1e-6)


# --- in the NMPC --------------------------------------------------------------------------------
VESSEL = load_vessel("roboat2")


def nmpc_case(p: NmpcProblem, offset: float):
    """A straight-line reference at 1 m/s from rest, `offset` metres to the side: the plan
    saturates thrusters at the start when the offset is large."""
    t = p.dt * np.arange(p.N + 1)
    q_ref = np.zeros((p.N + 1, 6))
    q_ref[:, 0], q_ref[:, 3] = 100.0 + t, 1.0  # far from the origin, as in a mission
    q_hat = np.array([100.0, offset, 0.4, 0.0, 0.0, 0.0])
    return q_hat, q_ref, p.feedforward(q_ref, np.zeros((p.N + 1, 3)))


@pytest.mark.parametrize("mode", ["rti", "nlp"])
def test_nmpc_riccati_equals_its_clarabel_path(mode):
    """rti: one QP with saturated thrusters. nlp: the SQP on a milder case (it runs its 30
    iterations either way; with saturated thrusters the undamped SQP does not settle and
    amplifies the two QP solvers' last digits)."""
    ric = NmpcProblem(VESSEL, NmpcConfig(mode=mode))
    assert ric.cfg.solver == "riccati"  # the default
    cla = NmpcProblem(VESSEL, NmpcConfig(mode=mode, solver="clarabel"))
    solver, opts = tight_clarabel()
    cla._solver = type("Tight", (), {"Solve": lambda self, prog: solver.Solve(prog, None, opts)})()
    q_hat, q_ref, u_ref = nmpc_case(ric, offset=6.0 if mode == "rti" else 1.0)
    a, b = ric.solve(q_hat, q_ref, u_ref), cla.solve(q_hat, q_ref, u_ref)
    assert a.success and b.success and a.iterations == b.iterations
    if mode == "rti":
        assert np.any(np.abs(a.u) > 50.0 - 1e-6)  # thrust bounds active
    # 1e-6 of the ±50 N range: Clarabel on the absolute QP (positions of 100 m, a cost of 1e5)
    # is itself only that close; on the QP in deviations it agrees with ours to 4e-7 N
    np.testing.assert_allclose(a.u, b.u, atol=50e-6)
    np.testing.assert_allclose(a.q, b.q, atol=1e-6)
    assert a.cost == pytest.approx(b.cost, rel=1e-9)


def test_nmpc_infeasible_step_fails_with_riccati_too():
    """Surging at 6 m/s against a 3 m/s bound: one 0.1 s step at 200 N cannot bring q_1 within
    the bound. The Riccati QP says so, hands the step to Clarabel (which agrees) and the step
    fails (the Nmpc system then keeps the shifted plan)."""
    p = NmpcProblem(VESSEL, NmpcConfig())
    q_hat, q_ref, u_ref = nmpc_case(p, offset=0.0)
    q_hat[3] = 6.0
    sol = p.solve(q_hat, q_ref, u_ref)
    assert not sol.success and "infeasible" in sol.status.lower()
    assert p.qp_fallbacks == 1


def test_unknown_solver_is_refused_and_riccati_accepted_in_scenarios():
    with pytest.raises(ValueError, match="riccati"):
        NmpcProblem(VESSEL, NmpcConfig(solver="hpipm"))
    s = read_scenario("river_tracking")
    for name in ("riccati", "clarabel", "osqp"):
        s.nmpc.solver = name
        validate_scenario(s)
    s.nmpc.solver = "hpipm"
    with pytest.raises(ConfigError, match="riccati"):
        validate_scenario(s)
