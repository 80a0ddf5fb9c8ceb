"""Closed-loop stability analysis: linearisations, pole maps, margins, Lyapunov/SOS regions.

Everything here is numerical and checkable by hand; the tests compare each piece with a closed
form. Conventions: plant state q = [x y ψ u v r] (000 eq. 7), generalised force τ = [X Y N]
(body frame), a controller is linearised as τ − τ* = H (state − trim).

**Plant** (000 eqs. 1-6, ``vessel_dynamics``): :func:`linearize_plant` runs Drake's
``Linearize`` on :class:`VesselPlant` about a straight run at surge speed u0 with its trim thrust
[Xu u0, 0, 0] (not an equilibrium: x grows, so ``equilibrium_check_tolerance=inf``). By hand
(``straight_run_jacobian``) the eigenvalues are 0, 0, 0 (x, y, ψ: no restoring force), −Xu/m11
and the two of the sway-yaw block [[−Yv/m22, −m11 u0/m22], [−(m22 − m11) u0/m33, −Nr/m33]].

**Loops** (:class:`LinearLoop`): ẋ = F x + G u (or x⁺ = F x + G u when sampled), the
controller's force τ = H x, closed by u = τ. Continuous loops use the laws as if evaluated
continuously; sampled loops discretise the plant exactly with a zero-order hold over the
controller period T (ZOH, ``expm``) and let the law read the state at the sample and hold τ,
which is what the Drake controllers (discrete state, periodic update) do. Loops built here:

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

**Margins** (``control.stability_margins``): the loop is broken at the plant input of one
channel with the other channels closed, L_i = −e_iᵀ H (sI − F − G (H − e_i e_iᵀ H))⁻¹ G e_i
(negative-feedback convention), continuous and sampled (the exact discrete loop at the
controller rate, which contains the ZOH's T/2 delay). For the decoupled PD about rest,
L = (kp + kd s) / (m s² + d s) and |L(jω_c)| = 1 gives
ω_c² = [kd² − d² + √((kd² − d²)² + 4 m² kp²)] / (2 m²),  PM = 90° + atan2(kd ω_c, kp) −
atan2(m ω_c, d) (the double integrator, d = 0: PM = atan2(kd ω_c, kp)); the gain margin is
infinite in continuous time.

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

The claimed region is checked by sampling (:func:`check_region_by_sampling`): uniform states in
{V ≤ ρ}, mapped to full plant states about random set-points, the *true* vector field
(``vessel_derivatives`` with ``pd_tau`` clipped to the box), V̇ by the chain rule. Outside the
box the real allocation (W-weighted projection onto the attainable set) is not the box clip: the
saturated region certifies the clip model, the unsaturated one the real vessel (inside the box
the allocator reproduces τ exactly).
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import control
import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import (
    ClarabelSolver,
    CsdpSolver,
    MathematicalProgram,
    ScsSolver,
    SolverOptions,
)
from pydrake.symbolic import Polynomial, Variables
from pydrake.systems.primitives import Linearize
from scipy.linalg import expm, solve_continuous_lyapunov, solve_discrete_lyapunov

from usvdrake.jsonable import jsonable
from usvdrake.scenario import ControlConfig, Scenario, load_scenario
from usvdrake.systems.control.heading_speed_law import heading_speed_tau
from usvdrake.systems.control.nmpc_problem import NmpcConfig
from usvdrake.systems.control.passive_observer import (
    PassiveObserverConfig,
    fossen_gains,
    observer_derivatives,
    observer_step,
)
from usvdrake.systems.control.pd_controller import (
    PdControllerConfig,
    mass_damping,
    pd_gains,
    pd_tau,
)
from usvdrake.systems.guidance.line_of_sight import los_reference, wrap_angle
from usvdrake.systems.vessel.thrusters import configuration_matrix, extended_matrix
from usvdrake.systems.vessel.vessel_discrete import rk4_with_jacobians
from usvdrake.systems.vessel.vessel_dynamics import (
    straight_run_jacobian,
    trim_thrust,
    vessel_derivatives,
)
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import Hydrodynamics, VesselParams, load_vessel

STATES = ["x", "y", "psi", "u", "v", "r"]
CHANNELS = ["surge", "sway", "yaw"]
DEFAULT_TRIM_SPEED = 0.6  # [m/s] the straight run of the Roboat II analysis (NOTES.md)
ERROR_STATES = ["e_x", "e_y", "psi_err", "u", "v", "r"]  # the ROA coordinates (body frame)
_CHANNEL_STATES = ([0, 3], [1, 4], [2, 5])  # (position-like, velocity-like) per DOF


# --- plant -----------------------------------------------------------------------------------
def input_matrix(xi: Hydrodynamics) -> np.ndarray:
    """∂q̇/∂τ = [0; M⁻¹] (6×3)."""
    b = np.zeros((6, 3))
    b[3:, :] = np.diag([1.0 / xi.m11, 1.0 / xi.m22, 1.0 / xi.m33])
    return b


def linearize_plant(vessel: VesselParams, surge_speed: float = DEFAULT_TRIM_SPEED):
    """(A, B) of ``VesselPlant`` about the straight run q = [0, 0, 0, u0, 0, 0] with the trim
    thrust, still water (Drake ``Linearize``; the run is not an equilibrium, hence the infinite
    equilibrium tolerance). u0 = 0 gives rest."""
    plant = VesselPlant(vessel)
    ctx = plant.CreateDefaultContext()
    ctx.SetContinuousState([0.0, 0.0, 0.0, surge_speed, 0.0, 0.0])
    plant.GetInputPort("tau").FixValue(ctx, trim_thrust(vessel.hydrodynamics, surge_speed))
    plant.GetInputPort("tau_env").FixValue(ctx, np.zeros(3))
    plant.GetInputPort("current").FixValue(ctx, np.zeros(2))
    lin = Linearize(
        plant,
        ctx,
        input_port_index=plant.GetInputPort("tau").get_index(),
        output_port_index=plant.GetOutputPort("state").get_index(),
        equilibrium_check_tolerance=np.inf,
    )
    return np.array(lin.A()), np.array(lin.B())


def straight_run_eigenvalues(xi: Hydrodynamics, surge_speed: float) -> np.ndarray:
    """The plant's eigenvalues about the straight run, in closed form (module docstring)."""
    a11, a12 = -xi.Yv / xi.m22, -xi.m11 * surge_speed / xi.m22
    a21, a22 = -(xi.m22 - xi.m11) * surge_speed / xi.m33, -xi.Nr / xi.m33
    tr, det = a11 + a22, a11 * a22 - a12 * a21
    disc = np.sqrt(complex(tr * tr / 4.0 - det))
    pair = [tr / 2.0 + disc, tr / 2.0 - disc]
    return np.array([0.0, 0.0, 0.0, -xi.Xu / xi.m11, *pair], dtype=complex)


def zoh(a: np.ndarray, b: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation (Φ, Γ) = (e^{AT}, ∫₀ᵀ e^{As} ds B)."""
    n, m = b.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = a, b
    e = expm(big * period)
    return e[:n, :n], e[:n, n:]


def autodiff_jacobian(fun, x0) -> tuple[np.ndarray, np.ndarray]:
    """(f(x0), ∂f/∂x(x0)) of a function of a vector, through AutoDiffXd."""
    x = InitializeAutoDiff(np.asarray(x0, float)).ravel()
    y = np.asarray(fun(x))
    return ExtractValue(y).ravel(), ExtractGradient(y)


def central_jacobian(fun, x0, h: float = 1e-6) -> np.ndarray:
    """∂f/∂x by central differences (for float-only project functions)."""
    x0 = np.asarray(x0, float)
    cols = []
    for i in range(len(x0)):
        dx = np.zeros_like(x0)
        dx[i] = h
        cols.append((np.asarray(fun(x0 + dx), float) - np.asarray(fun(x0 - dx), float)) / (2 * h))
    return np.array(cols).T


# --- linear loops ----------------------------------------------------------------------------
@dataclass
class LinearLoop:
    """ẋ = F x + G u (``dt`` = 0) or x⁺ = F x + G u (``dt`` = T), controller force τ = H x,
    closed by u = τ. ``unregulated``: names of integrator states dropped by :meth:`reduced`."""

    name: str
    F: np.ndarray
    G: np.ndarray
    H: np.ndarray
    dt: float = 0.0
    states: list[str] = field(default_factory=list)
    channels: list[str] = field(default_factory=lambda: list(CHANNELS))
    unregulated: list[str] = field(default_factory=list)

    @property
    def sampled(self) -> bool:
        return self.dt > 0

    @property
    def closed(self) -> np.ndarray:
        return self.F + self.G @ self.H

    def eigenvalues(self) -> np.ndarray:
        return np.linalg.eigvals(self.closed)

    def stability_measure(self) -> float:
        """max Re(λ) (continuous) or max |z| (sampled)."""
        ev = self.eigenvalues()
        return float(np.max(np.abs(ev)) if self.sampled else np.max(ev.real))

    def is_stable(self, tol: float = 1e-9) -> bool:
        m = self.stability_measure()
        return bool(m < 1.0 - tol) if self.sampled else bool(m < -tol)

    def reduced(self, drop: list[str]) -> LinearLoop:
        """The loop without states that feed back nowhere (their F column is 0, or e_i when
        sampled, and their H column 0): their eigenvalue (0 or 1) is structural."""
        idx = [self.states.index(s) for s in drop]
        for i in idx:
            col = self.F[:, i] - (np.eye(len(self.F))[:, i] if self.sampled else 0.0)
            if np.max(np.abs(col)) > 1e-9 or np.max(np.abs(self.H[:, i])) > 1e-9:
                raise ValueError(f"{self.name}: state {self.states[i]} feeds back")
        keep = [i for i in range(len(self.F)) if i not in idx]
        return LinearLoop(
            self.name,
            self.F[np.ix_(keep, keep)],
            self.G[keep],
            self.H[:, keep],
            self.dt,
            [self.states[i] for i in keep],
            list(self.channels),
            list(self.unregulated) + list(drop),
        )

    def loop_transfer(self, channel: int) -> control.StateSpace:
        """L_i: the loop broken at the plant input of ``channel``, the others closed (negative
        feedback convention: the closed loop is L/(1 + L))."""
        e = np.zeros((self.H.shape[0], 1))
        e[channel, 0] = 1.0
        a = self.F + self.G @ (self.H - e @ self.H[[channel]])
        return control.ss(a, self.G @ e, -self.H[[channel]], 0.0, self.dt if self.sampled else 0)

    def frequency_grid(self, n: int = 3000) -> np.ndarray:
        """Log-spaced ω [rad/s] from 1e-4 to 100 × the fastest pole (continuous) or to the
        Nyquist frequency π/T (sampled, excluded)."""
        if self.sampled:
            top = np.pi / self.dt * (1.0 - 1e-9)
        else:
            fast = np.abs(np.concatenate([np.linalg.eigvals(self.F), self.eigenvalues()])).max()
            top = 100.0 * fast + 10.0
        return np.logspace(-4.0, np.log10(top), n)

    def frequency_response(self, channel: int, w: np.ndarray) -> np.ndarray:
        """L_i(jω) or L_i(e^{jωT}) evaluated from the state space (batched LAPACK solves)."""
        sys = self.loop_transfer(channel)
        a, b, c = (np.asarray(m) for m in (sys.A, sys.B, sys.C))
        pts = np.exp(1j * w * self.dt) if self.sampled else 1j * w
        m = pts[:, None, None] * np.eye(len(a))[None] - a[None]
        x = np.linalg.solve(m, np.broadcast_to(b, (len(w), *b.shape)).astype(complex))
        return (c[None] @ x)[:, 0, 0]

    def margins(self, channel: int) -> dict:
        """Gain margin [dB], phase margin [deg] and their crossovers [rad/s] by
        ``control.stability_margins`` on the exact frequency response over
        :meth:`frequency_grid` (python-control's polynomial route is ill-conditioned for these
        loops: uncontrollable modes of the other channels, poles at z = 1). Sampled loops whose
        L(e^{jπ}) is real negative reach −180° exactly at the Nyquist frequency, which no grid
        brackets: that gain margin is evaluated there. None = infinite. ``gain_margin_db`` is
        python-control's pick (closest to 0 dB); a negative value is a gain-*reduction* margin
        (conditionally stable loop, e.g. LOS adds an integrator in the heading loop);
        ``all_gain_margins_db`` lists every [GM dB, ω] found."""
        w = self.frequency_grid()
        resp = self.frequency_response(channel, w)
        data = (np.abs(resp), np.degrees(np.angle(resp)), w)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gm, pm, _, wpc, wgc, _ = control.stability_margins(data)
            gms, _, _, wpcs, _, _ = control.stability_margins(data, returnall=True)
        gms, wpcs = list(np.atleast_1d(gms)), list(np.atleast_1d(wpcs))
        if self.sampled:
            nyq = float(self.frequency_response(channel, np.array([np.pi / self.dt]))[0].real)
            if nyq < 0:
                gms.append(-1.0 / nyq)
                wpcs.append(np.pi / self.dt)
                if not np.isfinite(gm) or abs(np.log(-1 / nyq)) < abs(np.log(gm)):
                    gm, wpc = -1.0 / nyq, np.pi / self.dt
        return {
            "gain_margin_db": _finite(20.0 * np.log10(gm)) if gm > 0 else None,
            "phase_margin_deg": _finite(pm),
            "phase_crossover_rad_s": _finite(wpc),
            "gain_crossover_rad_s": _finite(wgc),
            "all_gain_margins_db": [
                [float(20.0 * np.log10(g)), float(x)]
                for g, x in zip(gms, wpcs, strict=True)
                if np.isfinite(g) and g > 0
            ],
        }


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def sampled_state_feedback(loop: LinearLoop, period: float) -> LinearLoop:
    """The continuous state-feedback loop with the law read at the samples and τ held (ZOH)."""
    phi, gam = zoh(loop.F, loop.G, period)
    return LinearLoop(
        loop.name, phi, gam, loop.H.copy(), period, list(loop.states), list(loop.channels)
    )


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


# --- margins by hand ---------------------------------------------------------------------------
def pd_phase_margin(m: float, d: float, kp: float, kd: float) -> tuple[float, float]:
    """(PM [deg], ω_c [rad/s]) of L = (kp + kd s)/(m s² + d s) (module docstring)."""
    a = kd * kd - d * d
    wc = np.sqrt((a + np.sqrt(a * a + 4.0 * m * m * kp * kp)) / (2.0 * m * m))
    pm = 90.0 + np.degrees(np.arctan2(kd * wc, kp) - np.arctan2(m * wc, d))
    return float(pm), float(wc)


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


@dataclass
class RegionOfAttraction:
    """The Lyapunov certificate of the round vessel's PD loop (module docstring)."""

    P: np.ndarray  # V = zᵀ P z, z = [e_x, e_y, ψ̃, u, v, r]
    Q: np.ndarray
    K: np.ndarray  # τ = K z
    tau_max: np.ndarray  # [N, N, N m] the box
    rho: float  # claimed level with the box-clip saturation model
    rho_unsaturated: float  # claimed level of the unsaturated region
    rho_box: np.ndarray  # per channel: {V ≤ ρ} inside |τ_i| ≤ τ_max,i
    rho_wrap: float  # {V ≤ ρ} inside |ψ̃| ≤ π
    rho_polynomial: float | None  # SOS level of the unsaturated dynamics (None: ≥ the cap)
    rho_channels: np.ndarray | None  # saturated SOS level per channel (decomposed programme)
    decomposed: bool
    remainder: float  # max |coefficient| of the coupling terms of V̇
    solver: str
    solve_seconds: float

    def extents(self, rho: float | None = None) -> dict:
        """Largest |z_i| over {V ≤ ρ} in physical units, and the at-rest slices."""
        rho = self.rho if rho is None else rho
        pinv = np.linalg.inv(self.P)
        ext = np.sqrt(rho * np.diag(pinv))
        return {
            "position_error_m": float(max(ext[0], ext[1])),
            "heading_error_deg": float(np.degrees(ext[2])),
            "surge_m_s": float(ext[3]),
            "sway_m_s": float(ext[4]),
            "yaw_rate_deg_s": float(np.degrees(ext[5])),
            "at_rest_position_error_m": float(np.sqrt(rho / max(self.P[0, 0], self.P[1, 1]))),
            "at_rest_heading_error_deg": float(np.degrees(np.sqrt(rho / self.P[2, 2]))),
        }


def region_of_attraction(
    xi: Hydrodynamics,
    kp: np.ndarray,
    kd: np.ndarray,
    tau_max: np.ndarray,
    q: np.ndarray | None = None,
    solver_name: str = "clarabel",
    method: str = "auto",
    back_off: float = 1e-3,
) -> RegionOfAttraction:
    """Quadratic Lyapunov function and SOS region estimates (module docstring). ``method``:
    "auto" (decompose when the coupling terms vanish), "full" (the 9-variable programme)."""
    t0 = time.perf_counter()
    k = dp_error_feedback(kp, kd)
    a = straight_run_jacobian(xi, 0.0) + input_matrix(xi) @ k
    q = np.eye(6) if q is None else np.asarray(q, float)
    p = lyapunov_matrix(a, q)
    pinv = np.linalg.inv(p)
    rho_box = np.array([tau_max[i] ** 2 / (k[i] @ pinv @ k[i]) for i in range(3)])
    rho_wrap = float(np.pi**2 / pinv[2, 2])
    cap = 1e3 * float(max(rho_box.max(), rho_wrap))
    rho_poly = sos_rho_polynomial(xi, k, p, cap, solver_name)
    rho_poly = None if rho_poly > 0.99 * cap else rho_poly
    remainder = coupling_remainder(xi, p)
    block_diag = all(
        np.max(np.abs(p[np.ix_(ci, cj)])) == 0.0
        for i, ci in enumerate(_CHANNEL_STATES)
        for j, cj in enumerate(_CHANNEL_STATES)
        if i != j
    )
    k_diag = all(
        np.max(np.abs(k[i, [c for c in range(6) if c not in _CHANNEL_STATES[i]]])) == 0.0
        for i in range(3)
    )
    decomposed = method == "auto" and block_diag and k_diag and remainder <= 1e-12 * np.abs(p).max()
    a_open = straight_run_jacobian(xi, 0.0)
    b_open = input_matrix(xi)
    if decomposed:
        rho_ch = []
        for i, idx in enumerate(_CHANNEL_STATES):
            ix = np.ix_(idx, idx)
            rho_ch.append(
                sos_rho_channel(
                    p[ix], a_open[ix], b_open[idx, i], k[i, idx], tau_max[i], cap, solver_name
                )
            )
        rho_channels = np.array(rho_ch)
        rho_sat = float(rho_channels.min())
    else:
        rho_channels = None
        rho_sat = sos_rho_full(xi, k, p, tau_max, cap, solver_name)
    scale = 1.0 - back_off
    rho_unsat = min(float(rho_box.min()), rho_wrap, np.inf if rho_poly is None else rho_poly)
    return RegionOfAttraction(
        P=p,
        Q=q,
        K=k,
        tau_max=np.asarray(tau_max, float),
        rho=scale * min(rho_sat, rho_wrap),
        rho_unsaturated=scale * rho_unsat,
        rho_box=rho_box,
        rho_wrap=rho_wrap,
        rho_polynomial=rho_poly,
        rho_channels=rho_channels,
        decomposed=decomposed,
        remainder=remainder,
        solver=solver_name,
        solve_seconds=time.perf_counter() - t0,
    )


def sample_ellipsoid(p: np.ndarray, rho: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """n points uniform in {zᵀ P z ≤ ρ} (n × dim)."""
    dim = len(p)
    d = rng.standard_normal((n, dim))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radius = rng.random(n) ** (1.0 / dim)
    ell = np.linalg.cholesky(p)  # P = L Lᵀ, z = L⁻ᵀ y with ‖y‖² ≤ ρ
    return np.linalg.solve(ell.T, (np.sqrt(rho) * radius[:, None] * d).T).T


def true_vdot(
    xi: Hydrodynamics,
    kp: np.ndarray,
    kd: np.ndarray,
    tau_max: np.ndarray,
    p: np.ndarray,
    z: np.ndarray,
    rng: np.random.Generator,
    allocator=None,
) -> tuple[np.ndarray, np.ndarray]:
    """(V̇, saturated (n × 3, per channel)) at error states z (n × 6) through the true closed
    loop: each z becomes a plant state about a random set-point η_d, τ = ``pd_tau`` clipped to
    the box (or passed through ``allocator``, a ``ThrustAllocator``), q̇ =
    ``vessel_derivatives``, and V̇ = 2 zᵀ P ż with ż from q̇ by the chain rule
    (e = Rᵀ(ψ)(p − p_d))."""
    n = len(z)
    eta_d = np.column_stack(
        [rng.uniform(-50, 50, n), rng.uniform(-50, 50, n), rng.uniform(-np.pi, np.pi, n)]
    )
    psi = wrap_angle(eta_d[:, 2] + z[:, 2])
    c, s = np.cos(psi), np.sin(psi)
    pos = eta_d[:, :2] + np.column_stack([c * z[:, 0] - s * z[:, 1], s * z[:, 0] + c * z[:, 1]])
    q = np.column_stack([pos, psi, z[:, 3:6]])
    tau = np.empty((n, 3))
    for i in range(n):
        ref = np.concatenate([eta_d[i], np.zeros(6)])
        tau[i] = pd_tau(xi, kp, kd, q[i], ref)
    saturated = np.abs(tau) > tau_max
    if allocator is None:
        applied = np.clip(tau, -tau_max, tau_max)
    else:
        applied = np.array([allocator.allocate(t).tau_achieved for t in tau])
    zeros = np.zeros(n)
    qdot = vessel_derivatives(xi, q.T, applied.T, (zeros, zeros, zeros), (zeros, zeros)).T
    # z recomputed from q (the true map), and its derivative
    dp = pos - eta_d[:, :2]
    e = np.column_stack([c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1]])
    w = qdot[:, 2]
    de = np.column_stack(
        [
            c * qdot[:, 0] + s * qdot[:, 1] + w * (-s * dp[:, 0] + c * dp[:, 1]),
            -s * qdot[:, 0] + c * qdot[:, 1] + w * (-c * dp[:, 0] - s * dp[:, 1]),
        ]
    )
    zz = np.column_stack([e, wrap_angle(psi - eta_d[:, 2]), q[:, 3:6]])
    zdot = np.column_stack([de, w, qdot[:, 3:6]])
    return 2.0 * np.einsum("ij,jk,ik->i", zz, p, zdot), saturated


def check_region_by_sampling(
    xi: Hydrodynamics,
    kp: np.ndarray,
    kd: np.ndarray,
    roa: RegionOfAttraction,
    rho: float | None = None,
    n: int = 10_000,
    seed: int = 0,
    allocator=None,
) -> dict:
    """Sample n states uniformly in {V ≤ ρ} and evaluate the true V̇ (:func:`true_vdot`)."""
    rho = roa.rho if rho is None else rho
    rng = np.random.default_rng(seed)
    z = sample_ellipsoid(roa.P, rho, n, rng)
    vdot, sat = true_vdot(xi, kp, kd, roa.tau_max, roa.P, z, rng, allocator)
    v = np.einsum("ij,jk,ik->i", z, roa.P, z)
    return {
        "samples": int(n),
        "rho": float(rho),
        "all_decreasing": bool(np.all(vdot < 0.0)),
        "violations": int(np.sum(vdot >= 0.0)),
        "max_vdot": float(vdot.max()),
        "max_vdot_over_v": float(np.max(vdot / v)),
        "saturated_fraction": float(np.mean(np.any(sat, axis=1))),
        "saturated_fraction_per_channel": np.mean(sat, axis=0).tolist(),
        "z": z,
        "vdot": vdot,
        "saturated": sat,
    }


# --- the top level -----------------------------------------------------------------------------
def _eig_list(ev) -> list[list[float]]:
    ev = np.asarray(ev, complex)
    ev = ev[np.lexsort((ev.imag, ev.real))]
    return [[float(x.real), float(x.imag)] for x in ev]


def _loop_entry(cont: LinearLoop | None, samp: LinearLoop | None, description: str) -> dict:
    out = {"description": description}
    ref = cont if cont is not None else samp
    out["states"] = list(ref.states)
    out["unregulated"] = list(ref.unregulated)
    if cont is not None:
        out["continuous"] = {
            "eigenvalues": _eig_list(cont.eigenvalues()),
            "max_real": cont.stability_measure(),
            "stable": cont.is_stable(),
        }
    else:
        out["continuous"] = "not applicable (discrete-time controller)"
    if samp is not None:
        out["sampled"] = {
            "period_s": samp.dt,
            "eigenvalues": _eig_list(samp.eigenvalues()),
            "max_abs": samp.stability_measure(),
            "stable": samp.is_stable(),
        }
    margins = {}
    for i, ch in enumerate(ref.channels):
        margins[ch] = {
            "continuous": cont.margins(i) if cont is not None else None,
            "sampled": samp.margins(i) if samp is not None else None,
        }
    out["margins"] = margins
    return out


def _default_trim(vessel: VesselParams) -> float:
    return min(DEFAULT_TRIM_SPEED, vessel.max_speed)


def analyze_stability(
    scenario: str | Path | Scenario,
    out_dir: str | Path | None = None,
    *,
    trim_speed: float | None = None,
    roa_samples: int = 10_000,
    allocator_samples: int = 2000,
    seed: int = 0,
) -> dict:
    """Stability of ``scenario``'s vessel and controller (module docstring); returns the JSON-able
    content of ``analysis.json`` and, with ``out_dir``, writes it with the plots (pole map, Bode
    plots with margins, region-of-attraction slices)."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    vessel = load_vessel(sc.vessel)
    xi = vessel.hydrodynamics
    result = {
        "scenario": sc.name,
        "vessel": vessel.name,
        "controller": sc.controller,
        "estimator": sc.estimator,
        "notes": [],
    }
    loops: dict[str, tuple] = {}
    roa_data = None
    if sc.controller == "explore":
        u0 = 0.0
        cont = pd_loop(xi, sc.exploration.pd)
        samp = sampled_state_feedback(cont, 1.0 / sc.exploration.pd.rate_hz)
        loops["pd"] = (cont, samp, "DP PD on the exact state about rest (Fossen 2011 §12.2)")
        if sc.estimator == "observer":
            o = sc.exploration.observer
            obs = fossen_gains(xi, o.cutoff, T=o.bias_time_constant, rate_hz=o.rate_hz)
            c2 = pd_observer_loop(xi, sc.exploration.pd, obs)
            try:
                s2 = sampled_pd_observer_loop(xi, sc.exploration.pd, obs)
            except ValueError as exc:
                s2 = None
                result["notes"].append(f"sampled observer loop not analysed: {exc}")
            loops["pd_observer"] = (
                c2,
                s2,
                "PD on the passive observer's estimate (exact pose, commanded τ)",
            )
            result["separation"] = {
                "observer_error_eigenvalues": _eig_list(
                    np.linalg.eigvals(observer_error_matrix(obs, xi))
                ),
                "max_mismatch": _set_distance(
                    c2.eigenvalues(),
                    np.concatenate(
                        [cont.eigenvalues(), np.linalg.eigvals(observer_error_matrix(obs, xi))]
                    ),
                ),
            }
        roa_data = _roa_report(vessel, sc.exploration.pd, roa_samples, allocator_samples, seed)
        result["lyapunov"] = roa_data["report"]
    elif sc.controller == "baseline":
        u0 = _default_trim(vessel) if trim_speed is None else trim_speed
        inner = baseline_loop(vessel, sc.control, u0, los=False).reduced(["x", "y"])
        outer = baseline_loop(vessel, sc.control, u0, los=True).reduced(["x"])
        period = 1.0 / sc.control.rate_hz
        loops["heading_speed"] = (
            inner,
            sampled_state_feedback(inner, period),
            "heading/speed PD alone (x, y not regulated)",
        )
        loops["los_heading_speed"] = (
            outer,
            sampled_state_feedback(outer, period),
            f"LOS (Δ = {sc.control.lookahead} m) + heading/speed PD, path along x",
        )
        result["lyapunov"] = "not analysed (the Lyapunov/ROA analysis covers the explore PD)"
    else:
        u0 = _default_trim(vessel) if trim_speed is None else trim_speed
        try:
            loops["nmpc_lq"] = (
                None,
                nmpc_loop(vessel, sc.nmpc, u0),
                "NMPC's receding-horizon LQ gain about the straight run, offset-free filter "
                "included, exact state (the NMHE is not modelled)",
            )
        except ValueError as exc:
            result["notes"].append(f"NMPC loop not analysed: {exc}")
        result["lyapunov"] = "not analysed (the Lyapunov/ROA analysis covers the explore PD)"
    a, b = linearize_plant(vessel, u0)
    result["plant"] = {
        "trim_surge_speed_m_s": u0,
        "eigenvalues": _eig_list(np.linalg.eigvals(a)),
        "closed_form_eigenvalues": _eig_list(straight_run_eigenvalues(xi, u0)),
        "A": a.tolist(),
        "B": b.tolist(),
    }
    result["loops"] = {name: _loop_entry(c, s, d) for name, (c, s, d) in loops.items()}
    result = jsonable(result)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "analysis.json").write_text(json.dumps(result, indent=2))
        files = [_plot_poles(loops, out / "poles.png", sc.name)]
        for name, (c, s, _) in loops.items():
            files.append(_plot_bode(c, s, out / f"bode_{name}.png", name))
        if roa_data is not None:
            files.append(_plot_roa(roa_data, out / "roa.png"))
        result["files"] = [str(f) for f in files]
        (out / "analysis.json").write_text(json.dumps(result, indent=2))
    return result


def _set_distance(a, b) -> float:
    """Largest distance of an optimal one-to-one matching of two eigenvalue sets."""
    from scipy.optimize import linear_sum_assignment

    a, b = np.asarray(a, complex), np.asarray(b, complex)
    if len(a) != len(b):
        return float("inf")
    cost = np.abs(a[:, None] - b[None, :])
    r, c = linear_sum_assignment(cost)
    return float(cost[r, c].max())


def _roa_report(vessel, pd_cfg, n, n_alloc, seed) -> dict:
    from usvdrake.systems.vessel.thrust_allocation_problem import ThrustAllocator

    xi = vessel.hydrodynamics
    kp, kd = pd_gains(xi, pd_cfg)
    t0 = time.perf_counter()
    tau_max, _ = thrust_box(vessel)
    box_s = time.perf_counter() - t0
    roa = region_of_attraction(xi, kp, kd, tau_max)
    check = check_region_by_sampling(xi, kp, kd, roa, n=n, seed=seed)
    check_u = check_region_by_sampling(xi, kp, kd, roa, roa.rho_unsaturated, n=n, seed=seed + 1)
    report = {
        "loop": "round vessel PD on the exact state (no observer), continuous-time law",
        "coordinates": ERROR_STATES,
        "Q": roa.Q.tolist(),
        "P": roa.P.tolist(),
        "tau_max": roa.tau_max.tolist(),
        "thrust_box_seconds": box_s,
        "rho": roa.rho,
        "rho_unsaturated": roa.rho_unsaturated,
        "rho_box_per_channel": roa.rho_box.tolist(),
        "rho_wrap": roa.rho_wrap,
        "rho_polynomial_sos": roa.rho_polynomial,
        "rho_saturated_sos_per_channel": None
        if roa.rho_channels is None
        else roa.rho_channels.tolist(),
        "decomposed": roa.decomposed,
        "coupling_remainder": roa.remainder,
        "solver": roa.solver,
        "solve_seconds": roa.solve_seconds,
        "extent": roa.extents(),
        "extent_unsaturated": roa.extents(roa.rho_unsaturated),
        "sampling_check": {k: v for k, v in check.items() if k not in ("z", "vdot", "saturated")},
        "sampling_check_unsaturated": {
            k: v for k, v in check_u.items() if k not in ("z", "vdot", "saturated")
        },
    }
    if n_alloc > 0:
        alloc = ThrustAllocator(vessel.thrusters, vessel.allocation_weight)
        chk = check_region_by_sampling(xi, kp, kd, roa, n=n_alloc, seed=seed + 2, allocator=alloc)
        report["allocator_check"] = {
            "note": "the real thrust allocation instead of the box clip (not certified)",
            **{k: v for k, v in chk.items() if k not in ("z", "vdot", "saturated")},
        }
    a_cl = straight_run_jacobian(xi, 0.0) + input_matrix(xi) @ roa.K
    phi, gam = zoh(straight_run_jacobian(xi, 0.0), input_matrix(xi), 1.0 / pd_cfg.rate_hz)
    pd_ = solve_discrete_lyapunov((phi + gam @ roa.K).T, np.eye(6))
    report["sampled_lyapunov_min_eig"] = float(np.linalg.eigvalsh(0.5 * (pd_ + pd_.T)).min())
    report["continuous_lyapunov_residual"] = float(
        np.abs(a_cl.T @ roa.P + roa.P @ a_cl + roa.Q).max()
    )
    return {"report": report, "roa": roa, "check": check}


def format_table(result: dict) -> str:
    """A readable text summary of :func:`analyze_stability`'s result."""

    def fmt(x, spec=".3g", none="inf"):
        return none if x is None else format(x, spec)

    def eigs(ev):
        parts = []
        for re, im in ev:
            parts.append(f"{re:.4g}" if abs(im) < 1e-12 else f"{re:.4g}{im:+.4g}j")
        return ", ".join(parts)

    lines = [
        f"Stability analysis: {result['scenario']} (vessel {result['vessel']}, controller "
        f"{result['controller']}, estimator {result['estimator']})",
        "",
        f"Plant about u0 = {result['plant']['trim_surge_speed_m_s']} m/s: eigenvalues "
        + eigs(result["plant"]["eigenvalues"]),
        "",
        f"{'loop':<20}{'continuous max Re':>19}{'stable':>8}{'sampled max |z|':>17}"
        f"{'T [s]':>7}{'stable':>8}",
    ]
    for name, lp in result["loops"].items():
        c, s = lp["continuous"], lp.get("sampled")
        cre = f"{c['max_real']:.4f}" if isinstance(c, dict) else "n/a"
        cst = ("yes" if c["stable"] else "NO") if isinstance(c, dict) else "n/a"
        sab = f"{s['max_abs']:.4f}" if s else "n/a"
        sdt = f"{s['period_s']:.3g}" if s else ""
        sst = ("yes" if s["stable"] else "NO") if s else "n/a"
        lines.append(f"{name:<20}{cre:>19}{cst:>8}{sab:>17}{sdt:>7}{sst:>8}")
        if lp["unregulated"]:
            lines.append(
                f"{'':<20}(unregulated integrators dropped: {', '.join(lp['unregulated'])})"
            )
    lines += [
        "",
        "Margins, loop broken at the plant input (others closed): GM [dB] / PM [deg] @ ω_c [rad/s]",
        f"{'loop':<20}{'channel':<8}{'continuous':>30}{'sampled':>30}",
    ]
    for name, lp in result["loops"].items():
        for ch, m in lp["margins"].items():
            cols = []
            for key in ("continuous", "sampled"):
                v = m[key]
                if v is None:
                    cols.append("n/a")
                else:
                    cols.append(
                        f"{fmt(v['gain_margin_db'], '.1f')} / {fmt(v['phase_margin_deg'], '.1f')}"
                        f" @ {fmt(v['gain_crossover_rad_s'], '.3f', 'none')}"
                    )
            lines.append(f"{name:<20}{ch:<8}{cols[0]:>30}{cols[1]:>30}")
    if "separation" in result:
        lines += [
            "",
            "Separation principle (PD + observer): max eigenvalue mismatch "
            f"{result['separation']['max_mismatch']:.2e}",
        ]
    ly = result.get("lyapunov")
    if isinstance(ly, dict):
        ext, extu = ly["extent"], ly["extent_unsaturated"]
        chk = ly["sampling_check"]
        lines += [
            "",
            f"Lyapunov / region of attraction ({ly['loop']})",
            f"  box |τ| ≤ [{ly['tau_max'][0]:.3f} N, {ly['tau_max'][1]:.3f} N, "
            f"{ly['tau_max'][2]:.3f} N m]",
            f"  unsaturated region ρ = {ly['rho_unsaturated']:.4g}: at rest |e| ≤ "
            f"{extu['at_rest_position_error_m']:.2f} m or |ψ̃| ≤ "
            f"{extu['at_rest_heading_error_deg']:.1f}°",
            f"  with box saturation ρ = {ly['rho']:.4g}: at rest |e| ≤ "
            f"{ext['at_rest_position_error_m']:.2f} m or |ψ̃| ≤ "
            f"{ext['at_rest_heading_error_deg']:.1f}°; extents |e| {ext['position_error_m']:.2f} "
            f"m, |u|,|v| {ext['surge_m_s']:.2f} m/s, |r| {ext['yaw_rate_deg_s']:.0f}°/s",
            f"  SOS: {ly['solver']}, {ly['solve_seconds']:.2f} s, "
            f"{'per-channel' if ly['decomposed'] else 'full'} programme",
            f"  sampling check: {chk['samples']} states, {chk['violations']} with V̇ ≥ 0, "
            f"max V̇/V = {chk['max_vdot_over_v']:.3g}, "
            f"saturated {100 * chk['saturated_fraction']:.0f} %",
        ]
        if "allocator_check" in ly:
            ac = ly["allocator_check"]
            lines.append(
                f"  real allocation (not certified): {ac['violations']}/{ac['samples']} with V̇ ≥ 0"
            )
    elif ly:
        lines += ["", f"Lyapunov: {ly}"]
    for note in result.get("notes", []):
        lines.append(f"note: {note}")
    return "\n".join(lines)


# --- plots ---------------------------------------------------------------------------------------
def _figure(w=10, h=4.5):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


_MARKERS = ["x", "o", "s", "^", "d", "v"]


def _plot_poles(loops: dict, path: Path, title: str) -> Path:
    fig = _figure(15, 4.8)
    ax_s, ax_z, ax_zz = (fig.add_subplot(1, 3, k) for k in (1, 2, 3))
    zoom = []
    for i, (name, (c, s, _)) in enumerate(loops.items()):
        mk = _MARKERS[i % len(_MARKERS)]
        style = (
            {"marker": mk, "color": f"C{i}"}
            if mk == "x"
            else {
                "marker": mk,
                "facecolors": "none",
                "edgecolors": f"C{i}",
            }
        )
        if c is not None:
            ev = c.eigenvalues()
            ax_s.scatter(ev.real, ev.imag, label=name, **style)
        if s is not None:
            ev = s.eigenvalues()
            for ax in (ax_z, ax_zz):
                ax.scatter(ev.real, ev.imag, label=f"{name} (T = {s.dt:g} s)", **style)
            zoom += list(ev[np.abs(ev) > 0.5])
    th = np.linspace(0, 2 * np.pi, 2000)
    for ax in (ax_z, ax_zz):
        ax.plot(np.cos(th), np.sin(th), "k-", lw=0.8)
    ax_s.axvline(0.0, color="k", lw=0.8)
    if zoom:
        zoom = np.array(zoom)
        half = max(np.max(np.abs(zoom - 1.0)), 0.02) * 1.15
        ax_zz.set_xlim(1.0 - 2 * half, 1.0 + 0.2 * half)
        ax_zz.set_ylim(-1.1 * half, 1.1 * half)
    titles = ("s-plane (continuous)", "z-plane (sampled)", "z-plane near z = 1")
    for ax, t in zip((ax_s, ax_z, ax_zz), titles, strict=True):
        ax.set_title(t)
        ax.set_xlabel("Re")
        ax.set_ylabel("Im")
        ax.grid(True, alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    ax_z.set_aspect("equal")
    fig.suptitle(f"Closed-loop poles: {title}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _plot_bode(cont: LinearLoop | None, samp: LinearLoop | None, path: Path, name: str) -> Path:
    fig = _figure(10, 7)
    ax_m, ax_p = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    ref = cont if cont is not None else samp
    w_max = np.pi / samp.dt * 0.999 if samp is not None else 100.0
    w = np.logspace(-3, np.log10(w_max), 600)
    for i, ch in enumerate(ref.channels):
        for loop, style in ((cont, "-"), (samp, "--")):
            if loop is None:
                continue
            resp = loop.frequency_response(i, w)
            mag = 20 * np.log10(np.abs(resp))
            ph = np.degrees(np.unwrap(np.angle(resp)))
            ph -= 360.0 * np.ceil((ph[0] - 90.0) / 360.0)  # low-frequency phase in (−270°, 90°]
            m = loop.margins(i)
            kind = "cont." if loop is cont else f"T = {loop.dt:g} s"
            label = (
                f"{ch} {kind}: GM {_fmt_opt(m['gain_margin_db'])} dB, PM "
                f"{_fmt_opt(m['phase_margin_deg'])}°"
            )
            ax_m.semilogx(w, mag, style, color=f"C{i}", label=label)
            ax_p.semilogx(w, ph, style, color=f"C{i}")
            if m["gain_crossover_rad_s"] is not None:
                ax_p.plot(
                    m["gain_crossover_rad_s"], m["phase_margin_deg"] - 180.0, "o", color=f"C{i}"
                )
    ax_m.axhline(0.0, color="k", lw=0.8)
    ax_p.axhline(-180.0, color="k", lw=0.8)
    ax_m.set_ylabel("|L| [dB]")
    ax_p.set_ylabel("∠L [deg]")
    ax_p.set_xlabel("ω [rad/s]")
    ax_m.legend(fontsize=7)
    ax_m.grid(True, which="both", alpha=0.3)
    ax_p.grid(True, which="both", alpha=0.3)
    ax_m.set_title(f"Loop broken at the plant input: {name} (solid continuous, dashed sampled)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def _fmt_opt(x):
    return "inf" if x is None else f"{x:.1f}"


def _plot_roa(data: dict, path: Path) -> Path:
    roa: RegionOfAttraction = data["roa"]
    check = data["check"]
    fig = _figure(14, 4.8)
    pinv = np.linalg.inv(roa.P)
    th = np.linspace(0, 2 * np.pi, 400)
    circle = np.vstack([np.cos(th), np.sin(th)])
    deg = np.degrees(1.0)
    pairs = [((0, 3), "e_x [m]", "u [m/s]", 1.0), ((1, 4), "e_y [m]", "v [m/s]", 1.0)]
    pairs.append(((2, 5), "ψ̃ [deg]", "r [deg/s]", deg))
    rng = np.random.default_rng(0)
    pick = rng.choice(len(check["z"]), size=min(2000, len(check["z"])), replace=False)
    zs, sat = check["z"][pick], check["saturated"][pick]
    for ch, ((i, j), xl, yl, sc) in enumerate(pairs):
        ax = fig.add_subplot(1, 3, ch + 1)
        idx = [i, j]
        own = sat[:, ch]
        ax.scatter(zs[~own, i] * sc, zs[~own, j] * sc, s=2, color="0.65", label="samples")
        ax.scatter(
            zs[own, i] * sc, zs[own, j] * sc, s=3, color="C3", label="samples, this τ saturated"
        )
        slice_m = roa.P[np.ix_(idx, idx)]
        shadow_m = np.linalg.inv(pinv[np.ix_(idx, idx)])
        same = np.allclose(slice_m, shadow_m, rtol=1e-9, atol=0.0)
        for rho, label, color in (
            (roa.rho, "V = ρ (box saturation)", "C0"),
            (roa.rho_unsaturated, "V = ρ unsaturated", "C2"),
        ):
            mats = [(slice_m, "slice" if not same else "slice = projection", "-")]
            if not same:
                mats.append((shadow_m, "projection", "--"))
            for mat, lab2, style in mats:
                ell = np.linalg.cholesky(mat)
                pts = np.linalg.solve(ell.T, np.sqrt(rho) * circle) * sc
                ax.plot(pts[0], pts[1], style, lw=1.6, color=color, label=f"{label}, {lab2}")
        kk = roa.K[ch, idx]
        xlim, ylim = ax.get_xlim(), ax.get_ylim()
        xs = np.linspace(xlim[0], xlim[1], 10) / sc
        if abs(kk[1]) > 0:
            for sgn in (1, -1):
                ys = (sgn * roa.tau_max[ch] - kk[0] * xs) / kk[1]
                ax.plot(
                    xs * sc, ys * sc, "k:", lw=0.9, label="|τ| = τ_max (slice)" if sgn > 0 else None
                )
        ax.set_xlim(xlim)
        ax.set_ylim(ylim)
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(True, alpha=0.3)
        ax.set_title(f"{CHANNELS[ch]}: τ_max = {roa.tau_max[ch]:.3g}")
        if ch == 0:
            ax.legend(fontsize=6, loc="upper right")
    fig.suptitle(
        f"Region of attraction, V = zᵀPz ≤ ρ = {roa.rho:.3g} (samples of the 6-D set projected; "
        f"{check['samples']} checked, max V̇ = {check['max_vdot']:.2e})"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path
