"""The NMHE's QP workspace, the ``MathematicalProgram`` that ``NmheProblem`` (``nmhe_problem``,
where the formulation is described) refills and solves each sample: ``NmheQp`` checks an
``NmheConfig``, turns its variances into the weights of the cost (R_z, the thrust variances, PL,
Q_d, P_b, R_imu, P_a), lays out the decision vector x = [δq_0 … δq_{M−1}, e_0 … e_{M−2}, δb, δb_a]
and builds once the program's quadratic cost, the dynamics' equality constraint with its fixed
sparsity pattern, the velocity bounds (15c), the bias boxes and the solver (Clarabel or OSQP);
it also adds the linearised IMU terms to the cost, and solves the QP condensed when no velocity
bound is active (:meth:`NmheQp._solve_condensed`, the default). ``NmheProblem`` derives from it.
"""

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numba import njit
from pydrake.solvers import ClarabelSolver, MathematicalProgram, OsqpSolver

from usvdrake.systems.estimation.nmhe_model import NmheConfig, imu_interval_model
from usvdrake.systems.vessel.thrusters import command_size
from usvdrake.vessel import Hydrodynamics, Thruster


class NmheQp:
    """The NMHE QP's weights, variable layout and ``MathematicalProgram`` for one vessel (the
    workspace of :class:`~usvdrake.systems.estimation.nmhe_problem.NmheProblem`)."""

    def __init__(self, xi: Hydrodynamics, thrusters: list[Thruster], cfg: NmheConfig | None = None):
        cfg = NmheConfig() if cfg is None else cfg
        if cfg.horizon < 2:
            raise ValueError(f"NmheConfig.horizon must be >= 2 samples, got {cfg.horizon}")
        if cfg.rate_hz <= 0:
            raise ValueError(f"NmheConfig.rate_hz must be positive, got {cfg.rate_hz}")
        if not 0.0 <= cfg.update_offset < 1.0 / cfg.rate_hz:
            raise ValueError(
                f"NmheConfig.update_offset must be in [0, 1/rate_hz), got {cfg.update_offset}"
            )
        if not (np.isfinite(cfg.output_lead) and cfg.output_lead >= 0):
            raise ValueError(f"NmheConfig.output_lead must be >= 0, got {cfg.output_lead}")
        if cfg.thrust_delay_samples not in (0, 1):
            raise ValueError(
                f"NmheConfig.thrust_delay_samples must be 0 or 1, got {cfg.thrust_delay_samples}"
            )
        for name, n, zero_ok in (
            ("pose_variance", 4, False),
            ("arrival_variance", 6, False),
            ("disturbance_std", 3, False),
            ("bias_std", 3, True),
        ):
            v = np.asarray(getattr(cfg, name), float)
            ok = v.shape == (n,) and np.all(np.isfinite(v)) and np.all(v >= 0 if zero_ok else v > 0)
            if not ok:
                sign = ">= 0" if zero_ok else "> 0"
                raise ValueError(f"NmheConfig.{name} needs {n} finite numbers {sign}, got {v}")
        for name in ("accel_std", "gyro_std"):
            if not (np.isfinite(getattr(cfg, name)) and getattr(cfg, name) > 0):
                raise ValueError(f"NmheConfig.{name} must be > 0, got {getattr(cfg, name)}")
        if not (np.isfinite(cfg.accel_bias_std) and cfg.accel_bias_std >= 0):
            raise ValueError(f"NmheConfig.accel_bias_std must be >= 0, got {cfg.accel_bias_std}")
        if np.shape(cfg.imu_lever_arm) != (2,) or not np.all(np.isfinite(cfg.imu_lever_arm)):
            raise ValueError(f"NmheConfig.imu_lever_arm needs 2 numbers, got {cfg.imu_lever_arm}")
        lo, hi = np.asarray(cfg.velocity_min, float), np.asarray(cfg.velocity_max, float)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(lo < hi):
            raise ValueError(f"NmheConfig: need velocity_min < velocity_max (3 each), got {cfg}")
        self.xi, self.thrusters, self.cfg = xi, list(thrusters), cfg
        self.M = M = cfg.horizon
        self.dt = 1.0 / cfg.rate_hz
        self.n_u = command_size(self.thrusters)
        is_angle, max_force = [], []
        for t in self.thrusters:
            is_angle += [False, True] if t.azimuth else [False]
            max_force += [t.max_force] * (2 if t.azimuth else 1)
        is_angle = np.array(is_angle)
        self._cmd_var = np.where(is_angle, cfg.angle_variance, cfg.thrust_variance)
        # A missing thrust reading: zero command, uncertain by a full thruster's range.
        self._cmd_var_missing = np.where(is_angle, np.pi**2, np.square(max_force))
        self._w_z = 1.0 / np.asarray(cfg.pose_variance, float)
        self._p_l = np.diag(1.0 / np.asarray(cfg.arrival_variance, float))
        self._q_d = np.diag(np.square(np.asarray(cfg.disturbance_std, float)))
        bias_std = np.asarray(cfg.bias_std, float)
        self._bias_on = bias_std > 0  # a zero std pins that component of b at zero
        self._p_b = np.diag(
            [1.0 / sd**2 if on else 0.0 for sd, on in zip(bias_std, self._bias_on, strict=True)]
        )
        self._v_lo, self._v_hi = lo, hi
        self._w_imu = 1.0 / np.square([cfg.accel_std, cfg.accel_std, cfg.gyro_std])
        self._accel_bias_on = cfg.accel_bias_std > 0
        self._p_ba = 1.0 / cfg.accel_bias_std**2 if self._accel_bias_on else 0.0

        # x = [δq_0 … δq_{M−1} (6M), e_0 … e_{M−2} (3(M−1)), δb (3), δb_a (2)]
        self._i_e = 6 * M
        self._i_b = self._i_e + 3 * (M - 1)
        self._i_ba = self._i_b + 3
        self._n = n = self._i_ba + 2
        self._prog = MathematicalProgram()
        self._dq = self._prog.NewContinuousVariables(M, 6, "dq")
        self._e = self._prog.NewContinuousVariables(M - 1, 3, "e")
        self._db = self._prog.NewContinuousVariables(3, "db")
        self._dba = self._prog.NewContinuousVariables(2, "dba")
        self._x = x = np.concatenate([self._dq.ravel(), self._e.ravel(), self._db, self._dba])
        self._cost = self._prog.AddQuadraticCost(np.eye(n), np.zeros(n), x, is_convex=True)
        self._rows, self._cols = self._dynamics_pattern()
        a0 = sp.csc_matrix(
            (np.ones(len(self._rows)), (self._rows, self._cols)), shape=(6 * (M - 1), n)
        )
        self._dyn = self._prog.AddLinearEqualityConstraint(a0, np.zeros(6 * (M - 1)), x)
        self._box = self._prog.AddBoundingBoxConstraint(
            np.tile(self._v_lo, M), np.tile(self._v_hi, M), self._dq[:, 3:].ravel()
        )
        self._bias_box = self._prog.AddBoundingBoxConstraint(
            np.where(self._bias_on, -np.inf, 0.0), np.where(self._bias_on, np.inf, 0.0), self._db
        )
        self._accel_bias_box = self._prog.AddBoundingBoxConstraint(0.0, 0.0, self._dba)
        if cfg.solver == "osqp":
            self._solver = OsqpSolver()  # Drake's settings (polished) match Clarabel's answer
        elif cfg.solver in ("condensed", "clarabel"):
            # Clarabel is also the condensed solve's fallback when a velocity bound is active
            self._solver = ClarabelSolver()
        else:
            raise ValueError(
                f"NmheConfig.solver must be 'condensed', 'clarabel' or 'osqp', got {cfg.solver!r}"
            )

    def _dynamics_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) of the dynamics' nonzeros in the order :meth:`solve` fills them: per step
        k, [I on δq_{k+1}] (6), [−A_k on δq_k] (36), [−B_k on e_k] (18), [−B_k on δb] (18)."""
        rows, cols = [], []
        i6, i3 = np.arange(6), np.arange(3)
        for k in range(self.M - 1):
            r = 6 * k + i6
            rows += [r, np.repeat(r, 6), np.repeat(r, 3), np.repeat(r, 3)]
            cols += [
                6 * (k + 1) + i6,
                np.tile(6 * k + i6, 6),
                np.tile(self._i_e + 3 * k + i3, 6),
                np.tile(self._i_b + i3, 6),
            ]
        return np.concatenate(rows), np.concatenate(cols)

    def _add_imu_terms(
        self,
        hess: np.ndarray,
        grad: np.ndarray,
        imu: np.ndarray,
        q_bar: np.ndarray,
        ba_bar: np.ndarray,
    ) -> float:
        """Adds Σ_k ‖m_k − h(q_k, q_{k+1}) − [b_a; 0]‖²_{R_imu} + ‖b_a − b̄_a‖²_{P_a}, linearised
        about q̄ and b̄_a, to the cost ½ xᵀ H x + gᵀ x (in place) and returns its constant."""
        const = 0.0
        ib = slice(self._i_ba, self._i_ba + 2)
        hess[ib, ib] += 2.0 * self._p_ba * np.eye(2)  # prior ‖δb_a‖²_{P_a} (zero when off)
        have = np.isfinite(imu)
        if have.any():
            M = self.M
            h, j0, j1 = imu_interval_model(q_bar[:-1], q_bar[1:], self.dt, self.cfg.imu_lever_arm)
            w = np.where(have, self._w_imu, 0.0)  # (M − 1, 3)
            rho = np.where(have, imu, 0.0) - h
            rho[:, :2] -= ba_bar
            rho = np.where(have, rho, 0.0)
            # J_k = [∂h/∂q_k, ∂h/∂q_{k+1}] on δq_k, δq_{k+1} (contiguous, 12 wide) and the
            # identity on δb_a (rows f_x, f_y); the blocks of consecutive k overlap, so they are
            # accumulated with np.add.at
            jq = np.concatenate([j0, j1], axis=2)  # (M − 1, 3, 12)
            wjq = w[:, :, None] * jq
            iq = 6 * np.arange(M - 1)[:, None] + np.arange(12)  # (M − 1, 12)
            np.add.at(
                hess, (iq[:, :, None], iq[:, None, :]), 2.0 * np.einsum("kij,kil->kjl", jq, wjq)
            )
            np.add.at(grad, iq, -2.0 * np.einsum("kij,ki->kj", wjq, rho))
            qb = 2.0 * np.transpose(wjq[:, :2, :], (0, 2, 1))  # (M − 1, 12, 2): J_qᵀ W J_b
            for a in range(2):
                np.add.at(hess[:, self._i_ba + a], iq, qb[:, :, a])
                np.add.at(hess[self._i_ba + a, :], iq, qb[:, :, a])
            hess[ib, ib] += 2.0 * np.diag(w[:, :2].sum(axis=0))
            grad[ib] -= 2.0 * (w[:, :2] * rho[:, :2]).sum(axis=0)
            const += float(np.sum(w * rho * rho))
        return const

    def _solve_condensed(
        self,
        hess: np.ndarray,
        grad: np.ndarray,
        a: np.ndarray,
        b: np.ndarray,
        c: np.ndarray,
        q_bar: np.ndarray,
        free_b: np.ndarray,
        free_a: bool,
    ) -> np.ndarray | None:
        """The QP's minimiser x when no velocity bound (15c) is active, else None.

        The dynamics δq_{k+1} = A_k δq_k + B_k (e_k + δb) + c_k fix every δq_k from
        z = [δq_0, e, δb, δb_a] (condensing: x = T z + t), so without the bounds the QP is the
        unconstrained ½ zᵀ Tᵀ H T z + (Tᵀ (H t + g))ᵀ z, solved by one Cholesky factorisation of
        a (6 + 3(M − 1) + 5)-square matrix. A minimiser that satisfies the bounds minimises the
        bounded QP too (its KKT conditions hold with zero multipliers); one that does not goes
        to the interior-point solver. Held biases (δb or δb_a fixed at zero) are left out of z.
        """
        M, n, ie = self.M, self._n, self._i_e
        keep = np.concatenate(
            [np.ones(6 + 3 * (M - 1), bool), np.asarray(free_b, bool), np.full(2, free_a)]
        )
        t, t0 = _condensing(
            np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(b, dtype=float),
            np.ascontiguousarray(c, dtype=float), n, ie,
        )  # fmt: skip
        t = t[:, keep]
        ht = hess @ t
        try:
            z = -sla.cho_solve(sla.cho_factor(t.T @ ht), t.T @ (hess @ t0 + grad))
        except sla.LinAlgError:
            return None
        x = t @ z + t0
        vel = x[: 6 * M].reshape(M, 6)[:, 3:] + q_bar[:, 3:]
        if np.any(vel < self._v_lo) or np.any(vel > self._v_hi) or not np.all(np.isfinite(x)):
            return None
        return x


@njit(cache=True)
def _condensing(a, b, c, n, ie):
    """(T (n × nz), t (n,)) with x = T z + t: δq_0 = z[:6], δq_{k+1} = A_k δq_k + B_k (e_k + δb)
    + c_k, and e, δb, δb_a = z[6:] (nz = n − 6(M − 1)); a (M−1, 6, 6), b (M−1, 6, 3), c (M−1, 6)."""
    m1 = a.shape[0]
    nz = n - 6 * m1
    t = np.zeros((n, nz))
    t0 = np.zeros(n)
    for i in range(6):
        t[i, i] = 1.0
    for k in range(m1):
        r0, r1 = 6 * k, 6 * (k + 1)
        for i in range(6):
            for col in range(nz):
                acc = 0.0
                for j in range(6):
                    acc += a[k, i, j] * t[r0 + j, col]
                t[r1 + i, col] = acc
            acc = c[k, i]
            for j in range(6):
                acc += a[k, i, j] * t0[r0 + j]
            t0[r1 + i] = acc
            for j in range(3):
                t[r1 + i, 6 + 3 * k + j] += b[k, i, j]
                t[r1 + i, nz - 5 + j] += b[k, i, j]
    for i in range(nz - 6):
        t[ie + i, 6 + i] = 1.0
    return t, t0
