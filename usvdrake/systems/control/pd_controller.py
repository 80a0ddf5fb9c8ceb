"""Nonlinear PD tracking controller of Ueland 2017's motion controller (Fossen 2011 §12.2 DP-style
PD).

With the reference model's [η_d, η̇_d, η̈_d] (world frame), the estimate [η̂, ν̂] and bias b̂
(world frame) of the passive observer:

    ν_d = Rᵀ(ψ̂) η̇_d,   ν̇_d = Rᵀ(ψ̂) η̈_d − r_d S ν_d,   S = [[0, −1, 0], [1, 0, 0], [0, 0, 0]]
    τ = M ν̇_d + D ν_d − Kp Rᵀ(ψ̂) (η̂ − η_d) − Kd (ν̂ − ν_d) − Rᵀ(ψ̂) b̂

(ν̇_d is the exact derivative of Rᵀ(ψ) η̇_d along the desired yaw rate r_d = ψ̇_d; the heading
error ψ̂ − ψ_d is wrapped to (−π, π]). Kp acts on the position error expressed in the body
frame, Kp Rᵀ(ψ̂) η̃ as in Fossen's DP PID (Fossen 2011 §12.2, our reading; the form Rᵀ Kp η̃ is
the same when Kp_x = Kp_y, as for the round hull), so that Kp pairs with the body-frame M and D
below at any heading. The first two terms are the model feed-forward of
M ν̇ + D ν = τ (Roboat II eq. 2 without Coriolis, negligible at Ueland 2017's 0–0.3 m/s and zero for
the round hull's m11 = m22 when r = 0); the last cancels the estimated environmental force.

Gains from a closed-loop natural frequency ω_n and damping ζ per DOF:

    Kp = M ω_n²,   Kd = max(2 ζ ω_n M − D, 0)

so that near rest, on the nominal model, the body-frame error e = Rᵀ(ψ) η̃ obeys
M ë + (D + Kd) ė + Kp e = 0, i.e. ë + 2ζω_n ė + ω_n² e = 0 per DOF unless the clip acted
(then the damping is the hull's own, larger than asked). Defaults for ntnu_round (our choice): ω_n =
0.5 rad/s in surge/sway (above the reference model's ω = 0.3 rad/s, below the observer's
≈ 0.9 rad/s error poles; Kp = 2 N/m, Kd = 1.2 kg/s on top of Xu = 6 kg/s — at ω_n = 0.4 the
hull's own drag would already exceed 2ζω_n M and Kd would clip to 0), 1.5 rad/s in yaw (Ueland 2017:
"very low damping in yaw"; with m33 = 0.12 kg m² a stiff heading hold costs little moment:
Kp_ψ = 0.27 N m/rad, Kd_ψ ≈ 0.29 N m s/rad versus Nr = 0.03, against the ~1 N m the
thrusters give), ζ = 0.9 throughout; 10 Hz update rate (ω_n h ≤ 0.15).
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.angles import wrap_angle
from usvdrake.systems.vessel.vessel_dynamics import rotation
from usvdrake.vessel import Hydrodynamics

_S = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])


@dataclass
class PdControllerConfig:
    """Closed-loop natural frequency and damping per DOF [surge/x, sway/y, yaw] and the rate."""

    omega_n: list[float] = field(default_factory=lambda: [0.5, 0.5, 1.5])  # [rad/s]
    zeta: list[float] = field(default_factory=lambda: [0.9, 0.9, 0.9])
    rate_hz: float = 10.0  # [Hz] update rate; τ is held in between

    def __post_init__(self):
        w, z = np.asarray(self.omega_n, float), np.asarray(self.zeta, float)
        if w.shape != (3,) or z.shape != (3,) or not (np.all(w > 0) and np.all(z > 0)):
            raise ValueError(f"PdControllerConfig: 3 positive ω_n and ζ needed, got {w}, {z}")
        if not self.rate_hz > 0:
            raise ValueError("PdControllerConfig: rate_hz must be positive")


def mass_damping(xi: Hydrodynamics) -> tuple[np.ndarray, np.ndarray]:
    """M = diag(m11, m22, m33), D = diag(Xu, Yv, Nr)."""
    return np.diag([xi.m11, xi.m22, xi.m33]), np.diag([xi.Xu, xi.Yv, xi.Nr])


def pd_gains(xi: Hydrodynamics, cfg: PdControllerConfig) -> tuple[np.ndarray, np.ndarray]:
    """(Kp, Kd): Kp = M ω_n², Kd = max(2ζω_n M − D, 0) (diagonal 3×3)."""
    m, d = mass_damping(xi)
    w, z = np.diag(np.asarray(cfg.omega_n, float)), np.diag(np.asarray(cfg.zeta, float))
    kp = m @ w @ w
    kd = np.maximum(2.0 * z @ w @ m - d, 0.0)
    return kp, kd


def pd_tau(
    xi: Hydrodynamics, kp: np.ndarray, kd: np.ndarray, estimate, reference, bias=None
) -> np.ndarray:
    """τ [N, N, N m] (body frame) of the law in the module docstring.

    ``estimate`` = [η̂ (3), ν̂ (3)], ``reference`` = [η_d, η̇_d, η̈_d] (9, world frame), ``bias`` =
    b̂ (world frame, None: zero). Entries may be float or AutoDiffXd (for linearisation)."""
    estimate, reference = np.asarray(estimate), np.asarray(reference)
    m, d = mass_damping(xi)
    eta, nu = estimate[0:3], estimate[3:6]
    eta_d, eta_d_dot, eta_d_ddot = reference[0:3], reference[3:6], reference[6:9]
    rot_t = rotation(eta[2]).T
    nu_d = rot_t @ eta_d_dot
    nu_d_dot = rot_t @ eta_d_ddot - eta_d_dot[2] * (_S @ nu_d)
    e = eta - eta_d
    e = np.array([e[0], e[1], wrap_angle(e[2])])
    tau = m @ nu_d_dot + d @ nu_d - kp @ (rot_t @ e) - kd @ (nu - nu_d)
    if bias is not None:
        tau = tau - rot_t @ np.asarray(bias)
    return tau


class PdController(LeafSystem):
    """The PD law sampled every 1/rate_hz s, τ_desired held in between (discrete state).

    .. pydrake_system::

        name: PdController
        input_ports:
        - state_estimate
        - reference
        - bias_estimate
        output_ports:
        - tau_desired

    ``state_estimate`` = [x̂, ŷ, ψ̂, û, v̂, r̂]; ``reference`` = [η_d, η̇_d, η̈_d] (9, world
    frame, from ``ReferenceModel``); ``bias_estimate`` = b̂ (3, world frame, from
    ``PassiveObserver``; optional: zero when unconnected); ``tau_desired`` [N, N, N m] body frame.
    """

    def __init__(self, xi: Hydrodynamics, config: PdControllerConfig | None = None):
        super().__init__()
        self._xi = xi
        self._cfg = PdControllerConfig() if config is None else config
        self._kp, self._kd = pd_gains(xi, self._cfg)
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self._ref = self.DeclareVectorInputPort("reference", 9)
        self._bias = self.DeclareVectorInputPort("bias_estimate", 3)
        self._tau = self.DeclareDiscreteState(BasicVector(np.zeros(3)))
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / self._cfg.rate_hz, 0.0, self._update)
        self.DeclareStateOutputPort("tau_desired", self._tau)

    @property
    def gains(self) -> tuple[np.ndarray, np.ndarray]:
        """(Kp, Kd)."""
        return self._kp, self._kd

    def _update(self, context, discrete_state):
        bias = self._bias.Eval(context) if self._bias.HasValue(context) else None
        tau = pd_tau(
            self._xi, self._kp, self._kd, self._est.Eval(context), self._ref.Eval(context), bias
        )
        discrete_state.get_mutable_vector(self._tau).SetFromVector(tau)
