"""The NMHE of Roboat II §IV-C, eqs. (15)-(17), as one Gauss-Newton QP per sample (numerical core of
``Nmhe``).

**Window.** M samples at t_0 < … < t_{M−1} = t_j (newest last), dt apart. Sample k carries the
pose measurement z_k = [x y ψ r] (the first four entries of eq. 8) and the measured thruster
command ũ_k (the last n_u entries of eq. 8: per thruster [f] or [f, α]), the force applied over
[t_k, t_{k+1}). A missing entry is NaN (weight zero); the window may be only partly filled.

**The problem** (what we solve, term by term against eq. 15):

    min   ‖q̂_p − q̄‖²_PL                               arrival cost, 15a; PL fixed, eq. (17)
        + Σ_{k=0}^{M−1} ‖z_k − C q̂_k‖²_{R_z}            pose residuals, 15a; R_z ⊂ RT, eq. (16)
        + Σ_{k=0}^{M−2} ‖ũ_k − u_k‖²_{R_u}              thrust residuals, 15a; R_u ⊂ RT, (16)
        + Σ_{k=0}^{M−2} ‖d_k‖²_{Q_d}                    process noise w_k of 15b (ours)
        + ‖b − b̄‖²_{P_b}                                slow unmodelled force (ours)
    over  q̂_0 … q̂_{M−1} (6 each), u_0 … u_{M−2} (n_u each), d_0 … d_{M−2} (3 each), b (3)
    s.t.  q̂_{k+1} = F(q̂_k, τ(u_k) + b + d_k)          15b, F = RK4 of eq. (7) over dt
          q_min ≤ (u, v, r)_k ≤ q_max                    15c: ±3 m/s, ±2 m/s, ±2 rad/s

with C picking [x y ψ r] (h of eq. 8 without the forces, which are the u_k terms), p the first
sample of the window (while it fills, the first one received), R_z = diag(0.0005, 0.0005,
0.0005, 0.0001)⁻¹ and R_u = 1 N⁻² per force (RT of eq. 16), PL = diag(1, 1, 1, 0.1, 0.1, 1)⁻¹
(eq. 17). 15b as printed reads f(q̂_{k+1}, u_k); we use q̂_k.

* **Forces as decision variables.** Eq. (8) lists f1..f4 among the measurements, so the
  thruster forces u_k are estimated, weighted by RT's last four entries, rather than taken as
  known inputs: a reading may be off by ~1 N (``ThrustSensor``'s default noise) and treating it
  as exact would push that error into the velocities.
* **Process noise.** Eq. (15b) has a w_k that (15a) does not weight; left free it would cut q̂
  loose from the model, and u, v — never measured — would be fixed by the arrival cost alone.
  We take w_k as an unmodelled body force d_k [N, N, N m] entering where τ does,
  Q_d = diag(2 N, 2 N, 0.5 N m)⁻², so the velocities see it through the exact RK4 input
  Jacobian.
* **Slow force b.** Wind, current drag (a current shifts the drag by D ν_c) and model error are
  nearly constant over a window; white d_k explains a constant force only at a cost, and the
  velocity estimate was biased by 0.015-0.02 m/s under a 3-5 N force (our trials). b is one extra
  3-vector per window with the arrival-style prior b̄ = the last b̂, P_b = diag(0.5 N, 0.5 N,
  0.1 N m)⁻² (a random walk per sample); it is held at b̄ while the window fills, so start-up
  errors are not learnt as a force. ``bias_std`` = 0 removes it (then the problem is eq. 15
  plus d_k).

**Reduction (exact).** u_k and d_k enter only through the force error
e_k = τ(u_k) + d_k − τ(ũ_k) = J_k (u_k − ũ_k) + d_k (J_k = ∂τ/∂u at ũ_k; τ = B u is linear for
fixed thrusters, linearised for azimuths). Minimising their two terms for a given e_k leaves
e_kᵀ S_k⁻¹ e_k with S_k = J_k R_u⁻¹ J_kᵀ + Q_d⁻¹ (the covariance of a sum of independent
Gaussians), so the QP carries e_k (3 per step) instead of (u_k, d_k) (n_u + 3) and gives the
same q̂; the split is recovered afterwards: û_k = ũ_k + R_u⁻¹ J_kᵀ S_k⁻¹ e_k,
d̂_k = Q_d⁻¹ S_k⁻¹ e_k.

**One QP per call (real-time iteration, Diehl et al. 2005).** With the guess q̄_k (the previous
solution shifted by one sample, its newest state propagated with the measured thrust and b̄)
the dynamics are linearised with ``rk4_with_jacobians`` about (q̄_k, τ̃_k + b̄): in
δq_k = q̂_k − q̄_k and δb = b − b̄,

    δq_{k+1} = A_k δq_k + B_k (e_k + δb) + (F(q̄_k, τ̃_k + b̄) − q̄_{k+1}),

a sparse equality-constrained QP in (δq, e, δb, δb_a) — 6M + 3(M−1) + 3 + 2 = 182 variables for M =
20, 6(M−1) = 114 equalities, 3M bounds. Deviations keep the numbers O(1) wherever the vessel is. The
model is bilinear in the velocities and smooth in ψ, and the guess is one sample old, so one step
per sample converges (noiseless data: error < 1e-4 once the window is full).

**Solvers.** The velocity bounds (15c) are far from a boat's motion, so the default ("condensed")
first solves the QP without them: the dynamics give every δq_k from z = [δq_0, e, δb, δb_a]
(condensing, x = T z + t), leaving an unconstrained problem in 68 variables (M = 20) solved by one
Cholesky factorisation; a minimiser inside the bounds is the bounded QP's minimiser too (KKT with
zero multipliers), and one outside goes to Clarabel. The QP is also built once in a
``MathematicalProgram``, refilled with ``UpdateCoefficients`` / ``set_bounds`` and solved by
Clarabel or OSQP when asked ("clarabel", "osqp"). Whole call, M = 20, Roboat II, with the IMU
terms, river_tracking 30 s: condensed median 1.7 ms, Clarabel 3.1 ms, the same metrics to 2e-10
(earlier, pose and thrust only: Clarabel 1.5 ms, OSQP 1.2-1.3 ms, same estimates to 1e-10). An
interior-point method's accuracy does not depend on the conditioning (the weights here span 0.1 to
10⁴); the Cholesky factorisation of a positive-definite matrix of that conditioning loses ~4
digits of 16, and a factorisation that fails also goes to Clarabel.

**IMU** (not in Roboat II, whose z is pose and thrust only; used when an IMU feeds the window).
Waves move a small boat at 0.3-1 Hz by a few cm/s but only ~1 cm, under the pose noise (σ = 2.2 cm):
no estimator on poses alone can see that motion (river_tracking: u, v RMSE 0.041 m/s on poses,
0.009 / 0.012 with the IMU). The IMU's readings, averaged over each interval (``ImuIntervalMean``,
level frame), m_k = [f̄_x f̄_y ω̄_z], add

        + Σ_k ‖m_k − h(q̂_k, q̂_{k+1}) − [b_a; 0]‖²_{R_imu} + ‖b_a − b̄_a‖²_{P_a}

with h of :func:`imu_interval_model` (exact in ν_{k+1} − ν_k, trapezoid in the Coriolis and
lever-arm products), R_imu = diag(σ_a, σ_a, σ_g)⁻² (``accel_std``, ``gyro_std``) and b_a the
accelerometer's bias (turn-on ±0.002 g: 0.02 m/s², which would tilt the velocities across the
window by 0.02 m/s), a slow variable like b with the prior b̄_a = its last estimate,
P_a = ``accel_bias_std``⁻² per sample; the gyro's bias (±0.04 °/s) stays inside σ_g. Linearised
about q̄ like the rest, each term touches δq_k, δq_{k+1} and δb_a only. With the IMU the
unmodelled force d_k can be as large as the waves' (``disturbance_std`` of river_tracking:
30 N, 30 N, 10 N m): the accelerometer, not the prior on d_k, now says what it was.

**Arrival cost** (eq. 17, PL fixed): when a sample leaves the full window, the next prior q̄ is
this solution's q̂_1, the estimate of the sample that becomes the first (:meth:`step`).

**Angles.** The ψ measurements are unwrapped along the window (|Δψ| < π between samples up to
31 rad/s at 10 Hz) and shifted by 2π n onto the guess's branch, itself put on the prior's. ψ̂
is therefore continuous, like the plant's ψ, and equals the sensor's heading mod 2π.

**Horizon.** M = 20 samples (TE = 2 s at 10 Hz). Neither u nor v is measured: they are seen
through the slope of the positions, whose least-squares slope over M samples of σ = 0.022 m
has σ / (dt √(M(M²−1)/12)) = 0.024, 0.013, 0.0087, 0.0047 m/s for M = 10, 15, 20, 30, and PL
(σ_u = 0.32 m/s) carries almost nothing across windows. Measured (tests' trajectory, 570
samples): u/v RMSE 0.022/0.014 (M = 10), 0.011/0.006 (15), 0.0067/0.0042 (20), 0.0058/0.0043
(30) m/s at 1.1, 1.4, 1.55, 2.5 ms median. M = 10 misses 0.02 m/s; beyond 20 the gain is small
(the model, not the window, limits it) and the time grows: M = 20.
"""

import time

import numpy as np
import scipy.sparse as sp

from usvdrake.systems.estimation.nmhe_model import (
    POSE_INDEX,
    NmheConfig,  # noqa: F401  (re-exported: usvdrake.scenario imports it from here)
    NmheSolution,
    NmheWindow,
    _thrust_model,
)
from usvdrake.systems.estimation.nmhe_qp import NmheQp
from usvdrake.systems.vessel.vessel_discrete import rk4, rk4_with_jacobians


class NmheProblem(NmheQp):
    """Reusable NMHE QP for one vessel (see the module docstring for the formulation).

    The ``MathematicalProgram`` is a workspace: :meth:`solve` overwrites every coefficient from
    its arguments, so results depend on the arguments only (not on earlier calls); one instance
    must not be used from two threads at once.
    """

    def thrust_to_tau(self, commands: np.ndarray) -> np.ndarray:
        """τ (N, 3) [N, N, N m] of thruster commands (N, n_u)."""
        return _thrust_model(self.thrusters, np.atleast_2d(np.asarray(commands, float)))[0]

    def predict(
        self, q: np.ndarray, command: np.ndarray, h: float, bias: np.ndarray | None = None
    ) -> np.ndarray:
        """q (6,) propagated h [s] with ``command`` held and the slow force ``bias`` [N, N, N m]
        added (RK4 of eq. 7, still water); a NaN command counts as zero thrust."""
        tau = self.thrust_to_tau(np.nan_to_num(np.asarray(command, float)))
        if bias is not None:
            tau = tau + np.asarray(bias, float)
        return rk4(self.xi, np.asarray(q, float).reshape(1, 6), tau, h)[0]

    def empty_window(self) -> NmheWindow:
        """The window before the first sample."""
        return NmheWindow(
            z=np.full((self.M, 4), np.nan),
            u=np.full((self.M, self.n_u), np.nan),
            trajectory=np.zeros((self.M, 6)),
            prior=np.zeros(6),
            bias=np.zeros(3),
            count=0,
            imu=np.full((self.M, 3), np.nan),
            accel_bias=np.zeros(2),
        )

    def step(
        self,
        window: NmheWindow,
        z_new: np.ndarray,
        u_new: np.ndarray,
        initial_state: np.ndarray | None = None,
        imu_new: np.ndarray | None = None,
    ) -> tuple[NmheWindow, NmheSolution]:
        """Push one sample — pose [x y ψ r] [m, m, rad, rad/s] and thrust reading [N, rad] (see
        ``thrust_delay_samples``) — into the window and solve; ``window`` is not modified.
        ``imu_new``: the IMU's mean [f_x f_y ω_z] [m/s², m/s², rad/s] over the interval that
        ends at this pose sample (``ImuIntervalMean``), None or NaN when there is none.

        Arrival cost (eq. 17, PL fixed): when a sample leaves the full window, the prior for the
        new first sample is the last solution's estimate of that sample (its q̂_1); while the
        window fills nothing leaves, so the prior stays the first one: ``initial_state`` if
        given, else the first pose with zero velocities [x y ψ 0 0 r]. The slow force's prior
        is its last estimate. The guess is the last solution shifted by one sample, its newest
        state propagated with the thrust over the newest interval; on a failed QP the window
        keeps that guess as its trajectory."""
        M = self.M
        z_new = np.array(z_new, float).reshape(4)
        u_new = np.array(u_new, float).reshape(self.n_u)
        z = np.roll(window.z, -1, axis=0)
        u = np.roll(window.u, -1, axis=0)
        u[M - 1] = u_new
        if self.cfg.thrust_delay_samples == 1:
            u[M - 2] = u_new
        imu = np.roll(window.imu, -1, axis=0)
        imu[M - 1] = np.nan
        imu[M - 2] = np.nan if imu_new is None else np.array(imu_new, float).reshape(3)
        accel_bias = window.accel_bias
        if window.count == 0 and not np.isfinite(z_new).any():
            return window, self._no_solution(window.trajectory, np.nan_to_num(u[: M - 1]))
        if window.count == 0:
            if initial_state is not None:
                prior = np.array(initial_state, float).reshape(6)
            else:
                prior = np.nan_to_num(np.array([z_new[0], z_new[1], z_new[2], 0, 0, z_new[3]]))
            guess = None
        else:
            prior = window.trajectory[1].copy() if window.count >= M else window.prior.copy()
            newest = self.predict(window.trajectory[-1], u[M - 2], self.dt, window.bias)
            guess = np.vstack([window.trajectory[1:], newest])
            # Unwrap the new heading onto the guess's branch (the guess is within π of it).
            z_new[2] = newest[2] + (z_new[2] - newest[2] + np.pi) % (2.0 * np.pi) - np.pi
        z[M - 1] = z_new
        count = min(window.count + 1, M)
        if not np.isfinite(z).any():  # every pose in the window lost: coast on the model
            sol = self._no_solution(guess, np.nan_to_num(u[: M - 1]), window.bias, accel_bias)
            return NmheWindow(z, u, guess, prior, window.bias, count, imu, accel_bias), sol
        # b and b_a are learnt only from full windows: while the window fills, the velocities
        # are still poorly known and would be absorbed as a force (and forgotten slowly).
        sol = self.solve(
            z,
            u,
            prior,
            guess,
            window.bias,
            fix_bias=count < M,
            arrival_index=M - count,
            imu_window=imu,
            accel_bias_prior=accel_bias,
        )
        window = NmheWindow(z, u, sol.trajectory, prior, sol.bias, count, imu, sol.accel_bias)
        return window, sol

    def _no_solution(
        self,
        trajectory: np.ndarray,
        cmd: np.ndarray,
        bias: np.ndarray | None = None,
        accel_bias: np.ndarray | None = None,
    ) -> NmheSolution:
        return NmheSolution(
            estimate=trajectory[-1].copy(),
            trajectory=trajectory.copy(),
            thrust=cmd,
            disturbance=np.zeros((self.M - 1, 3)),
            bias=np.zeros(3) if bias is None else bias.copy(),
            accel_bias=np.zeros(2) if accel_bias is None else accel_bias.copy(),
            success=False,
            status="NoMeasurement",
            cost=float("nan"),
            solve_ms=0.0,
            arrival_index=self.M,
        )

    def solve(
        self,
        z_window: np.ndarray,
        u_window: np.ndarray,
        prior: np.ndarray,
        guess: np.ndarray | None = None,
        bias_prior: np.ndarray | None = None,
        fix_bias: bool = False,
        arrival_index: int | None = None,
        imu_window: np.ndarray | None = None,
        accel_bias_prior: np.ndarray | None = None,
    ) -> NmheSolution:
        """One NMHE step (eqs. 15-17): the QP linearised about ``guess``, solved once.

        z_window: (M, 4) pose samples [x y ψ r] [m, m, rad, rad/s], oldest first; NaN = missing
            (a partly filled window has NaN rows first).
        u_window: (M − 1, n_u) or (M, n_u) measured thruster commands [N, rad], row k applied
            over [t_k, t_{k+1}) (a row M − 1 is ignored); NaN entries = missing.
        prior: q̄ (6,), the arrival-cost prior at the first sample that holds a measurement.
        guess: (M, 6) linearisation trajectory (the previous solution shifted); default: the
            prior rolled out with the measured thrust.
        bias_prior: b̄ (3,) [N, N, N m], the slow force's prior; default zero.
        fix_bias: hold b (and b_a) at their priors instead of estimating them.
        arrival_index: the sample p the prior belongs to; default: the first holding a pose.
        imu_window: (M − 1, 3) or (M, 3) IMU interval means [f_x f_y ω_z] [m/s², m/s², rad/s],
            row k over [t_k, t_{k+1}) (a row M − 1 is ignored); NaN entries = missing; None: no
            IMU.
        accel_bias_prior: b̄_a (2,) [m/s²], the accelerometer bias's prior; default zero.
        """
        t_start = time.perf_counter()
        M, n_u, n = self.M, self.n_u, self._n
        z = np.array(z_window, float)
        if z.shape != (M, 4):
            raise ValueError(f"NmheProblem.solve: z_window must be ({M}, 4), got {z.shape}")
        u = np.array(u_window, float)
        if u.ndim != 2 or u.shape[1] != n_u or u.shape[0] not in (M - 1, M):
            raise ValueError(f"NmheProblem.solve: u_window must be ({M}, {n_u}), got {u.shape}")
        u = u[: M - 1]
        prior = np.array(prior, float).reshape(6)
        b_bar = np.zeros(3) if bias_prior is None else np.array(bias_prior, float).reshape(3)
        b_bar = np.where(self._bias_on, b_bar, 0.0)
        ba_bar = np.zeros(2) if accel_bias_prior is None else np.array(accel_bias_prior, float)
        ba_bar = ba_bar.reshape(2) if self._accel_bias_on else np.zeros(2)
        if not all(np.all(np.isfinite(v)) for v in (prior, b_bar, ba_bar)):
            raise ValueError(
                f"NmheProblem.solve: priors must be finite, got {prior}, {b_bar}, {ba_bar}"
            )
        if imu_window is None:
            imu = np.full((M - 1, 3), np.nan)
        else:
            imu = np.array(imu_window, float)
            if imu.ndim != 2 or imu.shape[1] != 3 or imu.shape[0] not in (M - 1, M):
                raise ValueError(f"NmheProblem.solve: imu_window must be ({M}, 3), got {imu.shape}")
            imu = imu[: M - 1]

        # Measurement weights; missing entries weigh nothing.
        have = np.isfinite(z)
        if not have.any():
            raise ValueError("NmheProblem.solve: the window holds no measurement")
        w = np.where(have, self._w_z, 0.0)
        z = np.where(have, z, 0.0)
        p = int(np.argmax(have.any(axis=1))) if arrival_index is None else int(arrival_index)
        if not 0 <= p < M:
            raise ValueError(f"NmheProblem.solve: arrival_index must be in [0, {M}), got {p}")

        # Thrust: τ̃_k, J_k and the force-error covariance S_k = J R_u⁻¹ Jᵀ + Q_d⁻¹.
        u_ok = np.isfinite(u)
        cmd = np.where(u_ok, u, 0.0)
        var = np.where(u_ok, self._cmd_var, self._cmd_var_missing)
        tau, jac = _thrust_model(self.thrusters, cmd)
        s_inv = np.linalg.inv(np.einsum("kij,kj,klj->kil", jac, var, jac) + self._q_d)

        # Linearisation trajectory q̄ and the model about it, with τ = τ̃_k + b̄.
        tau_lin = tau + b_bar
        if guess is None:
            q_bar = np.empty((M, 6))
            q_bar[: p + 1] = prior
            for k in range(p, M - 1):
                q_bar[k + 1] = rk4(self.xi, q_bar[k : k + 1], tau_lin[k : k + 1], self.dt)[0]
        else:
            q_bar = np.array(guess, float)
            if q_bar.shape != (M, 6) or not np.all(np.isfinite(q_bar)):
                raise ValueError(f"NmheProblem.solve: guess must be finite ({M}, 6)")
            q_bar[:, 2] += 2.0 * np.pi * np.round((prior[2] - q_bar[p, 2]) / (2.0 * np.pi))
        f_bar, a, b = rk4_with_jacobians(self.xi, q_bar[:-1], tau_lin, self.dt)

        # ψ: unwrap along the window, then onto the guess's 2π branch (itself on the prior's).
        has_psi = have[:, 2]
        if has_psi.any():
            i0 = int(np.argmax(has_psi))
            psi = np.unwrap(z[has_psi, 2])
            psi += 2.0 * np.pi * np.round((q_bar[i0, 2] - psi[0]) / (2.0 * np.pi))
            z[has_psi, 2] = psi

        # Cost ½ xᵀ H x + gᵀ x + c: the objective with the dynamics linearised.
        hess = np.zeros((n, n))
        grad = np.zeros(n)
        rho = z - q_bar[:, POSE_INDEX]  # pose residuals at the guess
        idx = (6 * np.arange(M)[:, None] + np.array(POSE_INDEX)).ravel()
        hess[idx, idx] = 2.0 * w.ravel()
        grad[idx] = -2.0 * (w * rho).ravel()
        dp = q_bar[p] - prior
        blk = slice(6 * p, 6 * p + 6)
        hess[blk, blk] += 2.0 * self._p_l
        grad[blk] += 2.0 * self._p_l @ dp
        for k in range(M - 1):
            e = slice(self._i_e + 3 * k, self._i_e + 3 * k + 3)
            hess[e, e] = 2.0 * s_inv[k]
        hess[self._i_b : self._i_ba, self._i_b : self._i_ba] = 2.0 * self._p_b
        const = float(np.sum(w * rho * rho) + dp @ self._p_l @ dp)
        const += self._add_imu_terms(hess, grad, imu, q_bar, ba_bar)
        free = self._bias_on & (not fix_bias)
        free_a = self._accel_bias_on and not fix_bias and bool(np.isfinite(imu[:, :2]).any())
        c_dyn = f_bar - q_bar[1:]  # δq_{k+1} − A_k δq_k − B_k (e_k + δb) = c_k

        x = None
        if self.cfg.solver == "condensed":
            x = self._solve_condensed(hess, grad, a, b, c_dyn, q_bar, free, free_a)
        if x is not None:
            status = "condensed"
            cost = float(0.5 * x @ hess @ x + grad @ x + const)
        else:
            result = self._solve_program(hess, grad, const, b, a, c_dyn, q_bar, free, free_a)
            status = str(result.get_solution_result())
            if not result.is_success():
                return NmheSolution(
                    estimate=q_bar[-1].copy(),
                    trajectory=q_bar,
                    thrust=cmd,
                    disturbance=np.zeros((M - 1, 3)),
                    bias=b_bar,
                    accel_bias=ba_bar,
                    success=False,
                    status=status,
                    cost=float("nan"),
                    solve_ms=1e3 * (time.perf_counter() - t_start),
                    arrival_index=p,
                )
            x = result.GetSolution(self._x)
            cost = float(result.get_optimal_cost())
        q_hat = q_bar + x[: 6 * M].reshape(M, 6)
        se = np.einsum("kij,kj->ki", s_inv, x[self._i_e : self._i_b].reshape(M - 1, 3))
        return NmheSolution(
            estimate=q_hat[-1].copy(),
            trajectory=q_hat,
            thrust=cmd + var * np.einsum("kji,kj->ki", jac, se),
            disturbance=se @ self._q_d.T,
            bias=b_bar + np.where(free, x[self._i_b : self._i_ba], 0.0),
            accel_bias=ba_bar + (x[self._i_ba :] if free_a else 0.0),
            success=True,
            status=status,
            cost=cost,
            solve_ms=1e3 * (time.perf_counter() - t_start),
            arrival_index=p,
        )

    def _solve_program(self, hess, grad, const, b, a, c_dyn, q_bar, free, free_a):
        """Refill the ``MathematicalProgram`` (cost, dynamics, bounds) and solve it."""
        M, n = self.M, self._n
        b_flat = -b.reshape(M - 1, 18)
        data = np.concatenate([np.ones((M - 1, 6)), -a.reshape(M - 1, 36), b_flat, b_flat], axis=1)
        a_eq = sp.csc_matrix((data.ravel(), (self._rows, self._cols)), shape=(6 * (M - 1), n))
        self._dyn.evaluator().UpdateCoefficients(a_eq, c_dyn.ravel())
        self._cost.evaluator().UpdateCoefficients(hess, grad, const, True)
        # Bounds (15c) on (u, v, r), in deviations from the guess; δb = 0 where b is held.
        self._box.evaluator().set_bounds(
            (self._v_lo - q_bar[:, 3:]).ravel(), (self._v_hi - q_bar[:, 3:]).ravel()
        )
        self._bias_box.evaluator().set_bounds(
            np.where(free, -np.inf, 0.0), np.where(free, np.inf, 0.0)
        )
        lim = np.inf if free_a else 0.0
        self._accel_bias_box.evaluator().set_bounds(np.full(2, -lim), np.full(2, lim))
        return self._solver.Solve(self._prog)
