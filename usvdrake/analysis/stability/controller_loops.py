"""The project's controllers as linear loops (:class:`LinearLoop`, conventions in
:mod:`usvdrake.analysis.stability.loops`): the round vessel's DP PD about rest, alone and acting
on the passive observer's estimate (continuous, and lifted to the controller period with Drake's
update timing), the baseline heading/speed law about a straight run with and without
line-of-sight guidance with its poles in closed form, and the NMPC's receding-horizon LQ gain
with the offset-free disturbance filter.

Loops built here:

* round vessel, DP PD about rest (Fossen 2011 §12.2; ``pd_controller``): τ = −Kp Rᵀ η̃ − Kd ν
  linearised by AutoDiff of ``pd_tau``. At rest the DOFs decouple and the closed-loop poles are
  the roots of det(s² M + (D + Kd) s + Kp) = Π_i (m_i s² + (d_i + kd_i) s + kp_i).
* the same PD acting on the passive observer's estimate (Fossen 2011 §11.4.1; Fossen & Strand
  1999), observer fed with the exact pose and the commanded τ. Continuous: by the separation
  principle the poles are those of the PD loop and of the observer error dynamics
  (per DOF [η̃, b̃, ν̃]' = [[−K2, 0, 1], [−K3, −1/T, 0], [−K4/m, 1/m, −d/m]] [η̃, b̃, ν̃]).
  Sampled: lifted to the controller period with the observer's own rate (an integer multiple)
  and the Drake timing: all updates at t_k read pre-update values, so the PD reads the estimate
  predicted for t_k, and the observer at t_k integrates with the τ of the previous period.
* baseline heading/speed law (``heading_speed_law``, feedback-linearising PD) about the straight
  run, alone (x, y unregulated) and with line-of-sight guidance along the x axis (Fossen 2011
  §10.3.2, ψ_d = atan(−y/Δ); only x unregulated). Jacobians: AutoDiff of the law, central
  differences of ``los_reference``. By hand the inner loop has poles −(Xu/m11 + k_u),
  −(Yv/m22 + k_v) and the double root of s² + 2ζω s + ω²; with LOS the (y, ψ, r) part becomes
  s³ + 2ζω s² + ω² s + ω² u0/Δ (stable iff 2ζωΔ > u0).
* NMPC (``nmpc_problem``): about the straight run with constraints inactive, one RTI QP is the
  finite-horizon LQ problem on the RK4 Jacobians (A, B B_thr) with Wq, WN, Wu, so the applied
  input is u = u_ff + K0 e with K0 from the backward Riccati recursion (receding horizon). The
  offset-free disturbance filter d̂ (``disturbance_gain``) is part of the loop (it adds 6 states:
  d̂ and the previous prediction). The NMHE is not modelled (exact state).

States that feed back nowhere (along-track x, and y without LOS) are integrators of the loop
(s = 0, z = 1) that no law regulates; they are dropped before the ``stable`` flag is set and
listed as ``unregulated``.
"""

from __future__ import annotations

import numpy as np

from usvdrake.analysis.stability.linearisation import (
    STATES,
    autodiff_jacobian,
    central_jacobian,
    input_matrix,
    linearize_plant,
    zoh,
)
from usvdrake.analysis.stability.loops import LinearLoop
from usvdrake.scenario import ControlConfig
from usvdrake.systems.control.heading_speed_law import heading_speed_tau
from usvdrake.systems.control.nmpc_problem import NmpcConfig
from usvdrake.systems.control.pd_controller import (
    PdControllerConfig,
    mass_damping,
    pd_gains,
    pd_tau,
)
from usvdrake.systems.estimation.observer_dynamics import (
    PassiveObserverConfig,
    observer_derivatives,
    observer_step,
)
from usvdrake.systems.guidance.line_of_sight import los_reference
from usvdrake.systems.vessel.thrusters import configuration_matrix
from usvdrake.systems.vessel.vessel_discrete import rk4_with_jacobians
from usvdrake.systems.vessel.vessel_dynamics import straight_run_jacobian, trim_thrust
from usvdrake.vessel import Hydrodynamics, VesselParams


# --- round vessel: PD (+ observer) about rest ------------------------------------------------
def pd_feedback(xi: Hydrodynamics, kp: np.ndarray, kd: np.ndarray) -> np.ndarray:
    """H = ∂τ/∂[η, ν] (3×6) of ``pd_tau`` about rest with a constant set-point (AutoDiff)."""

    def law(x):
        return pd_tau(xi, kp, kd, x, np.zeros(9))

    return autodiff_jacobian(law, np.zeros(6))[1]


def pd_characteristic_roots(xi: Hydrodynamics, kp: np.ndarray, kd: np.ndarray) -> np.ndarray:
    """Roots of det(s² M + (D + Kd) s + Kp) = Π_i (m_i s² + (d_i + kd_i) s + kp_i) (diagonal)."""
    m, d = mass_damping(xi)
    for k in (kp, kd):
        if np.max(np.abs(k - np.diag(np.diag(k)))) > 0:
            raise ValueError("pd_characteristic_roots: diagonal gains expected")
    roots = [np.roots([m[i, i], d[i, i] + kd[i, i], kp[i, i]]) for i in range(3)]
    return np.concatenate(roots).astype(complex)


def pd_loop(xi: Hydrodynamics, cfg: PdControllerConfig) -> LinearLoop:
    """Continuous PD loop of the round vessel about rest (state [η, ν])."""
    kp, kd = pd_gains(xi, cfg)
    a = straight_run_jacobian(xi, 0.0)
    return LinearLoop("pd", a, input_matrix(xi), pd_feedback(xi, kp, kd), 0.0, list(STATES))


def observer_linearization(cfg: PassiveObserverConfig, xi: Hydrodynamics):
    """(A_o, B_y, B_τ) of the continuous observer about rest: x̂̇ = A_o x̂ + B_y y + B_τ τ."""
    n = cfg.state_size

    def f(v):
        return observer_derivatives(cfg, xi, v[:n], v[n : n + 3], v[n + 3 : n + 6])

    j = central_jacobian(f, np.zeros(n + 6))
    return j[:, :n], j[:, n : n + 3], j[:, n + 3 :]


def observer_error_matrix(cfg: PassiveObserverConfig, xi: Hydrodynamics) -> np.ndarray:
    """Observer error dynamics about rest by hand, state [η̃, b̃, ν̃] (the observer's order):
    η̃̇ = ν̃ − K2 η̃,  b̃̇ = −b̃/T − K3 η̃,  M ν̃̇ = −D ν̃ + b̃ − K4 η̃ (no wave filter)."""
    if cfg.wave_filter:
        raise ValueError("observer_error_matrix: only the calm-water observer (no wave filter)")
    m = np.array([xi.m11, xi.m22, xi.m33])
    d = np.array([xi.Xu, xi.Yv, xi.Nr])
    a = np.zeros((9, 9))
    eye = np.eye(3)
    a[0:3, 0:3], a[0:3, 6:9] = -np.diag(cfg.K2), eye
    a[3:6, 0:3], a[3:6, 3:6] = -np.diag(cfg.K3), -np.diag(1.0 / cfg.T)
    a[6:9, 0:3], a[6:9, 3:6], a[6:9, 6:9] = -np.diag(cfg.K4 / m), np.diag(1 / m), -np.diag(d / m)
    return a


def _pd_on_estimate(xi, kp, kd, cfg: PassiveObserverConfig) -> np.ndarray:
    """∂τ/∂x̂ (3 × n_obs) of the PD acting on the observer state (η̂, ν̂ and −Rᵀ b̂)."""
    n = cfg.state_size
    k = 6 if cfg.wave_filter else 0

    def law(x):
        return pd_tau(
            xi,
            kp,
            kd,
            np.concatenate([x[k : k + 3], x[k + 6 : k + 9]]),
            np.zeros(9),
            x[k + 3 : k + 6],
        )

    return autodiff_jacobian(law, np.zeros(n))[1]


def pd_observer_loop(
    xi: Hydrodynamics, pd_cfg: PdControllerConfig, obs_cfg: PassiveObserverConfig
) -> LinearLoop:
    """Continuous plant + observer (fed y = η and the commanded τ) + PD on the estimate."""
    kp, kd = pd_gains(xi, pd_cfg)
    ao, by, bt = observer_linearization(obs_cfg, xi)
    n = obs_cfg.state_size
    h = np.hstack([np.zeros((3, 6)), _pd_on_estimate(xi, kp, kd, obs_cfg)])
    f = np.zeros((6 + n, 6 + n))
    f[:6, :6] = straight_run_jacobian(xi, 0.0)
    f[6:, :3] = by
    f[6:, 6:] = ao
    f[6:, :] += bt @ h  # the observer sees the controller's own τ
    g = np.vstack([input_matrix(xi), np.zeros((n, 3))])
    names = list(STATES) + [f"obs{i}" for i in range(n)]
    return LinearLoop("pd_observer", f, g, h, 0.0, names)


def sampled_pd_observer_loop(
    xi: Hydrodynamics, pd_cfg: PdControllerConfig, obs_cfg: PassiveObserverConfig
) -> LinearLoop:
    """The PD (at ``pd_cfg.rate_hz``) + observer (at ``obs_cfg.rate_hz``, an integer multiple)
    loop lifted to the controller period, with Drake's simultaneous-update timing (module
    docstring). Lifted state [q (6), x̂ (n), τ_prev (3)]."""
    ratio = obs_cfg.rate_hz / pd_cfg.rate_hz
    n_sub = int(round(ratio))
    if n_sub < 1 or abs(ratio - n_sub) > 1e-9:
        raise ValueError(f"observer rate {obs_cfg.rate_hz} Hz is not a multiple of the PD's")
    kp, kd = pd_gains(xi, pd_cfg)
    n = obs_cfg.state_size
    h_obs = 1.0 / obs_cfg.rate_hz

    def step(v):
        return observer_step(obs_cfg, xi, v[:n], v[n : n + 3], v[n + 3 : n + 6], h_obs)

    j = central_jacobian(step, np.zeros(n + 6))
    phi_o, gam_y, gam_t = j[:, :n], j[:, n : n + 3], j[:, n + 3 :]
    phi_h, gam_h = zoh(straight_run_jacobian(xi, 0.0), input_matrix(xi), h_obs)
    ns = 6 + n + 3
    # Every quantity as a linear map of (s, u): rows = [∂/∂s | ∂/∂u].
    q = np.hstack([np.eye(ns)[:6], np.zeros((6, 3))])
    xh = np.hstack([np.eye(ns)[6 : 6 + n], np.zeros((n, 3))])
    tau_prev = np.hstack([np.eye(ns)[6 + n :], np.zeros((3, 3))])
    h = np.hstack([np.zeros((3, 6)), _pd_on_estimate(xi, kp, kd, obs_cfg), np.zeros((3, 3))])
    tau_k = np.hstack([h, np.zeros((3, 3))])
    u = np.hstack([np.zeros((3, ns)), np.eye(3)])
    for i in range(n_sub):
        tau_in = tau_prev if i == 0 else tau_k
        xh = phi_o @ xh + gam_y @ q[:3] + gam_t @ tau_in
        q = phi_h @ q + gam_h @ u
    lifted = np.vstack([q, xh, tau_k])
    names = (
        list(STATES) + [f"obs{i}" for i in range(n)] + ["tau_prev_X", "tau_prev_Y", "tau_prev_N"]
    )
    return LinearLoop("pd_observer", lifted[:, :ns], lifted[:, ns:], h, 1.0 / pd_cfg.rate_hz, names)


# --- baseline heading/speed law (+ LOS) about a straight run ---------------------------------
def baseline_feedback(
    xi: Hydrodynamics, gains: ControlConfig, surge_speed: float, los: bool
) -> np.ndarray:
    """H = ∂τ/∂q (3×6) of ``heading_speed_tau`` at the straight run along x (ψ_d = 0, u_d =
    u0), with ψ_d from ``los_reference`` on a path along the x axis when ``los``."""
    q0 = np.array([0.0, 0.0, 0.0, surge_speed, 0.0, 0.0])

    def law(v):
        return heading_speed_tau(xi, gains, v[:6], v[6], surge_speed)

    _, j = autodiff_jacobian(law, np.concatenate([q0, [0.0]]))
    h = j[:, :6].copy()
    if los:
        waypoints = np.array([[1e4, 0.0]])

        def heading(p):
            ref = los_reference(
                waypoints, 0, p, np.zeros(2), surge_speed, gains.lookahead, 1.0, 1.0
            )
            return [ref.heading]

        dpsi = central_jacobian(heading, np.zeros(2))  # (1, 2): ∂ψ_d/∂[x, y]
        h[:, 0:2] += j[:, 6:7] @ dpsi
    return h


def baseline_loop(
    vessel: VesselParams, gains: ControlConfig, surge_speed: float, los: bool
) -> LinearLoop:
    """Continuous baseline loop about the straight run (full state; see :meth:`reduced`)."""
    xi = vessel.hydrodynamics
    a, b = linearize_plant(vessel, surge_speed)
    name = "los_heading_speed" if los else "heading_speed"
    return LinearLoop(name, a, b, baseline_feedback(xi, gains, surge_speed, los), 0.0, list(STATES))


def baseline_closed_form(xi: Hydrodynamics, gains: ControlConfig, u0: float, los: bool):
    """The baseline loop's poles by hand (module docstring), regulated states only."""
    w, z = gains.heading_natural_frequency, gains.heading_damping
    surge = -(xi.Xu / xi.m11 + gains.surge_bandwidth)
    sway = -(xi.Yv / xi.m22 + gains.sway_bandwidth)
    if los:
        yaw = np.roots([1.0, 2 * z * w, w * w, w * w * u0 / gains.lookahead])
    else:
        yaw = np.roots([1.0, 2 * z * w, w * w])
    return np.concatenate([[surge, sway], yaw]).astype(complex)


# --- NMPC's LQ linearisation ------------------------------------------------------------------
def nmpc_feedback_gain(vessel: VesselParams, cfg: NmpcConfig, surge_speed: float):
    """(K0, A, B): the receding-horizon LQ gain (thruster forces per state error) of the NMPC's
    QP about the straight run, and the RK4 Jacobians (A 6×6, B 6×3 per τ) it uses."""
    xi = vessel.hydrodynamics
    q0 = np.array([[0.0, 0.0, 0.0, surge_speed, 0.0, 0.0]])
    _, a, bt = rk4_with_jacobians(xi, q0, trim_thrust(xi, surge_speed)[None], cfg.dt)
    a, bt = a[0], bt[0]
    b = bt @ configuration_matrix(vessel.thrusters)
    n = int(round(cfg.horizon / cfg.dt))
    wq, r = np.diag(cfg.Wq), np.diag(cfg.Wu)
    p = np.diag(np.asarray(cfg.WN, float))
    k = None
    for _ in range(n):
        k = -np.linalg.solve(r + b.T @ p @ b, b.T @ p @ a)
        p = wq + a.T @ p @ (a + b @ k)
        p = 0.5 * (p + p.T)
    return k, a, bt


def nmpc_loop(vessel: VesselParams, cfg: NmpcConfig, surge_speed: float) -> LinearLoop:
    """Sampled NMPC loop about the straight run (exact state), with the offset-free filter:
    lifted state [e (6), d̂_prev (3), ν_pred (3)] (``Nmpc._step``: d̂ is updated from the
    previous plan's predicted velocity before the solve; the applied τ = τ_ff − d̂ + B_thr K0 e)."""
    xi = vessel.hydrodynamics
    k0, a_rk, b_rk = nmpc_feedback_gain(vessel, cfg, surge_speed)
    bthr = configuration_matrix(vessel.thrusters)
    a, b = linearize_plant(vessel, surge_speed)
    phi, gam = zoh(a, b, cfg.dt)
    g = cfg.disturbance_gain
    mdt = np.diag([xi.m11, xi.m22, xi.m33]) / cfg.dt
    sv = np.eye(6)[3:]
    kt = bthr @ k0  # τ per state error
    # d̂_k = d̂_{k-1} + g M/dt (S_ν e_k − ν_pred): a linear map of the lifted state
    dk = np.hstack([g * mdt @ sv, np.eye(3), -g * mdt])
    h = np.hstack([kt, np.zeros((3, 6))]) - dk
    f = np.zeros((12, 12))
    f[:6, :6] = phi
    f[6:9] = dk
    f[9:12, :6] = sv @ (a_rk + b_rk @ kt)  # the plan's prediction: τ_k − τ_ff + d̂_k = B K0 e
    gg = np.vstack([gam, np.zeros((6, 3))])
    names = list(STATES) + ["d_X", "d_Y", "d_N", "pred_u", "pred_v", "pred_r"]
    return LinearLoop("nmpc_lq", f, gg, h, cfg.dt, names)
