"""The Lyapunov and sum-of-squares machinery of the region of attraction: the thrust box the
thrusters can produce, the DP error dynamics in body-frame coordinates and the PD written in
them, the Lyapunov matrix (solved block by block), the SOS programmes (unsaturated, saturated
per channel and the full saturated one) and the symbolic check that V̇'s coupling terms vanish.

**Lyapunov certificate and region of attraction** (round vessel, PD on the exact state — no
observer, continuous-time law, no sampling): the error state z = [e_x, e_y, ψ̃, u, v, r] with
the position error in the body frame, e = Rᵀ(ψ)(p − p_d), ψ̃ = ψ − ψ_d (|ψ̃| < π, where the
law's wrap is the identity). This change of coordinates removes every trigonometric function
exactly (ṘᵀR = r S): with ψ_d, p_d constant,

    ė_x = u + r e_y,   ė_y = v − r e_x,   ψ̃̇ = r,
    m11 u̇ = w_X + m22 v r − Xu u,   m22 v̇ = w_Y − m11 u r − Yv v,
    m33 ṙ = w_N − (m22 − m11) u v − Nr r,     w = sat(τ),  τ = −Kp [e, ψ̃] − Kd ν,

a polynomial (quadratic) vector field, the Coriolis terms of eq. (5) included. Saturation: the
azimuths can produce every τ in the box |τ_i| ≤ τ_max,i of largest volume inside the attainable
set {B_e z : ‖(F_x, F_y)_j‖ ≤ f_max,j} (:func:`thrust_box`, an SOCP over the box's corners;
for ntnu_round ≈ [4.90 N, 3.59 N, 0.427 N m]); the saturation model clips each τ_i to that box.
V = zᵀ P z with Aᵀ P + P A = −Q (A the linearisation, Q = I by default).

1. Unsaturated region: the largest ρ with {V ≤ ρ} inside the box, ρ_box = min_i τ_max,i² /
   (k_iᵀ P⁻¹ k_i) (exact for an ellipsoid), inside |ψ̃| ≤ π (ρ_wrap = π² / (P⁻¹)_ψψ), and with
   V̇ < 0 on {V ≤ ρ} for the polynomial dynamics, certified by the one-shot SOS programme
   (Parrilo's equality form):  max ρ  s.t.  zᵀz (V − ρ) − λ(z) V̇(z)  is SOS, λ free.
   On {V̇ = 0, z ≠ 0} it forces V ≥ ρ, so V̇ ≠ 0 on the connected set {V < ρ} \\ {0}, where it
   is negative near 0.
2. Saturated region (box-clip model, larger): w_i = sat(τ_i) is lifted into extra
   indeterminates and pinned exactly by the semialgebraic set g1 = τ_max² − w² ≥ 0,
   g2 = (τ − w) w ≥ 0, h = (τ − w)(τ_max² − w²) = 0 (its only solution is w = sat(τ)); the
   S-procedure gives  max ρ s.t. zᵀz (V − ρ) − λ V̇ − Σ σ_1 g1 − Σ σ_2 g2 − Σ p h  SOS with
   σ SOS, λ, p free. When P is block diagonal per DOF channel and the Coriolis/kinematic part
   of V̇ vanishes identically (true for the round hull, m11 = m22: checked symbolically, not
   assumed), V̇ = Σ_c V̇_c(z_c, w_c) exactly and the programme splits into three 3-variable
   ones, ρ = min_c ρ_c (each z_c has V_c(z_c) ≤ V(z) ≤ ρ_c, so every V̇_c ≤ 0, one < 0);
   otherwise the full 9-variable programme is solved (slow: ~15 s with Clarabel). The claimed
   level is 0.999 of the SOS optimum (solver tolerance).
"""

from __future__ import annotations

import numpy as np
from pydrake.solvers import (
    ClarabelSolver,
    CsdpSolver,
    MathematicalProgram,
    ScsSolver,
    SolverOptions,
)
from pydrake.symbolic import Polynomial, Variables
from scipy.linalg import solve_continuous_lyapunov

from usvdrake.systems.vessel.thrusters import extended_matrix
from usvdrake.systems.vessel.vessel_dynamics import straight_run_jacobian
from usvdrake.vessel import Hydrodynamics, VesselParams


# --- thrust box, Lyapunov function, SOS region of attraction ---------------------------------
def thrust_box(vessel: VesselParams) -> tuple[np.ndarray, list[np.ndarray]]:
    """(τ_max, corner commands): the largest-volume box |τ_i| ≤ τ_max,i whose 8 corners (hence,
    by convexity, all of it) the thrusters can produce, and the extended thrust vectors that
    produce each corner (max geometric mean of τ_max, an SOCP; Clarabel)."""
    b = extended_matrix(vessel.thrusters)
    prog = MathematicalProgram()
    hbox = prog.NewContinuousVariables(3, "tau_max")
    zs = []
    for sx in (1, -1):
        for sy in (1, -1):
            for sn in (1, -1):
                z = prog.NewContinuousVariables(b.shape[1], "z")
                prog.AddLinearEqualityConstraint(
                    np.hstack([b, -np.diag([sx, sy, sn])]), np.zeros(3), np.concatenate([z, hbox])
                )
                k = 0
                for t in vessel.thrusters:
                    if t.azimuth:
                        prog.AddLorentzConeConstraint(np.array([t.max_force, z[k], z[k + 1]]))
                        k += 2
                    else:
                        prog.AddBoundingBoxConstraint(t.min_force, t.max_force, z[k])
                        k += 1
                zs.append(z)
    prog.AddMaximizeGeometricMeanCost(np.eye(3), np.zeros(3), hbox)
    result = ClarabelSolver().Solve(prog)
    if not result.is_success():
        raise RuntimeError(f"thrust_box: {result.get_solution_result()}")
    # Shrink by 1e-9 relative so that the corners are attainable despite the solver tolerance.
    return result.GetSolution(hbox) * (1 - 1e-9), [result.GetSolution(z) for z in zs]


def dp_error_dynamics(xi: Hydrodynamics, z, w) -> np.ndarray:
    """ż of the error state z = [e_x, e_y, ψ̃, u, v, r] with applied force w (module docstring);
    float, array or symbolic entries."""
    ex, ey, _, u, v, r = z
    return np.array(
        [
            u + r * ey,
            v - r * ex,
            r,
            (w[0] + xi.m22 * v * r - xi.Xu * u) / xi.m11,
            (w[1] - xi.m11 * u * r - xi.Yv * v) / xi.m22,
            (w[2] - (xi.m22 - xi.m11) * u * v - xi.Nr * r) / xi.m33,
        ]
    )


def dp_error_feedback(kp: np.ndarray, kd: np.ndarray) -> np.ndarray:
    """K with τ = K z (the PD in error coordinates: −Kp [e, ψ̃] − Kd ν)."""
    return -np.hstack([kp, kd])


def lyapunov_matrix(a: np.ndarray, q: np.ndarray | None = None) -> np.ndarray:
    """P of Aᵀ P + P A = −Q. Block-decoupled (A, Q) are solved block by block so that equal
    blocks give bitwise-equal P blocks (the symbolic cancellation check relies on it)."""
    q = np.eye(len(a)) if q is None else np.asarray(q, float)
    p = np.zeros_like(a)
    blocks = _blocks(a, q)
    for idx in blocks:
        ix = np.ix_(idx, idx)
        p[ix] = solve_continuous_lyapunov(a[ix].T, -q[ix])
    return 0.5 * (p + p.T)


def _blocks(a, q) -> list[list[int]]:
    """Connected components of the coupling graph of (A, Q) (in order of first state)."""
    n = len(a)
    adj = (np.abs(a) + np.abs(a.T) + np.abs(q) + np.abs(q.T)) > 0
    seen, out = set(), []
    for s in range(n):
        if s in seen:
            continue
        comp, stack = [], [s]
        while stack:
            i = stack.pop()
            if i in seen:
                continue
            seen.add(i)
            comp.append(i)
            stack += [j for j in range(n) if adj[i, j] and j not in seen]
        out.append(sorted(comp))
    return out


def _symbolic(fun):
    """numpy reports the floating-point flags Drake's symbolic arithmetic leaves behind in
    object-array products as "invalid value" warnings; they mean nothing here."""

    def wrapped(*args, **kwargs):
        with np.errstate(all="ignore"):
            return fun(*args, **kwargs)

    wrapped.__name__, wrapped.__doc__ = fun.__name__, fun.__doc__
    return wrapped


def _solver(name: str):
    solvers = {"clarabel": ClarabelSolver, "scs": ScsSolver, "csdp": CsdpSolver}
    s = solvers[name]()
    if not s.available():
        raise RuntimeError(f"SDP solver {name} is not available in this Drake")
    return s


def _solve_max_rho(prog, rho, solver_name: str) -> tuple[float, str]:
    prog.AddLinearCost(-rho)
    result = _solver(solver_name).Solve(prog, None, SolverOptions())
    if not result.is_success():
        raise RuntimeError(f"SOS programme failed: {result.get_solution_result()}")
    return float(result.GetSolution(rho)), str(result.get_solution_result())


@_symbolic
def sos_rho_polynomial(
    xi: Hydrodynamics, k: np.ndarray, p: np.ndarray, cap: float, solver_name: str = "clarabel"
) -> float:
    """max ρ ≤ cap with V̇ < 0 on {V < ρ} \\ {0} for the unsaturated polynomial dynamics
    (one-shot SOS, λ free of degree 1)."""
    prog = MathematicalProgram()
    z = prog.NewIndeterminates(6, "z")
    vdot = 2.0 * (z @ p) @ dp_error_dynamics(xi, z, k @ z)
    rho = prog.NewContinuousVariables(1, "rho")[0]
    lam = prog.NewFreePolynomial(Variables(z), 1).ToExpression()
    prog.AddSosConstraint((z @ z) * (z @ p @ z - rho) - lam * vdot)
    prog.AddBoundingBoxConstraint(0.0, cap, rho)
    return _solve_max_rho(prog, rho, solver_name)[0]


def _add_saturation(prog, xs, tau, w, tmax, lam_deg=2):
    """The S-procedure terms pinning w = sat(τ) (module docstring); returns their sum."""
    ind = Variables(xs)
    s1 = prog.NewSosPolynomial(ind, 2)[0].ToExpression()
    s2 = prog.NewSosPolynomial(ind, 2)[0].ToExpression()
    pf = prog.NewFreePolynomial(ind, 1).ToExpression()
    g1 = tmax * tmax - w * w
    return s1 * g1 + s2 * (tau - w) * w + pf * (tau - w) * g1


@_symbolic
def sos_rho_channel(
    p_c: np.ndarray,
    a_c: np.ndarray,
    b_c: np.ndarray,
    k_c: np.ndarray,
    tmax: float,
    cap: float,
    solver_name: str = "clarabel",
) -> float:
    """max ρ ≤ cap with V̇_c < 0 on {V_c < ρ} \\ {0} for one DOF channel ż = A_c z + b_c sat(k_cᵀ
    z), V_c = zᵀ P_c z (3 indeterminates: z_c and w)."""
    prog = MathematicalProgram()
    z = prog.NewIndeterminates(2, "z")
    w = prog.NewIndeterminates(1, "w")[0]
    xs = np.concatenate([z, [w]])
    vdot = 2.0 * (z @ p_c) @ (a_c @ z + b_c * w)
    rho = prog.NewContinuousVariables(1, "rho")[0]
    lam = prog.NewFreePolynomial(Variables(xs), 2).ToExpression()
    sat = _add_saturation(prog, xs, k_c @ z, w, tmax)
    prog.AddSosConstraint((z @ z) * (z @ p_c @ z - rho) - lam * vdot - sat)
    prog.AddBoundingBoxConstraint(0.0, cap, rho)
    return _solve_max_rho(prog, rho, solver_name)[0]


@_symbolic
def sos_rho_full(
    xi: Hydrodynamics,
    k: np.ndarray,
    p: np.ndarray,
    tau_max: np.ndarray,
    cap: float,
    solver_name: str = "clarabel",
) -> float:
    """The undecomposed saturated programme (9 indeterminates, λ free of degree 1); slow."""
    prog = MathematicalProgram()
    z = prog.NewIndeterminates(6, "z")
    w = prog.NewIndeterminates(3, "w")
    xs = np.concatenate([z, w])
    vdot = 2.0 * (z @ p) @ dp_error_dynamics(xi, z, w)
    rho = prog.NewContinuousVariables(1, "rho")[0]
    lam = prog.NewFreePolynomial(Variables(xs), 1).ToExpression()
    expr = (z @ z) * (z @ p @ z - rho) - lam * vdot
    tau = k @ z
    for i in range(3):
        expr = expr - _add_saturation(prog, xs, tau[i], w[i], tau_max[i])
    prog.AddSosConstraint(expr)
    prog.AddBoundingBoxConstraint(0.0, cap, rho)
    return _solve_max_rho(prog, rho, solver_name)[0]


@_symbolic
def coupling_remainder(xi: Hydrodynamics, p: np.ndarray) -> float:
    """max |coefficient| of the non-linear (Coriolis + kinematic) part of V̇, 2 zᵀ P f_nl(z),
    expanded symbolically: 0 means V̇ is the sum of the per-channel linear terms."""
    prog = MathematicalProgram()
    z = prog.NewIndeterminates(6, "z")
    a = straight_run_jacobian(xi, 0.0)
    f_nl = dp_error_dynamics(xi, z, np.zeros(3)) - a @ z
    poly = Polynomial(2.0 * (z @ p) @ f_nl)
    coeffs = [abs(c.Evaluate()) for c in poly.monomial_to_coefficient_map().values()]
    return max(coeffs, default=0.0)
