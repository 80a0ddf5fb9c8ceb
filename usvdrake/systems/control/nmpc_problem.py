"""Nonlinear MPC of Roboat II §IV-B (eqs. 10-14) on Drake's MathematicalProgram, solved in real
time.

    min  ½ Σ_k ‖q_k − q_ref,k‖²_Wq + ‖u_k − u_ref,k‖²_Wu  +  ‖q_N − q_ref,N‖²_WN      (10a)
    s.t. q_0 = q̂                                                                    (10b)
         q_{k+1} = F(q_k, u_k)  (RK4 of eq. 7 over dt, zero-order hold)              (10c)
         q_min ≤ q_k ≤ q_max,  u_min ≤ u_k ≤ u_max  (±50 N, eq. 14)                 (10d, e)

with Wq, WN, Wu of eqs. (11)-(13), horizon 4 s at dt = 0.1 s (N = 40), u the four thruster
forces (τ = B u, eq. 3), and u_ref the feed-forward thrust from the reference's inverse dynamics
(M ν̇_ref + C(ν_ref) ν_ref + D ν_ref, then B⁺), so that Wu penalises deviation from the
feed-forward, as eq. (10a) intends (NOTES.md: penalising raw newtons with u_ref = 0 tracks badly).

**Real-time iteration** (Diehl et al. 2005): each control step linearises (10c) around the
previous solution shifted by one step (multiple shooting, exact RK4 Jacobians from
``vessel_discrete``) and solves ONE convex QP. By default (``solver="riccati"``) the QP goes, in
deviations from the linearisation point, straight to :func:`~.ocp_qp.solve_ocp_qp`: an
interior-point method whose Newton systems are solved by a Riccati recursion over the stages
(HPIPM's approach, Frison & Diehl 2020), one compiled call per QP; a step it fails (rare: its
Mehrotra heuristic can cycle) goes to Clarabel on the sparse QP, built then. The reference path
(``"clarabel"`` / ``"osqp"``) is one sparse MathematicalProgram built at construction: its
Hessian is constant; each step only the linear cost term, the dynamics' values (fixed sparsity)
and (10b) are updated in place. The two differ only when q̂ itself violates a velocity bound:
the sparse QP bounds q_0 too and is then infeasible, the Riccati QP bounds q_1..q_N only (q_0 is
fixed to q̂ anyway).
**Full-NLP mode** iterates the same SQP to convergence (a fixed point of SQP is a KKT point of
the NLP); :func:`solve_nlp_ipopt` solves the NLP itself with IPOPT as an independent reference.
"""

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import ClarabelSolver, IpoptSolver, MathematicalProgram, OsqpSolver

from usvdrake.systems.control.ocp_qp import solve_ocp_qp, warm_up
from usvdrake.systems.vessel.thrusters import configuration_matrix, thrust_envelope
from usvdrake.systems.vessel.vessel_discrete import rk4, rk4_with_jacobians
from usvdrake.systems.vessel.vessel_dynamics import coriolis_times_velocity
from usvdrake.vessel import VesselParams

NX, HEADING = 6, 2
SOLVERS = ("riccati", "clarabel", "osqp")


@dataclass
class NmpcConfig:
    horizon: float = 4.0  # [s] prediction horizon N_c (Roboat II §IV-B)
    dt: float = 0.1  # [s] shooting interval = control period (10 Hz, Roboat II §VI)
    # [s] the update runs this long after the instants k·dt (the sensors'), after the
    # estimator's (NMHE: 1 ms), so it acts on the state estimated from the samples just taken
    update_offset: float = 0.002
    Wq: list[float] = field(
        default_factory=lambda: [200.0, 200.0, 100.0, 10.0, 10.0, 10.0]
    )  # eq. (11)
    WN: list[float] = field(
        default_factory=lambda: [1000.0, 1000.0, 500.0, 50.0, 50.0, 150.0]
    )  # eq. (12)
    Wu: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0, 1.0])  # eq. (13)
    velocity_bounds: list[float] = field(
        default_factory=lambda: [3.0, 2.0, 2.0]
    )  # [m/s, m/s, rad/s] |u|, |v|, |r| (10d)
    # QP solver: "riccati" (structure-exploiting interior point, ocp_qp), or "clarabel" / "osqp"
    # on the sparse MathematicalProgram (the reference)
    solver: str = "riccati"
    mode: str = "rti"  # "rti": one QP per step; "nlp": SQP iterated to convergence
    nlp_max_iterations: int = 30  # SQP iterations in "nlp" mode
    nlp_tolerance: float = 1e-6  # [-] stop when the step's infinity norm is below this
    max_consecutive_failures: int = 5  # then command zero thrust
    # [-] offset-free MPC: gain of the disturbance estimate d̂ (a constant body-frame force the
    # model adds to τ over the horizon, learned from the one-step prediction error); 0: off
    disturbance_gain: float = 0.3
    # "estimator": take d̂ from the estimator's force estimate when one is wired (the NMHE's);
    # "internal": always learn it here from the one-step prediction error
    disturbance_source: str = "internal"


@dataclass
class NmpcSolution:
    success: bool
    u: np.ndarray  # (N, n_u) planned thruster forces [N]
    q: np.ndarray  # (N + 1, 6) predicted states
    cost: float  # value of (10a)
    solve_ms: float  # wall time of this call [ms]
    iterations: int = 1
    status: str = ""


def wrap_reference(q_ref: np.ndarray, psi_now: float) -> np.ndarray:
    """The reference with its heading unwrapped and shifted by 2πn to start within π of ψ."""
    q = q_ref.copy()
    q[:, HEADING] = np.unwrap(q[:, HEADING])
    q[:, HEADING] += 2 * np.pi * np.round((psi_now - q[0, HEADING]) / (2 * np.pi))
    return q


class NmpcProblem:
    """The OCP of eqs. (10)-(14) for one vessel with fixed thrusters (Roboat II's Roboat II
    layout)."""

    def __init__(self, vessel: VesselParams, cfg: NmpcConfig):
        if any(t.azimuth for t in vessel.thrusters):
            raise ValueError(
                "NmpcProblem: azimuth thrusters are not supported (fixed thrusters only)"
            )
        if cfg.solver not in SOLVERS:
            raise ValueError(
                f"NmpcProblem: solver must be one of {', '.join(SOLVERS)}, got {cfg.solver!r}"
            )
        if not 0.0 <= cfg.update_offset < cfg.dt:
            raise ValueError(
                f"NmpcConfig.update_offset must be in [0, dt), got {cfg.update_offset}"
            )
        self.vessel, self.cfg = vessel, cfg
        self.xi = vessel.hydrodynamics
        self.N = int(round(cfg.horizon / cfg.dt))
        self.dt = cfg.dt
        self.B_thr = configuration_matrix(vessel.thrusters)  # τ = B u (eq. 3)
        self.disturbance_limit = thrust_envelope(vessel.thrusters)
        self.B_pinv = np.linalg.pinv(self.B_thr)
        self.nu = self.B_thr.shape[1]
        self.u_min = np.array([t.min_force for t in vessel.thrusters])
        self.u_max = np.array([t.max_force for t in vessel.thrusters])
        self.Wq, self.WN, self.Wu = (np.asarray(w, float) for w in (cfg.Wq, cfg.WN, cfg.Wu))
        self.qp_iterations = 0  # interior-point iterations of the last Riccati QP
        self.qp_fallbacks = 0  # Riccati QPs handed to Clarabel (see _qp_step)
        self._prog = None
        # the OCP QP's data in ocp_qp's layout: diagonal weights, boxes (positions unbounded)
        n = self.N
        self._Qd = np.vstack([np.tile(self.Wq, (n, 1)), self.WN])
        self._Rd = np.tile(self.Wu, (n, 1))
        vb = np.asarray(cfg.velocity_bounds, float)
        self._ubx = np.tile(np.concatenate([np.full(3, np.inf), vb]), (n + 1, 1))
        self._lbu, self._ubu = np.tile(self.u_min, (n, 1)), np.tile(self.u_max, (n, 1))
        if cfg.solver != "riccati":
            self._solver = ClarabelSolver() if cfg.solver == "clarabel" else OsqpSolver()
            self._build_qp()
        else:
            warm_up()  # load the compiled solver now, not in the first (real-time) step

    # --- the QP, built once ------------------------------------------------------------------
    def _build_qp(self) -> None:
        n, nu = self.N, self.nu
        prog = MathematicalProgram()
        self._q = prog.NewContinuousVariables(n + 1, NX, "q")
        self._u = prog.NewContinuousVariables(n, nu, "u")
        z = np.concatenate([self._q.ravel(), self._u.ravel()])
        self._nz = len(z)
        self._h = np.concatenate([np.tile(self.Wq, n), self.WN, np.tile(self.Wu, n)])
        prog.AddQuadraticCost(sp.diags(self._h).toarray(), np.zeros(self._nz), z, is_convex=True)
        self._lin = prog.AddLinearCost(np.zeros(self._nz), 0.0, z)
        # Dynamics rows: q_0 = q̂ ; q_{k+1} − A_k q_k − B_k u_k = c_k. Fixed sparsity pattern.
        rows, cols = [np.arange(NX)], [np.arange(NX)]
        for k in range(n):
            r = NX + NX * k + np.arange(NX)
            rows.append(r)
            cols.append(NX * (k + 1) + np.arange(NX))
            rows.append(np.repeat(r, NX))
            cols.append(np.tile(NX * k + np.arange(NX), NX))
            rows.append(np.repeat(r, nu))
            cols.append(np.tile(NX * (n + 1) + nu * k + np.arange(nu), NX))
        self._rows, self._cols = np.concatenate(rows), np.concatenate(cols)
        self._n_eq = NX * (n + 1)
        a0, b0 = np.tile(np.eye(NX), (n, 1, 1)), np.zeros((n, NX, nu))
        self._eq = prog.AddLinearEqualityConstraint(
            self._eq_matrix(a0, b0), np.zeros(self._n_eq), z
        )
        prog.AddBoundingBoxConstraint(
            np.tile(self.u_min, n), np.tile(self.u_max, n), self._u.ravel()
        )
        vb = np.asarray(self.cfg.velocity_bounds, float)
        hi = np.tile(np.concatenate([np.full(3, np.inf), vb]), n + 1)
        prog.AddBoundingBoxConstraint(-hi, hi, self._q.ravel())
        self._prog = prog

    def _eq_matrix(self, a: np.ndarray, b: np.ndarray) -> sp.csc_matrix:
        n = self.N
        ones = np.ones(NX)
        vals = [ones]
        for k in range(n):
            vals += [ones, -a[k].ravel(), -b[k].ravel()]
        return sp.csc_matrix(
            (np.concatenate(vals), (self._rows, self._cols)), shape=(self._n_eq, self._nz)
        )

    # --- pieces ---------------------------------------------------------------------------------
    def feedforward(
        self, q_ref: np.ndarray, nu_dot_ref: np.ndarray, disturbance=None
    ) -> np.ndarray:
        """u_ref (N, n_u): B⁺ (M ν̇_ref + C(ν_ref) ν_ref + D ν_ref − d̂), clipped to the limits."""
        xi = self.xi
        nu = q_ref[: self.N, 3:].T
        tau = (
            np.array([xi.m11, xi.m22, xi.m33])[:, None] * nu_dot_ref[: self.N].T
            + coriolis_times_velocity(xi, nu)
            + np.array([xi.Xu, xi.Yv, xi.Nr])[:, None] * nu
        )
        if disturbance is not None:
            tau = tau - np.asarray(disturbance, float)[:, None]
        return np.clip((self.B_pinv @ tau).T, self.u_min, self.u_max)

    def update_disturbance(
        self, d: np.ndarray, nu_measured: np.ndarray, nu_predicted: np.ndarray
    ) -> np.ndarray:
        """Offset-free MPC (Pannocchia & Rawlings 2003, here as a body-frame force): the one-step
        velocity prediction error, times M / dt, is the force the model missed; d̂ moves towards
        it by ``disturbance_gain`` (a first-order filter against measurement noise).

        d̂ is clipped to the thrusters' combined force (:func:`thrust_envelope`): a larger force
        cannot be countered anyway, and without the bound the filter integrates estimator
        start-up transients without limit (a campaign run wound it up to 3.4 kN in sway, and
        every QP after that was infeasible)."""
        m = np.array([self.xi.m11, self.xi.m22, self.xi.m33])
        missed = m * (np.asarray(nu_measured) - np.asarray(nu_predicted)) / self.dt
        d = np.asarray(d, float) + self.cfg.disturbance_gain * missed
        return np.clip(d, -self.disturbance_limit, self.disturbance_limit)

    def initial_guess(
        self, q_hat: np.ndarray, u_ref: np.ndarray, disturbance=None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Cold start: roll the feed-forward out from q̂."""
        d = np.zeros(3) if disturbance is None else np.asarray(disturbance, float)
        q = np.empty((self.N + 1, NX))
        q[0] = q_hat
        for k in range(self.N):
            q[k + 1] = rk4(self.xi, q[k : k + 1], (self.B_thr @ u_ref[k] + d)[None], self.dt)[0]
        return q, u_ref.copy()

    def shift(
        self, q: np.ndarray, u: np.ndarray, disturbance=None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Warm start for the next step: drop the first interval, repeat the last input."""
        d = np.zeros(3) if disturbance is None else np.asarray(disturbance, float)
        u_next = np.vstack([u[1:], u[-1:]])
        q_last = rk4(self.xi, q[-1:], (self.B_thr @ u[-1] + d)[None], self.dt)
        return np.vstack([q[1:], q_last]), u_next

    def cost(self, q: np.ndarray, u: np.ndarray, q_ref: np.ndarray, u_ref: np.ndarray) -> float:
        """(10a) with the ½ of the paper."""
        e = q - q_ref
        du = u - u_ref
        return 0.5 * float(
            np.sum(self.Wq * e[:-1] ** 2) + np.sum(self.WN * e[-1] ** 2) + np.sum(self.Wu * du**2)
        )

    def _qp_step(self, q_hat, q_ref, u_ref, q_bar, u_bar, d):
        tau_bar = u_bar @ self.B_thr.T + d
        q_next, a, bt = rk4_with_jacobians(self.xi, q_bar[:-1], tau_bar, self.dt)
        b = bt @ self.B_thr
        # Drake aborts (not raises) on non-finite coefficients, and the interior point would
        # only report a numerical failure: refuse them here instead (c is finite if these are).
        if not (
            np.isfinite(a).all()
            and np.isfinite(b).all()
            and np.isfinite(q_next).all()
            and np.isfinite(q_bar).all()
            and np.isfinite(u_bar).all()
            and np.isfinite(q_ref).all()
        ):
            return None, "non-finite linearisation"
        if self.cfg.solver == "riccati":
            sol, status = self._riccati_step(q_hat, q_ref, u_ref, q_bar, u_bar, q_next, a, b)
            if sol is not None:
                return sol, status
            # rare (a few steps in HIL runs): the interior point cycled; Clarabel on the
            # sparse QP, built on first need, takes this step so that the Riccati path never
            # fails where the reference would not
            self.qp_fallbacks += 1
            if self._prog is None:
                self._solver = ClarabelSolver()
                self._build_qp()
        c = q_next - np.einsum("kij,kj->ki", a, q_bar[:-1]) - np.einsum("kij,kj->ki", b, u_bar)
        self._eq.evaluator().UpdateCoefficients(
            self._eq_matrix(a, b), np.concatenate([q_hat, c.ravel()])
        )
        lin = -np.concatenate(
            [(self.Wq * q_ref[:-1]).ravel(), self.WN * q_ref[-1], (self.Wu * u_ref).ravel()]
        )
        self._lin.evaluator().UpdateCoefficients(lin, 0.0)
        self._prog.SetInitialGuess(self._q, q_bar)
        self._prog.SetInitialGuess(self._u, u_bar)
        result = self._solver.Solve(self._prog)
        if not result.is_success():
            return None, str(result.get_solution_result())
        return (result.GetSolution(self._q), result.GetSolution(self._u)), ""

    def _riccati_step(self, q_hat, q_ref, u_ref, q_bar, u_bar, q_next, a, b):
        """The same QP in deviations δ from (q̄, ū): δq_{k+1} = A δq_k + B δu_k + (F(q̄_k, ū_k)
        − q̄_{k+1}), linear costs W (z̄ − z_ref), boxes shifted by z̄. Same solution; the data
        are small numbers (not positions of hundreds of metres), so the relative tolerance is
        also an absolute one."""
        sol = solve_ocp_qp(
            a,
            b,
            q_next - q_bar[1:],
            q_hat - q_bar[0],
            self._Qd,
            self._Qd * (q_bar - q_ref),
            self._Rd,
            self._Rd * (u_bar - u_ref),
            -self._ubx - q_bar,
            self._ubx - q_bar,
            self._lbu - u_bar,
            self._ubu - u_bar,
        )
        self.qp_iterations = sol.iterations
        if not sol.success:
            return None, f"riccati: {sol.status_text}"
        q = q_bar + sol.x
        q[0] = q_hat  # exactly, not q̄_0 + (q̂ − q̄_0) rounded
        return (q, u_bar + sol.u), ""

    # --- the public solve ---------------------------------------------------------------------
    def solve(self, q_hat, q_ref, u_ref, warm=None, disturbance=None) -> NmpcSolution:
        """One NMPC step from estimate q̂ with references q_ref (N + 1, 6), u_ref (N, n_u), a
        warm start (the previous solution, already shifted) and the disturbance estimate d̂
        (body-frame force added to τ in the model); returns the plan."""
        t0 = time.perf_counter()
        q_hat = np.asarray(q_hat, float)
        d = np.zeros(3) if disturbance is None else np.asarray(disturbance, float)
        if not (np.isfinite(q_hat).all() and np.isfinite(d).all() and np.isfinite(u_ref).all()):
            ms = (time.perf_counter() - t0) * 1e3
            return NmpcSolution(
                False,
                np.zeros((self.N, self.nu)),
                np.zeros((self.N + 1, NX)),
                np.inf,
                ms,
                0,
                "non-finite input",
            )
        q_ref = wrap_reference(np.asarray(q_ref, float), q_hat[HEADING])
        q_bar, u_bar = warm if warm is not None else self.initial_guess(q_hat, u_ref, d)
        q_bar = q_bar.copy()
        q_bar[:, HEADING] += (
            2 * np.pi * np.round((q_hat[HEADING] - q_bar[0, HEADING]) / (2 * np.pi))
        )
        iterations, status, sol = 0, "", None
        max_it = 1 if self.cfg.mode == "rti" else self.cfg.nlp_max_iterations
        while iterations < max_it:
            iterations += 1
            sol, status = self._qp_step(q_hat, q_ref, u_ref, q_bar, u_bar, d)
            if sol is None:
                break
            step = max(np.max(np.abs(sol[0] - q_bar)), np.max(np.abs(sol[1] - u_bar)) / 50.0)
            q_bar, u_bar = sol
            if step < self.cfg.nlp_tolerance:
                break
        ms = (time.perf_counter() - t0) * 1e3
        if sol is None:
            return NmpcSolution(False, u_bar, q_bar, np.inf, ms, iterations, status)
        u = np.clip(sol[1], self.u_min, self.u_max)  # remove the solver's last 1e-9 of violation
        return NmpcSolution(
            True, u, sol[0], self.cost(sol[0], u, q_ref, u_ref), ms, iterations, "ok"
        )


def solve_nlp_ipopt(problem: NmpcProblem, q_hat, q_ref, u_ref, warm=None) -> NmpcSolution:
    """The same OCP as a true NLP for IPOPT (independent reference): RK4 equality constraints
    with their exact Jacobians supplied through AutoDiffXd."""
    t0 = time.perf_counter()
    n, nu, xi, dt, bthr = problem.N, problem.nu, problem.xi, problem.dt, problem.B_thr
    q_ref = wrap_reference(np.asarray(q_ref, float), q_hat[HEADING])
    prog = MathematicalProgram()
    q = prog.NewContinuousVariables(n + 1, NX, "q")
    u = prog.NewContinuousVariables(n, nu, "u")
    w = np.concatenate([np.tile(problem.Wq, n), problem.WN, np.tile(problem.Wu, n)])
    target = np.concatenate([q_ref[:-1].ravel(), q_ref[-1], u_ref.ravel()])
    z = np.concatenate([q.ravel(), u.ravel()])
    # ½ Σ w (z − target)², the same (10a) as the QP
    prog.AddQuadraticCost(np.diag(w), -w * target, 0.5 * float(w @ target**2), z, is_convex=True)
    prog.AddBoundingBoxConstraint(q_hat, q_hat, q[0])
    prog.AddBoundingBoxConstraint(np.tile(problem.u_min, n), np.tile(problem.u_max, n), u.ravel())

    def dynamics(x):
        """[q_k, u_k, q_{k+1}] ↦ q_{k+1} − F(q_k, B u_k), floats or AutoDiffXd."""
        if isinstance(x[0], AutoDiffXd):
            val, grad = ExtractValue(x).ravel(), ExtractGradient(x)
            q1, a, bt = rk4_with_jacobians(xi, val[None, :NX], (bthr @ val[NX : NX + nu])[None], dt)
            jac = np.hstack([-a[0], -bt[0] @ bthr, np.eye(NX)])
            out = InitializeAutoDiff(val[NX + nu :] - q1[0], jac @ grad)
            return out.ravel()
        x = np.asarray(x, float)
        return x[NX + nu :] - rk4(xi, x[None, :NX], (bthr @ x[NX : NX + nu])[None], dt)[0]

    for k in range(n):
        prog.AddConstraint(
            dynamics, np.zeros(NX), np.zeros(NX), np.concatenate([q[k], u[k], q[k + 1]])
        )
    q0, u0 = warm if warm is not None else problem.initial_guess(q_hat, u_ref)
    prog.SetInitialGuess(q, q0)
    prog.SetInitialGuess(u, u0)
    result = IpoptSolver().Solve(prog)
    qs, us = result.GetSolution(q), result.GetSolution(u)
    ms = (time.perf_counter() - t0) * 1e3
    return NmpcSolution(
        result.is_success(),
        us,
        qs,
        problem.cost(qs, us, q_ref, u_ref),
        ms,
        0,
        str(result.get_solution_result()),
    )
