"""Configuration, records and measurement models of the NMHE (numerical core of ``Nmhe``):
``NmheConfig`` holds the estimator's settings (rate, horizon M, the weights RT and PL of Roboat II
eqs. (16)-(17), the process-noise, slow-force and IMU terms, bounds and solver), ``NmheSolution``
and ``NmheWindow`` are what one step returns and what is kept between samples, and the two
measurement models the QP is linearised with are the thrust map τ(u) with its Jacobian
(``_thrust_model``, the batched ``thrusters.mix``) and the IMU interval mean h(q_k, q_{k+1})
(:func:`imu_interval_model`). The formulation is in ``nmhe_problem``'s docstring, which "the
module docstring" in the comments below refers to.
"""

from dataclasses import dataclass, field

import numpy as np

from usvdrake.vessel import Thruster

POSE_INDEX = [0, 1, 2, 5]  # C of h(q): z = [x y ψ r] picks these entries of q = [x y ψ u v r]

# What no pose or thrust sensor of a surface vessel reports: positions beyond 1000 km of the
# world's origin, turn rates above 20 rad/s, forces above 1 MN (a corrupt or unit-confused reading)
MAX_POSITION_M = 1.0e6
MAX_TURN_RATE = 20.0
MAX_THRUST = 1.0e6


def screen_sample(
    z: np.ndarray, u: np.ndarray, u_last: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """(z, u, skipped): a pose sample z = [x y ψ r] and thrust reading u made safe for the
    window. A pose value that is non-finite or beyond what a sensor reports becomes NaN (a
    missing value, which the window bridges; an impossible position drops the whole pose); a
    thrust reading with such a value is replaced by the last one. ``skipped``: something was."""
    z = np.array(z, float).reshape(4)
    u = np.array(u, float).reshape(-1)
    bad = ~np.isfinite(z)
    with np.errstate(invalid="ignore"):
        if abs(z[0]) > MAX_POSITION_M or abs(z[1]) > MAX_POSITION_M:
            bad[:] = True
        if abs(z[3]) > MAX_TURN_RATE:
            bad[3] = True
        thrust_bad = not np.all(np.isfinite(u)) or np.any(np.abs(u) > MAX_THRUST)
    z[bad] = np.nan
    if thrust_bad:
        u = np.array(u_last, float).reshape(-1)
    return z, u, bool(bad.any() or thrust_bad)


@dataclass
class NmheConfig:
    rate_hz: float = 10.0  # [Hz] sample and update rate, dt = 1 / rate (Roboat II §VI: 10 Hz)
    horizon: int = 20  # [samples] window length M (M / rate = 2 s; see the module docstring)
    # [m², m², rad², (rad/s)²] variances of z = [x y ψ r]: RT⁻¹ of Roboat II eq. (16), first four
    pose_variance: list[float] = field(default_factory=lambda: [0.0005, 0.0005, 0.0005, 0.0001])
    thrust_variance: float = 1.0  # [N²] variance of each measured force: RT⁻¹ of eq. (16), f1..f4
    angle_variance: float = 0.0175**2  # [rad²] azimuth-angle reading (not in Roboat II: 1° encoder)
    # [m², m², rad², (m/s)², (m/s)², (rad/s)²] PL⁻¹ of Roboat II eq. (17), fixed
    arrival_variance: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0, 0.1, 0.1, 1.0])
    # [N, N, N m] 1σ of the white unmodelled body force d_k per sample (w_k of eq. 15b; ours)
    disturbance_std: list[float] = field(default_factory=lambda: [2.0, 2.0, 0.5])
    # [N, N, N m] 1σ of the slow force b's prior (last estimate) per sample; 0 = no b (ours)
    bias_std: list[float] = field(default_factory=lambda: [0.5, 0.5, 0.1])
    # [m/s, m/s, rad/s] bounds on (u, v, r), eq. (15c)
    velocity_min: list[float] = field(default_factory=lambda: [-3.0, -2.0, -2.0])
    velocity_max: list[float] = field(default_factory=lambda: [3.0, 2.0, 2.0])
    # 1: the thrust sample taken at t_k is the force held over [t_{k−1}, t_k) (the sensor and a
    # 10 Hz controller update at the same instants); 0: it is the force over [t_k, t_{k+1})
    thrust_delay_samples: int = 1
    # "condensed" (exact when no velocity bound is active, else Clarabel), "clarabel" or "osqp"
    solver: str = "condensed"
    # [s] ``Nmhe`` updates this long after the instants k·dt at which its sensors sample (its
    # compute slot, after the sensors' and before the controller's), so it reads the samples
    # just taken; 0: at the same instants, when it reads the samples of the instant before
    update_offset: float = 0.001
    # [s] ``Nmhe`` holds the newest sample's estimate propagated this far: to the instant its
    # consumer reads it (the NMPC's ``update_offset``; 2 dt with update_offset 0)
    output_lead: float = 0.002
    # IMU terms (used when an IMU feeds the window; see "IMU" in the module docstring)
    accel_std: float = 0.01  # [m/s²] 1σ of an interval's mean level-frame specific force (x, y)
    gyro_std: float = 0.002  # [rad/s] 1σ of an interval's mean yaw rate (noise + turn-on bias)
    # [m/s²] 1σ of the accelerometer bias prior (last estimate) per sample; 0 = bias not learnt
    accel_bias_std: float = 0.002
    # [m] the IMU at (x fwd, y left) of the body origin (the autonomy copies sensors.imu's)
    imu_lever_arm: list[float] = field(default_factory=lambda: [0.0, 0.0])


@dataclass
class NmheSolution:
    """One NMHE step; rows are samples (oldest first), ψ unwrapped."""

    estimate: np.ndarray  # q̂ at the newest sample t_{M−1} [m, m, rad, m/s, m/s, rad/s]
    trajectory: np.ndarray  # q̂_0 … q̂_{M−1} (M, 6)
    thrust: np.ndarray  # û_k (M−1, n_u) estimated thruster commands [N, rad]
    disturbance: np.ndarray  # d̂_k (M−1, 3) estimated white unmodelled force [N, N, N m]
    bias: np.ndarray  # b̂ (3,) estimated slow unmodelled force [N, N, N m]
    accel_bias: np.ndarray  # b̂_a (2,) estimated accelerometer bias [m/s²] (zero without IMU)
    success: bool  # the QP solved; if not, estimate/trajectory are the guess
    status: str  # the solver's result
    cost: float  # value of the linearised objective (15a + the d_k and b terms) [-]
    solve_ms: float  # wall time of the whole call (linearise, fill, solve) [ms]
    arrival_index: int  # p: the sample the arrival cost applies to


@dataclass
class NmheWindow:
    """What the estimator remembers between samples (the ``Nmhe`` keeps it in the Context)."""

    z: np.ndarray  # (M, 4) pose samples [x y ψ r], ψ unwrapped; NaN = missing / not yet received
    u: np.ndarray  # (M, n_u) thruster commands, row k applied over [t_k, t_{k+1}); NaN = missing
    trajectory: np.ndarray  # (M, 6) the last solution q̂ (or its propagated guess on failure)
    prior: np.ndarray  # (6,) arrival-cost prior q̄ at the window's first valid sample
    bias: np.ndarray  # (3,) the last estimate of the slow force b [N, N, N m]
    count: int  # samples received, capped at M
    imu: np.ndarray  # (M, 3) IMU means [f_x f_y ω_z], row k over [t_k, t_{k+1}); NaN = missing
    accel_bias: np.ndarray  # (2,) the last accelerometer-bias estimate [m/s²]


def _thrust_model(thrusters: list[Thruster], cmd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """τ (N, 3) [N, N, N m] and J = ∂τ/∂cmd (N, 3, n_u) for a batch of commands (N, n_u), the
    batched form of ``thrusters.mix``."""
    n = len(cmd)
    tau = np.zeros((n, 3))
    jac = np.zeros((n, 3, cmd.shape[1]))
    k = 0
    for t in thrusters:
        f = cmd[:, k]
        a = cmd[:, k + 1] if t.azimuth else np.full(n, np.deg2rad(t.angle_deg))
        c, s = np.cos(a), np.sin(a)
        col = np.stack([c, s, t.x * s - t.y * c], axis=1)
        tau += f[:, None] * col
        jac[:, :, k] = col
        if t.azimuth:
            jac[:, :, k + 1] = f[:, None] * np.stack([-s, c, t.x * c + t.y * s], axis=1)
        k += 2 if t.azimuth else 1
    return tau, jac


def imu_interval_model(
    q0: np.ndarray, q1: np.ndarray, dt: float, lever_arm=(0.0, 0.0)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What an IMU at ``lever_arm`` (l_x, l_y) [m] reads on average over intervals of length dt
    that start at states q0 (N, 6) and end at q1 (N, 6): h (N, 3) = [f̄_x, f̄_y, ω̄_z] [m/s², m/s²,
    rad/s] and the Jacobians ∂h/∂q0, ∂h/∂q1 (N, 3, 6).

    The level-frame specific force of ``imu_model`` integrated over the interval: ∫ ν̇ dt is
    exactly ν1 − ν0, and the products (r v, r u, r²) are averaged by the trapezoid rule, so

        f̄_x = (u1 − u0)/dt − ½(r0 v0 + r1 v1) − l_y (r1 − r0)/dt − l_x ½(r0² + r1²)
        f̄_y = (v1 − v0)/dt + ½(r0 u0 + r1 u1) + l_x (r1 − r0)/dt − l_y ½(r0² + r1²)
        ω̄_z = ½(r0 + r1)

    (trapezoid error (ω dt)²/12 of a component at angular frequency ω: 1.3 % for 0.6 Hz waves
    at dt = 0.1 s)."""
    lx, ly = float(lever_arm[0]), float(lever_arm[1])
    q0, q1 = np.atleast_2d(q0), np.atleast_2d(q1)
    u0, v0, r0 = q0[:, 3], q0[:, 4], q0[:, 5]
    u1, v1, r1 = q1[:, 3], q1[:, 4], q1[:, 5]
    h = np.stack(
        [
            (u1 - u0) / dt
            - 0.5 * (r0 * v0 + r1 * v1)
            - ly * (r1 - r0) / dt
            - lx * 0.5 * (r0 * r0 + r1 * r1),
            (v1 - v0) / dt
            + 0.5 * (r0 * u0 + r1 * u1)
            + lx * (r1 - r0) / dt
            - ly * 0.5 * (r0 * r0 + r1 * r1),
            0.5 * (r0 + r1),
        ],
        axis=1,
    )
    jac = []
    for sign, u, v, r in ((-1.0, u0, v0, r0), (1.0, u1, v1, r1)):
        j = np.zeros((len(u), 3, 6))
        j[:, 0, 3] = sign / dt
        j[:, 0, 4] = -0.5 * r
        j[:, 0, 5] = -0.5 * v - sign * ly / dt - lx * r
        j[:, 1, 3] = 0.5 * r
        j[:, 1, 4] = sign / dt
        j[:, 1, 5] = 0.5 * u + sign * lx / dt - ly * r
        j[:, 2, 5] = 0.5
        jac.append(j)
    return h, jac[0], jac[1]
