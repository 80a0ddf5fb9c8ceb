"""Nonlinear passive observer of Ueland 2017's motion controller (Fossen & Strand 1999; Fossen 2011
§11.4.1).

Model (Fossen 2011 §11.4.1, low-speed / dynamic-positioning form, Coriolis neglected):

    ξ̇ = A_w ξ,   η_w = C_w ξ                          wave-frequency motion (2nd-order per DOF)
    η̇ = R(ψ) ν ḃ = −T⁻¹ b slowly varying bias, world frame M ν̇ = −D ν + Rᵀ(ψ) b + τ y = η + η_w
    measured pose [x, y, ψ]

with A_w = [[0, I], [−Ω², −2ΛΩ]], C_w = [0, I], Ω = diag(ω_oi) (dominating wave frequency),
Λ = diag(ζ_i) (wave-spectrum damping), M = diag(m11, m22, m33), D = diag(Xu, Yv, Nr).

Observer (Fossen 2011 §11.4.1, "passive observer equations"; Fossen & Strand 1999):

    ξ̂̇  = A_w ξ̂ + K1 ỹ
    η̂̇  = R(y_ψ) ν̂ + K2 ỹ
    b̂̇  = −T⁻¹ b̂ + K3 ỹ
    M ν̂̇ = −D ν̂ + Rᵀ(y_ψ) b̂ + τ + Rᵀ(y_ψ) K4 ỹ
    ŷ = η̂ + C_w ξ̂,   ỹ = y − ŷ  (heading component wrapped to (−π, π])

R is evaluated at the *measured* heading y_ψ, which makes the error dynamics linear for a fixed
heading and passive (the book's argument). Gains (Fossen 2011 §11.4.1, gain formulas):

    K1 = [diag(−2(ζ_ni − ζ_i) ω_ci / ω_oi); diag(2 ω_oi (ζ_ni − ζ_i))],   K2 = diag(ω_ci)

which turn the position loop into the notch/low-pass filter
(s² + 2ζ ω_o s + ω_o²) / ((s + ω_c)(s² + 2ζ_n ω_o s + ω_o²)) per DOF, and K3, K4 positive
diagonal with the passivity ordering 1/T_i ≪ K3_i/K4_i < ω_oi < ω_ci. Equation numbers are not
quoted: we could not check them against the printed book.

``wave_filter=False`` (the default, for Ueland 2017's calm basin water) drops ξ, K1 and A_w: ŷ = η̂,
the remaining 9 states are [η̂, b̂, ν̂] and the ordering becomes 1/T_i ≪ K3_i/K4_i < ω_ci.

Our choice of K3, K4 (``fossen_gains``; the book leaves them free within the ordering): with
1/T neglected and no wave filter, each DOF's error dynamics (fixed heading) has the
characteristic polynomial s³ + (ω_c + d) s² + (ω_c d + k4) s + k3, d = D_i/m_i, k4 = K4_i/m_i,
k3 = K3_i/m_i. With p = (ω_c + d)/3, K4 = m (3p² − ω_c d) (> 0 always) and K3 = m p³ put all
three poles at −p. For ntnu_round the defaults ω_c = [2, 2, 3] rad/s give p ≈ 0.92 rad/s in
surge and sway (K3/K4 ≈ 0.75 s⁻¹) and 1.08 rad/s in yaw (K3/K4 ≈ 0.46 s⁻¹): faster than the
PD loop in surge/sway (0.5 rad/s), comparable in yaw (1.5 rad/s: the tiny yaw inertia and
damping need a stiff heading loop, and a faster yaw observer lets the yaw bias, i.e. the
integral action, act sooner), far below the 5 Hz SLAM pose rate. T = 1000 s is Fossen's
example value; a constant environmental force is then estimated to T K3/(K4 + T K3) ≥ 99.7 %
(the rest is a small steady innovation). With the wave filter, ω_o must lie between K3/K4 and
ω_c (the default ω_o = 1 rad/s only satisfies the ordering; set it to the encounter wave
frequency and ω_c above it).

The LeafSystem is discrete: every 1/rate_hz s it samples y and τ, forms the innovation ỹ and
integrates the observer ODE over the period with RK4 substeps, ỹ, τ and R(y_ψ) held (ZOH; see
``observer_step``), deterministic and cheap.
"""

from dataclasses import dataclass, field

import numpy as np

from usvdrake.angles import wrap_angle
from usvdrake.systems.vessel.vessel_dynamics import rotation
from usvdrake.vessel import Hydrodynamics


def _diag3(value, name: str) -> np.ndarray:
    v = np.broadcast_to(np.asarray(value, float), (3,)).copy()
    if not np.all(np.isfinite(v)):
        raise ValueError(f"passive observer: {name} must be finite, got {v}")
    return v


@dataclass
class PassiveObserverConfig:
    """Gains and wave model of the passive observer (build it with ``fossen_gains``; the field
    defaults are placeholders, not a tuning).

    Diagonal gains are stored as their diagonals (3 values per matrix; K1 as its two 3×3
    diagonal blocks [K11, K12]). ``T`` are the bias time constants [s] (inf: constant bias)."""

    K2: np.ndarray = field(default_factory=lambda: np.full(3, 2.0))  # [1/s] = ω_c
    K3: np.ndarray = field(default_factory=lambda: np.ones(3))  # [N/(m s)], [N m/(rad s)]
    K4: np.ndarray = field(default_factory=lambda: np.ones(3))  # [N/m], [N m/rad]
    T: np.ndarray = field(default_factory=lambda: np.full(3, 1000.0))  # [s]
    wave_filter: bool = False
    K11: np.ndarray = field(default_factory=lambda: np.zeros(3))  # [-] (wave filter only)
    K12: np.ndarray = field(default_factory=lambda: np.zeros(3))  # [1/s] (wave filter only)
    omega_o: np.ndarray = field(default_factory=lambda: np.ones(3))  # [rad/s] Ω (wave filter)
    zeta: np.ndarray = field(default_factory=lambda: np.full(3, 0.1))  # Λ (wave filter)
    rate_hz: float = 20.0  # [Hz] update rate of the discrete LeafSystem
    substeps: int = 4  # RK4 steps per update period

    def __post_init__(self):
        for name in ("K2", "K3", "K4", "T", "K11", "K12", "omega_o", "zeta"):
            v = np.broadcast_to(np.asarray(getattr(self, name), float), (3,)).copy()
            setattr(self, name, v)
        if not (np.all(self.K2 > 0) and np.all(self.K3 > 0) and np.all(self.K4 > 0)):
            raise ValueError("passive observer: K2, K3, K4 must be positive")
        if not np.all(self.T > 0):
            raise ValueError("passive observer: bias time constants T must be positive")
        if not (self.rate_hz > 0 and self.substeps >= 1):
            raise ValueError("passive observer: rate_hz > 0 and substeps >= 1 required")

    @property
    def state_size(self) -> int:
        return 15 if self.wave_filter else 9

    def wave_matrix(self) -> np.ndarray:
        """A_w (6×6) = [[0, I], [−Ω², −2ΛΩ]]."""
        a = np.zeros((6, 6))
        a[0:3, 3:6] = np.eye(3)
        a[3:6, 0:3] = -np.diag(self.omega_o**2)
        a[3:6, 3:6] = -np.diag(2.0 * self.zeta * self.omega_o)
        return a

    def passivity_violations(self, margin: float = 10.0) -> list[str]:
        """The orderings 1/T ≪ K3/K4 < ω_o < ω_c that fail ("≪": a factor ``margin``)."""
        out = []
        ratio = self.K3 / self.K4
        if np.any(margin / self.T > ratio):
            out.append(f"1/T ≪ K3/K4 fails: 1/T = {1 / self.T}, K3/K4 = {ratio}")
        upper = self.omega_o if self.wave_filter else self.K2
        if np.any(ratio >= upper):
            what = "ω_o" if self.wave_filter else "ω_c"
            out.append(f"K3/K4 < {what} fails: K3/K4 = {ratio}, {what} = {upper}")
        if self.wave_filter and np.any(self.omega_o >= self.K2):
            out.append(f"ω_o < ω_c fails: ω_o = {self.omega_o}, ω_c = {self.K2}")
        return out


def fossen_gains(
    xi: Hydrodynamics,
    omega_c=(2.0, 2.0, 3.0),
    *,
    wave_filter: bool = False,
    omega_o=1.0,
    zeta=0.1,
    zeta_n=1.0,
    T=1000.0,
    K3=None,
    K4=None,
    rate_hz: float = 20.0,
    substeps: int = 4,
) -> PassiveObserverConfig:
    """Gains per Fossen 2011 §11.4.1 from the cut-off frequencies ω_c [rad/s] (scalar or per
    DOF): K2 = diag(ω_c), K1 = [diag(−2(ζ_n − ζ) ω_c/ω_o); diag(2 ω_o (ζ_n − ζ))] (wave filter
    only; ω_o the dominating wave frequency, ζ the wave-spectrum damping, ζ_n ≥ ζ the notch
    damping). K4, K3 default to m (3p² − ω_c d) and m p³ with p = (ω_c + d)/3, d = D/m (triple
    pole at −p with 1/T neglected, see module docstring). Raises ValueError if the ordering
    1/T ≪ K3/K4 < ω_o < ω_c (or 1/T ≪ K3/K4 < ω_c without wave filter) fails."""
    m = np.array([xi.m11, xi.m22, xi.m33])
    wc = _diag3(omega_c, "omega_c")
    wo = _diag3(omega_o, "omega_o")
    z = _diag3(zeta, "zeta")
    zn = _diag3(zeta_n, "zeta_n")
    d = np.array([xi.Xu, xi.Yv, xi.Nr]) / m
    p = (wc + d) / 3.0
    k4 = m * (3.0 * p**2 - wc * d) if K4 is None else _diag3(K4, "K4")
    k3 = m * p**3 if K3 is None else _diag3(K3, "K3")
    cfg = PassiveObserverConfig(
        K2=wc,
        K3=k3,
        K4=k4,
        T=np.broadcast_to(np.asarray(T, float), (3,)).copy(),
        wave_filter=wave_filter,
        K11=-2.0 * (zn - z) * wc / wo,
        K12=2.0 * wo * (zn - z),
        omega_o=wo,
        zeta=z,
        rate_hz=rate_hz,
        substeps=substeps,
    )
    bad = cfg.passivity_violations()
    if bad:
        raise ValueError("passive observer gains: " + "; ".join(bad))
    return cfg


def split_state(cfg: PassiveObserverConfig, x: np.ndarray):
    """(ξ̂ (6 or 0), η̂, b̂, ν̂) of the observer state x."""
    k = 6 if cfg.wave_filter else 0
    return x[0:k], x[k : k + 3], x[k + 3 : k + 6], x[k + 6 : k + 9]


def initial_observer_state(cfg: PassiveObserverConfig, pose, velocity=None, bias=None):
    """x̂ with η̂ = pose, ν̂ = velocity (default 0), b̂ = bias (default 0), ξ̂ = 0."""
    parts = [
        np.zeros(6 if cfg.wave_filter else 0),
        _diag3(pose, "pose"),
        np.zeros(3) if bias is None else _diag3(bias, "bias"),
        np.zeros(3) if velocity is None else _diag3(velocity, "velocity"),
    ]
    return np.concatenate(parts)


def innovation(cfg: PassiveObserverConfig, x: np.ndarray, y) -> np.ndarray:
    """ỹ = y − (η̂ + C_w ξ̂), heading wrapped to (−π, π]."""
    xi_w, eta, _, _ = split_state(cfg, x)
    y_hat = eta + (xi_w[3:6] if cfg.wave_filter else 0.0)
    e = np.asarray(y, float) - y_hat
    e[2] = wrap_angle(e[2])
    return e


def observer_derivatives(
    cfg: PassiveObserverConfig, xi: Hydrodynamics, x, y, tau, innovation_override=None
) -> np.ndarray:
    """x̂̇ of the passive observer (module docstring) for measurement y = [x, y, ψ] and the
    commanded body-frame force τ. ``innovation_override``: use this ỹ instead of y − ŷ(x̂)
    (the sampled form of ``observer_step``); R is always R(y_ψ)."""
    x = np.asarray(x, float)
    xi_w, _, b, nu = split_state(cfg, x)
    e = innovation(cfg, x, y) if innovation_override is None else innovation_override
    rot = rotation(float(y[2]))
    m = np.array([xi.m11, xi.m22, xi.m33])
    d = np.array([xi.Xu, xi.Yv, xi.Nr])
    eta_dot = rot @ nu + cfg.K2 * e
    b_dot = -b / cfg.T + cfg.K3 * e
    nu_dot = (-d * nu + rot.T @ b + np.asarray(tau, float) + rot.T @ (cfg.K4 * e)) / m
    parts = [eta_dot, b_dot, nu_dot]
    if cfg.wave_filter:
        parts.insert(0, cfg.wave_matrix() @ xi_w + np.concatenate([cfg.K11 * e, cfg.K12 * e]))
    return np.concatenate(parts)


def observer_step(cfg: PassiveObserverConfig, xi: Hydrodynamics, x, y, tau, h: float):
    """x̂ after h seconds (RK4, ``cfg.substeps`` steps; ψ̂ wrapped after).

    The innovation ỹ = y − ŷ is formed once, at the sample instant where y is valid, and held
    with τ and R(y_ψ) over the period (zero-order hold of the observer's inputs). Holding y
    instead and re-forming ỹ inside the period would compare a stale y with a moving ŷ, and
    the estimate would lag the motion by about h/2."""
    x = np.asarray(x, float).copy()
    e = innovation(cfg, x, y)
    dt = h / cfg.substeps

    def f(state):
        return observer_derivatives(cfg, xi, state, y, tau, innovation_override=e)

    for _ in range(cfg.substeps):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x += dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    k = 6 if cfg.wave_filter else 0
    x[k + 2] = wrap_angle(x[k + 2])
    return x
