"""A structure-exploiting interior-point solver for the optimal-control QP of (N)MPC:

    min  Σ_{k<N} ½ x_kᵀ Q_k x_k + q_kᵀ x_k + ½ u_kᵀ R_k u_k + r_kᵀ u_k  +  ½ x_Nᵀ Q_N x_N + q_Nᵀ x_N
    s.t. x_0 = x̂,   x_{k+1} = A_k x_k + B_k u_k + c_k,
         lbu_k ≤ u_k ≤ ubu_k (k < N),   lbx_k ≤ x_k ≤ ubx_k (1 ≤ k ≤ N),

with diagonal Q_k ⪰ 0, R_k ≻ 0 and ±inf marking an absent bound (masked out, never a big number).
x_0 is fixed to x̂, so state bounds apply from k = 1: a bound on x_0 could only make the problem
infeasible when x̂ itself violates it (the sparse Clarabel QP of ``nmpc_problem`` declares it on
q_0 too and fails then; this solver does not).

Method: the primal-dual predictor-corrector interior point of Mehrotra 1992 (infeasible start),
as in HPIPM (Frison & Diehl 2020) and Rao, Wright & Rawlings 1998. Each bound is an inequality
with a slack s ≥ 0 and a multiplier λ ≥ 0; eliminating them adds λ/s to the diagonal Hessian,
and the Newton system keeps the OCP structure, so a backward Riccati recursion over the stages
solves it (O(N (n_x + n_u)³) work), factorised once per iteration and back-substituted twice
(predictor and corrector share the matrix). The cost-to-go update is written as a sum of
positive semi-definite terms (Joseph form): the textbook AᵀPA − FᵀG⁻¹F cancels the huge λ/s of
active bounds near convergence (1 numerical failure in 60 random instances, none this way).
Near the end, λ/s ~ 1e16 also makes G = R̃ + BᵀPB lose definiteness in rounding: an iterate
that already has μ within 1e-4 · tol of the scales (the ones seen are 1e-16 .. 1e-14) is then
returned as converged, being as exact as double precision allows. A solve is one call into compiled
code (:func:`_ipm` and the numba functions it calls; no Python per stage or per iteration);
small dense products are explicit loops because BLAS calls on 6 × 6 matrices cost more than the
arithmetic.

Status: converged (relative residuals and complementarity below ``tol``), maximum iterations,
infeasible-looking (multipliers diverging, the step collapsing, or μ stuck while the bounds stay
violated: what an infeasible box does to an interior-point method), a numerical failure
(non-finite iterate, singular Riccati block), or stalled (μ stuck at a feasible point: Mehrotra's
heuristic cycling; :func:`solve_ocp_qp` then tries once more from larger multipliers).
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

CONVERGED, MAX_ITERATIONS, INFEASIBLE, NUMERICAL, STALLED = 0, 1, 2, 3, 4
STATUS_TEXT = ("converged", "max iterations", "infeasible-looking", "numerical failure", "stalled")

STEP_FRACTION = 0.995  # fraction of the step to the boundary (keeps s, λ strictly positive)
INIT_SLACK = 1.0  # slacks start at least this far from their bound, λ = μ₀ / s
# converged when μ ≤ MU_REL · tol · (gradient scale) · (primal scale): at a weakly active bound
# (λ* ≈ 0) s and λ both shrink only like √μ, so μ must be far below tol for the solution to be
# within tol; 1e-16 relative gives ≤ 3e-7 N on the NMPC (1e-14: 1.2e-5 N) at one more iteration
MU_REL = 1e-8
DIVERGED = 1e12  # λ beyond this × the gradient scale: the dual is running away (infeasible)
MIN_STEP = 1e-10  # a step this short several times in a row: stalled at an infeasible box
# μ not down by 10× over 10 iterations (after the first 15): Mehrotra's heuristic is cycling
# (seen in HIL runs: μ alternating ~16 / ~31 with σ alternating ~0.9 / ~0.1)
STALL_WINDOW, STALL_START = 10, 15


@dataclass
class OcpQpSolution:
    x: np.ndarray  # (N + 1, n_x) states
    u: np.ndarray  # (N, n_u) inputs
    pi: np.ndarray  # (N, n_x) multipliers of the dynamics
    status: int  # CONVERGED, MAX_ITERATIONS, INFEASIBLE or NUMERICAL
    iterations: int  # Newton steps taken
    res_stat: float  # ‖∇ Lagrangian‖∞ at the returned point
    res_eq: float  # ‖dynamics residual‖∞
    res_ineq: float  # ‖bound residual (z − lb − s, ub − z − s)‖∞
    mu: float  # mean complementarity sᵀλ / m

    @property
    def success(self) -> bool:
        return self.status == CONVERGED

    @property
    def status_text(self) -> str:
        return STATUS_TEXT[self.status]


def _c_array(v, shape: tuple) -> np.ndarray:
    """v as a writable C-contiguous float64 array of that shape, copied only when it is not one
    already (readonly or strided arrays would compile another numba specialisation)."""
    a = np.asarray(v, np.float64)
    if a.shape == shape and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(np.broadcast_to(a, shape), order="C")


def _stage_array(v, n: int, dim: int, fill: float) -> np.ndarray:
    """A bound or weight per stage, (n, dim): None → fill, (dim,) → repeated."""
    return np.full((n, dim), fill) if v is None else _c_array(v, (n, dim))


def solve_ocp_qp(
    A,
    B,
    c,
    x0,
    Q,
    q,
    R,
    r,
    lbx=None,
    ubx=None,
    lbu=None,
    ubu=None,
    x_init=None,
    u_init=None,
    tol: float = 1e-8,
    max_iter: int = 50,
) -> OcpQpSolution:
    """Solve the OCP QP above. A (N, n_x, n_x), B (N, n_x, n_u), c (N, n_x), x0 (n_x,); the
    diagonals Q (N + 1, n_x) (row N is the terminal weight) and R (N, n_u); linear terms q
    (N + 1, n_x), r (N, n_u); bounds per stage or one row for all, ±inf or None for none
    (lbx/ubx rows 0..N, row 0 ignored). x_init, u_init: a primal starting point (default 0;
    infeasible starts are fine)."""
    n, nx, nu = np.shape(B)
    x = np.zeros((n + 1, nx)) if x_init is None else np.array(x_init, float, order="C")
    u = np.zeros((n, nu)) if u_init is None else np.array(u_init, float, order="C")
    x[0] = x0
    args = (
        _c_array(A, (n, nx, nx)),
        _c_array(B, (n, nx, nu)),
        _c_array(c, (n, nx)),
        _c_array(x0, (nx,)),
        _stage_array(Q, n + 1, nx, 0.0),
        _stage_array(q, n + 1, nx, 0.0),
        _stage_array(R, n, nu, 0.0),
        _stage_array(r, n, nu, 0.0),
        _stage_array(lbx, n + 1, nx, -np.inf),
        _stage_array(ubx, n + 1, nx, np.inf),
        _stage_array(lbu, n, nu, -np.inf),
        _stage_array(ubu, n, nu, np.inf),
    )
    x_start, u_start = x.copy(), u.copy()
    pi = np.zeros((n, nx))
    status, it, res = _ipm(*args, x, u, pi, float(tol), int(max_iter), 1.0)
    if status in (STALLED, MAX_ITERATIONS, NUMERICAL):
        # a cycling start (seen in a HIL run: λ_l and λ_u of one input growing together from
        # λ far below the gradient's scale) may converge from λ at that scale: one more try
        mu0 = max(1.0, float(np.max(np.abs(args[5]))), float(np.max(np.abs(args[7]))))
        x, u, pi = x_start, u_start, np.zeros((n, nx))
        status, it2, res = _ipm(*args, x, u, pi, float(tol), int(max_iter), mu0)
        it += it2
    return OcpQpSolution(x, u, pi, int(status), int(it), res[0], res[1], res[2], res[3])


def warm_up() -> None:
    """Load (or compile) the compiled code now: the first call costs ~0.1-0.3 s (20-30 s on a
    fresh cache), which a real-time loop must not pay at its first control step (a HIL run's
    thruster watchdog tripped on it). The signature depends on types only, so a 1-stage QP
    with one bound serves every later size."""
    one, zero = np.ones((1, 1)), np.zeros((1, 1))
    solve_ocp_qp(one[None], one[None], zero, [0.0], [[1.0], [1.0]], [[0.0], [0.0]], one, zero,
                 lbu=-1.0, ubu=1.0)  # fmt: skip


# --- the compiled core ----------------------------------------------------------------------------
# Rows of a packed box array (NBOX, stages, dim), one for x and one for u: slacks and
# multipliers of the lower / upper bounds, their primal residuals z − lb − s_l and ub − z − s_u,
# complementarity right-hand sides, Newton steps, and the predictor's steps kept for the
# corrector. An absent bound has s = 1, λ = 0 and zeros in every other row, so all formulas
# below contribute nothing for it (masking, not big numbers).
SL, SU, LL, LU, RL, RU, RCL, RCU, DSL, DSU, DLL, DLU, ASL, ASU, ALL, ALU = range(16)
NBOX = 16


@njit(cache=True)
def _box_init(z, lb, ub, ml, mu, box, mu0):
    """Slacks at least INIT_SLACK (the primal may start outside its box), λ = μ₀ / s.
    Returns the number of finite bounds."""
    zf, lbf, ubf, mlf, muf = z.ravel(), lb.ravel(), ub.ravel(), ml.ravel(), mu.ravel()
    bf = box.reshape(NBOX, zf.size)
    bf[:] = 0.0
    m = 0
    for i in range(zf.size):
        bf[SL, i], bf[SU, i] = 1.0, 1.0
        if mlf[i]:
            bf[SL, i] = max(zf[i] - lbf[i], INIT_SLACK)
            bf[LL, i] = mu0 / bf[SL, i]
            m += 1
        if muf[i]:
            bf[SU, i] = max(ubf[i] - zf[i], INIT_SLACK)
            bf[LU, i] = mu0 / bf[SU, i]
            m += 1
    return m


@njit(cache=True)
def _box_residuals(z, lb, ub, ml, mu, box):
    """Primal residuals of the bounds; returns (‖·‖∞, Σ sλ, max λ)."""
    zf, lbf, ubf, mlf, muf = z.ravel(), lb.ravel(), ub.ravel(), ml.ravel(), mu.ravel()
    bf = box.reshape(NBOX, zf.size)
    worst, gap, lam = 0.0, 0.0, 0.0
    for i in range(zf.size):
        if mlf[i]:
            bf[RL, i] = zf[i] - lbf[i] - bf[SL, i]
        if muf[i]:
            bf[RU, i] = ubf[i] - zf[i] - bf[SU, i]
        worst = max(worst, abs(bf[RL, i]), abs(bf[RU, i]))
        gap += bf[SL, i] * bf[LL, i] + bf[SU, i] * bf[LU, i]
        lam = max(lam, bf[LL, i], bf[LU, i])
    return worst, gap, lam


@njit(cache=True)
def _box_hessian(h, box, h_out):
    """The Newton system's diagonal: the cost's plus λ/s of each bound (0 for absent ones)."""
    hf, of = h.ravel(), h_out.ravel()
    bf = box.reshape(NBOX, hf.size)
    for i in range(hf.size):
        of[i] = hf[i] + bf[LL, i] / bf[SL, i] + bf[LU, i] / bf[SU, i]


@njit(cache=True)
def _box_rhs(box, ml, mu, sigma_mu, corrector, rs, g):
    """Complementarity right-hand sides rc = −s∘λ (predictor), + σμ − ds_aff∘dλ_aff
    (corrector); then the reduced gradient g = r_stat − (rc_l − λ_l r_l)/s_l
    + (rc_u − λ_u r_u)/s_u: the stationarity row after eliminating ds = ±dz + r and
    dλ = (rc − λ ds)/s."""
    rf, gf, mlf, muf = rs.ravel(), g.ravel(), ml.ravel(), mu.ravel()
    bf = box.reshape(NBOX, gf.size)
    for i in range(gf.size):
        rcl = -bf[SL, i] * bf[LL, i]
        rcu = -bf[SU, i] * bf[LU, i]
        if corrector:
            rcl += sigma_mu * mlf[i] - bf[ASL, i] * bf[ALL, i]
            rcu += sigma_mu * muf[i] - bf[ASU, i] * bf[ALU, i]
        bf[RCL, i], bf[RCU, i] = rcl, rcu
        gf[i] = (
            rf[i]
            - (rcl - bf[LL, i] * bf[RL, i]) / bf[SL, i]
            + (rcu - bf[LU, i] * bf[RU, i]) / bf[SU, i]
        )


@njit(cache=True)
def _box_step(dz, ml, mu, box):
    """Recover ds, dλ from dz; return the largest α keeping s + α ds, λ + α dλ ≥ 0 (inf: any)."""
    df, mlf, muf = dz.ravel(), ml.ravel(), mu.ravel()
    bf = box.reshape(NBOX, df.size)
    alpha = np.inf
    for i in range(df.size):
        bf[DSL, i] = df[i] + bf[RL, i] if mlf[i] else 0.0
        bf[DSU, i] = bf[RU, i] - df[i] if muf[i] else 0.0
        bf[DLL, i] = (bf[RCL, i] - bf[LL, i] * bf[DSL, i]) / bf[SL, i]
        bf[DLU, i] = (bf[RCU, i] - bf[LU, i] * bf[DSU, i]) / bf[SU, i]
        for j in range(4):  # the rows SL, SU, LL, LU against DSL, DSU, DLL, DLU
            dv = bf[DSL + j, i]
            if dv < 0.0:
                alpha = min(alpha, -bf[SL + j, i] / dv)
    return alpha


@njit(cache=True)
def _box_mu_after(box, alpha):
    """Σ (s + α ds)(λ + α dλ) over the bounds: Mehrotra's μ_aff (times m)."""
    bf = box.reshape(NBOX, box[0].size)
    total = 0.0
    for i in range(bf.shape[1]):
        total += (bf[SL, i] + alpha * bf[DSL, i]) * (bf[LL, i] + alpha * bf[DLL, i])
        total += (bf[SU, i] + alpha * bf[DSU, i]) * (bf[LU, i] + alpha * bf[DLU, i])
    return total


@njit(cache=True)
def _factorize(A, B, Qt, Rt, P, K, L):
    """Backward Riccati recursion of the Newton system's matrix: P_N = Q̃_N; per stage
    G = R̃ + BᵀPB = LLᵀ, K = −G⁻¹BᵀPA, P_k = Q̃_k + (A + BK)ᵀP(A + BK) + KᵀR̃K. False if G is
    not numerically positive definite."""
    n, nx, nu = B.shape
    P[n] = 0.0
    for i in range(nx):
        P[n, i, i] = Qt[n, i]
    pa = np.empty((nx, nx))
    pb = np.empty((nx, nu))
    f = np.empty((nu, nx))
    acl, w = np.empty((nx, nx)), np.empty((nx, nx))
    # loops ordered so that the innermost runs along contiguous rows (LLVM vectorises them)
    for k in range(n - 1, -1, -1):
        a, b, p, g = A[k], B[k], P[k + 1], L[k]
        pa[:] = 0.0
        pb[:] = 0.0
        for i in range(nx):
            for m in range(nx):
                pim = p[i, m]
                for j in range(nx):
                    pa[i, j] += pim * a[m, j]
                for j in range(nu):
                    pb[i, j] += pim * b[m, j]
        g[:] = 0.0
        f[:] = 0.0
        for i in range(nu):
            g[i, i] = Rt[k, i]
        for m in range(nx):
            for i in range(nu):
                bmi = b[m, i]
                for j in range(nu):
                    g[i, j] += bmi * pb[m, j]
                for j in range(nx):
                    f[i, j] += bmi * pa[m, j]
        # Cholesky G = L Lᵀ in place (lower triangle)
        for j in range(nu):
            s = g[j, j]
            for m in range(j):
                s -= g[j, m] * g[j, m]
            if not s > 0.0:
                return False
            g[j, j] = np.sqrt(s)
            for i in range(j + 1, nu):
                t = g[i, j]
                for m in range(j):
                    t -= g[i, m] * g[j, m]
                g[i, j] = t / g[j, j]
            for i in range(j):
                g[i, j] = 0.0
        for j in range(nx):  # K[:, j] = −G⁻¹ f[:, j]
            col = K[k, :, j]
            _chol_solve(g, f[:, j], col)
            for i in range(nu):
                col[i] = -col[i]
        if k == 0:
            break  # x_0 is fixed: P_0 is never used
        # Joseph form P_k = Q̃ + (A + BK)ᵀ P (A + BK) + Kᵀ R̃ K: a sum of PSD terms, where
        # AᵀPA − FᵀG⁻¹F cancels huge barrier terms (λ/s ~ 1e16 near the end) and goes indefinite
        kk_ = K[k]
        for i in range(nx):
            for j in range(nx):
                acl[i, j] = a[i, j]
                w[i, j] = pa[i, j]
            for m in range(nu):
                bim, pbim = b[i, m], pb[i, m]
                for j in range(nx):
                    acl[i, j] += bim * kk_[m, j]
                    w[i, j] += pbim * kk_[m, j]
        pk = P[k]
        pk[:] = 0.0
        for m in range(nx):
            for i in range(nx):
                ami = acl[m, i]
                for j in range(nx):
                    pk[i, j] += ami * w[m, j]
        for m in range(nu):
            for i in range(nx):
                kmi = Rt[k, m] * kk_[m, i]
                for j in range(nx):
                    pk[i, j] += kmi * kk_[m, j]
        for i in range(nx):  # exactly symmetric (rounding would make it drift)
            pk[i, i] += Qt[k, i]
            for j in range(i):
                pk[i, j] = pk[j, i] = 0.5 * (pk[i, j] + pk[j, i])
    return True


@njit(cache=True, inline="always")
def _chol_solve(lo, rhs, out):
    """out = (L Lᵀ)⁻¹ rhs for the lower-triangular L in ``lo``."""
    n = rhs.size
    for i in range(n):
        s = rhs[i]
        for m in range(i):
            s -= lo[i, m] * out[m]
        out[i] = s / lo[i, i]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for m in range(i + 1, n):
            s -= lo[m, i] * out[m]
        out[i] = s / lo[i, i]


@njit(cache=True)
def _back_substitute(A, B, P, K, L, gx, gu, rd, p, kk, dx, du, dpi):
    """Solve the Newton system for one right-hand side with the factorisation: backward pass for
    the value function's linear term p_k and the feedforward kk_k, forward rollout from dx_0 = 0;
    the dynamics multiplier is the gradient of the value function at the next state."""
    n, nx, nu = B.shape
    h = np.empty(nx)
    gk = np.empty(nu)
    p[n] = gx[n]
    for k in range(n - 1, -1, -1):
        for i in range(nx):
            s = p[k + 1, i]
            for m in range(nx):
                s += P[k + 1, i, m] * rd[k, m]
            h[i] = s
        for i in range(nu):
            s = gu[k, i]
            for m in range(nx):
                s += B[k, m, i] * h[m]
            gk[i] = s
        _chol_solve(L[k], gk, kk[k])
        for i in range(nu):
            kk[k, i] = -kk[k, i]
        if k > 0:
            for i in range(nx):
                s = gx[k, i]
                for m in range(nx):
                    s += A[k, m, i] * h[m]
                for m in range(nu):
                    s += K[k, m, i] * gk[m]
                p[k, i] = s
    dx[0] = 0.0
    for k in range(n):
        for i in range(nu):
            s = kk[k, i]
            for m in range(nx):
                s += K[k, i, m] * dx[k, m]
            du[k, i] = s
        for i in range(nx):
            s = rd[k, i]
            for m in range(nx):
                s += A[k, i, m] * dx[k, m]
            for m in range(nu):
                s += B[k, i, m] * du[k, m]
            dx[k + 1, i] = s
        for i in range(nx):
            s = p[k + 1, i]
            for m in range(nx):
                s += P[k + 1, i, m] * dx[k + 1, m]
            dpi[k, i] = s


@njit(cache=True)
def _residuals(A, B, c, Q, q, R, r, x, u, pi, bx, bu, rsx, rsu, rd):
    """Stationarity (rows k ≥ 1 for x) and dynamics residuals; returns their ∞-norms."""
    n, nx, nu = B.shape
    stat, eq = 0.0, 0.0
    rsx[0] = 0.0
    for k in range(1, n + 1):
        for i in range(nx):
            s = Q[k, i] * x[k, i] + q[k, i] - pi[k - 1, i] - bx[LL, k, i] + bx[LU, k, i]
            if k < n:
                for m in range(nx):
                    s += A[k, m, i] * pi[k, m]
            rsx[k, i] = s
            stat = max(stat, abs(s))
    for k in range(n):
        for i in range(nu):
            s = R[k, i] * u[k, i] + r[k, i] - bu[LL, k, i] + bu[LU, k, i]
            for m in range(nx):
                s += B[k, m, i] * pi[k, m]
            rsu[k, i] = s
            stat = max(stat, abs(s))
        for i in range(nx):
            s = c[k, i] - x[k + 1, i]
            for m in range(nx):
                s += A[k, i, m] * x[k, m]
            for m in range(nu):
                s += B[k, i, m] * u[k, m]
            rd[k, i] = s
            eq = max(eq, abs(s))
    return stat, eq


@njit(cache=True)
def _ipm(A, B, c, x0, Q, q, R, r, lbx, ubx, lbu, ubu, x, u, pi, tol, max_iter, mu0):
    """Mehrotra predictor-corrector on the OCP QP; x, u, pi are updated in place. Returns
    (status, iterations, [res_stat, res_eq, res_ineq, mu])."""
    n, nx, nu = B.shape
    mlx, mux = np.isfinite(lbx), np.isfinite(ubx)
    mlx[0], mux[0] = False, False  # x_0 is fixed (see the module docstring)
    mlu, muu = np.isfinite(lbu), np.isfinite(ubu)
    bx, bu = np.empty((NBOX, n + 1, nx)), np.empty((NBOX, n, nu))
    rsx, gx, dx, Qt = (
        np.empty((n + 1, nx)),
        np.empty((n + 1, nx)),
        np.empty((n + 1, nx)),
        np.empty((n + 1, nx)),
    )
    rsu, gu, du, Rt = np.empty((n, nu)), np.empty((n, nu)), np.empty((n, nu)), np.empty((n, nu))
    rd, dpi = np.empty((n, nx)), np.empty((n, nx))
    P, K, L = np.empty((n + 1, nx, nx)), np.empty((n, nu, nx)), np.empty((n, nu, nu))
    p, kk = np.empty((n + 1, nx)), np.empty((n, nu))

    x[0] = x0
    m = _box_init(x, lbx, ubx, mlx, mux, bx, mu0) + _box_init(u, lbu, ubu, mlu, muu, bu, mu0)
    # scales for the relative tolerances: the data's magnitudes, at least 1
    g_scale, p_scale = 1.0, 1.0
    for v in (q.ravel(), r.ravel()):
        for i in range(v.size):
            g_scale = max(g_scale, abs(v[i]))
    for v in (c.ravel(), x0, lbx.ravel(), ubx.ravel(), lbu.ravel(), ubu.ravel()):
        for i in range(v.size):
            if np.isfinite(v[i]):
                p_scale = max(p_scale, abs(v[i]))

    res = np.zeros(4)
    mu_hist = np.zeros(max_iter + 1)
    status, it, short_steps = MAX_ITERATIONS, 0, 0
    while True:
        stat, eq = _residuals(A, B, c, Q, q, R, r, x, u, pi, bx, bu, rsx, rsu, rd)
        ineq_x, gap_x, lam_x = _box_residuals(x, lbx, ubx, mlx, mux, bx)
        ineq_u, gap_u, lam_u = _box_residuals(u, lbu, ubu, mlu, muu, bu)
        ineq = max(ineq_x, ineq_u)
        mu = (gap_x + gap_u) / m if m > 0 else 0.0
        res[0], res[1], res[2], res[3] = stat, eq, ineq, mu
        if not (np.isfinite(stat) and np.isfinite(eq) and np.isfinite(ineq) and np.isfinite(mu)):
            status = NUMERICAL
            break
        residuals_ok = stat <= tol * g_scale and max(eq, ineq) <= tol * p_scale
        if residuals_ok and mu <= MU_REL * tol * g_scale * p_scale:
            status = CONVERGED
            break
        if max(lam_x, lam_u) > DIVERGED * g_scale or short_steps >= 3:
            status = INFEASIBLE
            break
        mu_hist[it] = mu
        if it >= STALL_START and mu > 0.1 * mu_hist[it - STALL_WINDOW]:
            # no progress on μ: cycling if the primal is (nearly) feasible, else an infeasible box
            status = STALLED if max(eq, ineq) <= 1e-4 * p_scale else INFEASIBLE
            break
        if it >= max_iter:
            break
        it += 1
        _box_hessian(Q, bx, Qt)
        _box_hessian(R, bu, Rt)
        if not _factorize(A, B, Qt, Rt, P, K, L):
            # λ/s of active bounds has outgrown double precision: accept the point if it is
            # already at that floor (see the module docstring), else give up
            ok = residuals_ok and mu <= 1e-4 * tol * g_scale * p_scale
            status = CONVERGED if ok else NUMERICAL
            break
        # predictor (affine scaling, σ = 0), then the corrector with Mehrotra's σ = (μ_aff/μ)³
        # and the second-order term; both reuse the one factorisation
        sigma_mu = 0.0
        for corrector in (False, True):
            _box_rhs(bx, mlx, mux, sigma_mu, corrector, rsx, gx)
            _box_rhs(bu, mlu, muu, sigma_mu, corrector, rsu, gu)
            _back_substitute(A, B, P, K, L, gx, gu, rd, p, kk, dx, du, dpi)
            alpha = min(_box_step(dx, mlx, mux, bx), _box_step(du, mlu, muu, bu))
            if not corrector:
                alpha = min(1.0, alpha)
                mu_aff = (_box_mu_after(bx, alpha) + _box_mu_after(bu, alpha)) / max(m, 1)
                sigma_mu = (mu_aff / mu) ** 3 * mu if mu > 0.0 else 0.0
                bx[ASL : ALU + 1] = bx[DSL : DLU + 1]
                bu[ASL : ALU + 1] = bu[DSL : DLU + 1]
        alpha = min(1.0, STEP_FRACTION * alpha)  # a full Newton step if the boundary is far
        short_steps = short_steps + 1 if alpha < MIN_STEP else 0
        x += alpha * dx
        u += alpha * du
        pi += alpha * dpi
        bx[SL : LU + 1] += alpha * bx[DSL : DLU + 1]
        bu[SL : LU + 1] += alpha * bu[DSL : DLU + 1]
    return status, it, res
