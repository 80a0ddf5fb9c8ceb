"""Environmental disturbances as seeded random processes (numerical core of ``Environment``).

* **Current** (Fossen 2011 §8.3): a world-frame velocity V_c = (U_c + δ) [cos β_c, sin β_c] whose
  speed variation δ is a first-order Gauss-Markov process.
* **Wind** (Fossen 2011 §8.1): mean speed plus a Gauss-Markov gust; the force on the hull above
  the waterline follows the relative air velocity (u_rw, v_rw) = ν − R(ψ)ᵀ V_w:
      X = −½ ρ_a c_x A_F u_rw V_rw,   Y = −½ ρ_a c_y A_L v_rw V_rw,   N = ½ ρ_a c_n A_L L u_rw v_rw
  with A_F = B h_f, A_L = L h_f the frontal and lateral windage (h_f = height − draught). This is
  Fossen's C_X = −c_x cos γ, C_Y = c_y sin γ, C_N = c_n sin 2γ written in velocity components;
  N > 0 turns the bow into the wind.
* **First-order wave forces**: a Pierson-Moskowitz sea (significant height H_s, peak period T_p)
  as a sum of regular Airy components with seeded frequencies and phases, amplitude
  a_i = √(2 S(ω_i) Δω). For a hull much shorter than the waves the wave-frequency force is the
  Froude-Krylov + added-mass inertia force (Morison inertia term) M a_fluid, a_fluid the
  horizontal particle acceleration at the surface; it is evaluated on two strips at ±L/4 so the
  phase difference along the hull gives a yaw moment. The first-order forces average to zero:
  the vessel oscillates with the waves (amplitude ≈ a_i) without drifting.

Gauss-Markov steps are exact discretisations x_{k+1} = φ x_k + σ √(1 − φ²) w_k, φ = e^{−h/T},
with w_k drawn from a generator seeded by (seed, stream, k): the same seed and step give the same
number whatever else ran before, so a diagram can be re-simulated and reset freely.
"""

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from usvdrake.random_streams import white_sample
from usvdrake.vessel import VesselParams


@dataclass
class CurrentConfig:
    speed: float = 0.0  # [m/s] mean water velocity
    direction_deg: float = 0.0  # [deg] direction the water flows towards (ENU, from east)
    variation_std: float = 0.0  # [m/s] std of the slow speed variation (Gauss-Markov)
    variation_time_constant: float = 60.0  # [s] correlation time of that variation


@dataclass
class WindConfig:
    mean_speed: float = 0.0  # [m/s] mean wind speed at deck height
    direction_deg: float = 0.0  # [deg] direction the air moves towards (ENU, from east)
    gust_std: float = 0.0  # [m/s] std of the gust speed (first-order Gauss-Markov)
    gust_time_constant: float = 5.0  # [s] gust correlation time
    air_density: float = 1.225  # [kg/m^3]
    cx: float = 0.6  # [-] surge wind-force coefficient (Fossen 2011 §8.1, small craft)
    cy: float = 0.8  # [-] sway wind-force coefficient
    cn: float = 0.05  # [-] yaw wind-moment coefficient (≈0 for fore-aft symmetric hulls)


@dataclass
class WaveConfig:
    significant_height: float = 0.0  # [m] Hs of a Pierson-Moskowitz sea
    peak_period: float = 2.0  # [s] Tp
    direction_deg: float = 0.0  # [deg] direction the waves travel towards (ENU, from east)
    components: int = 16  # [-] number of regular wave components summed


@dataclass
class EnvironmentConfig:
    current: CurrentConfig = field(default_factory=CurrentConfig)
    wind: WindConfig = field(default_factory=WindConfig)
    waves: WaveConfig = field(default_factory=WaveConfig)
    update_period: float = 0.1  # [s] step of the random processes (gusts, current variation)


GRAVITY = 9.81  # [m/s^2]
STREAM_GUST, STREAM_CURRENT = 1, 2


def gauss_markov_step(x: float, sigma: float, time_constant: float, h: float, w: float) -> float:
    """One exact step of dx = −x/T dt + σ √(2/T) dW (stationary std σ) over h, white sample w."""
    phi = np.exp(-h / time_constant)
    return phi * x + sigma * np.sqrt(1.0 - phi * phi) * w


def pierson_moskowitz(omega: np.ndarray, hs: float, tp: float) -> np.ndarray:
    """PM spectrum S(ω) [m² s] for significant height hs [m] and peak period tp [s]
    (DNV-RP-C205 §3.5.5 form: S = 5/16 H_s² ω_p⁴ ω⁻⁵ exp(−5/4 (ω_p/ω)⁴))."""
    wp = 2.0 * np.pi / tp
    return 5.0 / 16.0 * hs**2 * wp**4 * omega**-5 * np.exp(-1.25 * (wp / omega) ** 4)


@dataclass
class WaveComponents:
    amplitude: np.ndarray  # [m]
    omega: np.ndarray  # [rad/s]
    wavenumber: np.ndarray  # [rad/m], deep water k = ω²/g
    phase: np.ndarray  # [rad]
    direction: float  # [rad] propagation direction (ENU)


def make_waves(cfg, seed: int) -> WaveComponents:
    """Random-phase, random-frequency components of the PM spectrum over [0.5, 3] ω_p."""
    rng = np.random.default_rng([seed, 3])
    n = cfg.components
    wp = 2.0 * np.pi / cfg.peak_period
    edges = np.linspace(0.5 * wp, 3.0 * wp, n + 1)
    omega = edges[:-1] + rng.uniform(0.0, 1.0, n) * np.diff(edges)
    amp = np.sqrt(
        2.0 * pierson_moskowitz(omega, cfg.significant_height, cfg.peak_period) * np.diff(edges)
    )
    return WaveComponents(
        amplitude=amp,
        omega=omega,
        wavenumber=omega**2 / GRAVITY,
        phase=rng.uniform(0.0, 2.0 * np.pi, n),
        direction=np.deg2rad(cfg.direction_deg),
    )


def wave_acceleration(waves: WaveComponents, xy: np.ndarray, t: float) -> np.ndarray:
    """Horizontal fluid-particle acceleration [m/s²] at the surface at world point xy, time t."""
    d = np.array([np.cos(waves.direction), np.sin(waves.direction)])
    theta = waves.wavenumber * (d @ xy) - waves.omega * t + waves.phase
    mag = np.sum(waves.amplitude * waves.omega**2 * np.sin(theta))
    return mag * d


class EnvironmentModel:
    """Disturbance forces and current for one vessel; stateless apart from the Gauss-Markov
    states passed in (gust speed, current speed variation)."""

    def __init__(self, cfg: EnvironmentConfig, vessel: VesselParams, seed: int):
        self.cfg, self.vessel, self.seed = cfg, vessel, seed
        hull = vessel.hull
        freeboard = max(hull.height - hull.draught, 0.0)
        self.area_frontal = hull.beam * freeboard
        self.area_lateral = hull.length * freeboard
        self.waves = make_waves(cfg.waves, seed) if cfg.waves.significant_height > 0 else None
        # amplitude ω² of each component: its particle acceleration's amplitude
        self._wave_gain = None if self.waves is None else self.waves.amplitude * self.waves.omega**2
        self._no_wind = cfg.wind.mean_speed == 0.0 and cfg.wind.gust_std == 0.0
        # the kernels' constant arguments, made once (the plant asks at every integrator stage)
        w, b = cfg.wind, math.radians(cfg.wind.direction_deg)
        k = 0.5 * w.air_density
        self._wind_direction = (math.cos(b), math.sin(b))
        self._wind_gains = (
            k * w.cx * self.area_frontal,
            k * w.cy * self.area_lateral,
            k * w.cn * self.area_lateral * hull.length,
        )
        if self.waves is not None:
            h = vessel.hydrodynamics
            self._wave_constants = (
                0.25 * hull.length,
                self.waves.direction,
                self.waves.wavenumber,
                self.waves.phase,
                self.waves.omega,
                self._wave_gain,
                h.m11,
                h.m22,
            )

    def step_processes(self, gust: float, current_var: float, k: int) -> tuple[float, float]:
        """Advance (gust, current variation) by one update period, step index k."""
        h = self.cfg.update_period
        w, c = self.cfg.wind, self.cfg.current
        gust = gauss_markov_step(
            gust, w.gust_std, w.gust_time_constant, h, white_sample(self.seed, STREAM_GUST, k)
        )
        current_var = gauss_markov_step(
            current_var,
            c.variation_std,
            c.variation_time_constant,
            h,
            white_sample(self.seed, STREAM_CURRENT, k),
        )
        return gust, current_var

    def current(self, current_var: float) -> np.ndarray:
        """Water velocity [m/s], world frame."""
        c = self.cfg.current
        if c.speed == 0.0 and c.variation_std == 0.0:
            return np.zeros(2)
        b = np.deg2rad(c.direction_deg)
        return (c.speed + current_var) * np.array([np.cos(b), np.sin(b)])

    def wind_force(self, q: np.ndarray, gust: float) -> np.ndarray:
        """Wind force/moment [N, N, N m] in the body frame (zero when no wind is configured: no
        air drag on the boat's own motion either)."""
        if self._no_wind:
            return np.zeros(3)
        return np.array(_wind_force(*self._wind_args(q, gust)))

    def wave_force(self, q: np.ndarray, t: float) -> np.ndarray:
        """First-order wave force/moment [N, N, N m] in the body frame (two-strip inertia model)."""
        if self.waves is None:
            return np.zeros(3)
        return np.array(_wave_force(*self._wave_args(q, t)))

    def tau_env(self, q: np.ndarray, t: float, gust: float) -> np.ndarray:
        """Wind + waves in one compiled call (the plant asks at every integrator stage)."""
        if self.waves is None or self._no_wind:
            return self.wind_force(q, gust) + self.wave_force(q, t)
        w = _wind_force(*self._wind_args(q, gust))
        f = _wave_force(*self._wave_args(q, t))
        return np.array((w[0] + f[0], w[1] + f[1], w[2] + f[2]))

    def _wind_args(self, q, gust):
        speed = self.cfg.wind.mean_speed + gust
        c, s = self._wind_direction
        return (float(q[2]), float(q[3]), float(q[4]), speed * c, speed * s, *self._wind_gains)

    def _wave_args(self, q, t):
        return (float(q[0]), float(q[1]), float(q[2]), float(t), *self._wave_constants)


@njit(cache=True)
def _wind_force(psi, u, v, vw0, vw1, kx, ky, kn):
    """Wind force in velocity components (see the module docstring): u_rw, v_rw relative air."""
    c, s = math.cos(psi), math.sin(psi)
    u_rw = u - (c * vw0 + s * vw1)
    v_rw = v - (-s * vw0 + c * vw1)
    v_rel = math.hypot(u_rw, v_rw)
    return -kx * u_rw * v_rel, -ky * v_rw * v_rel, kn * u_rw * v_rw


@njit(cache=True)
def _wave_force(x, y, psi, t, half, direction, wavenumber, phase, omega, gain, m11, m22):
    """Both strips (bow x = +L/4, stern x = −L/4) in one pass over the spectrum's components;
    the same sum as wave_acceleration at each strip's point, times half the inertia each."""
    c, s = math.cos(psi), math.sin(psi)
    d0, d1 = math.cos(direction), math.sin(direction)
    along = d0 * x + d1 * y
    offset = half * (d0 * c + d1 * s)
    bow = 0.0
    stern = 0.0
    for i in range(wavenumber.shape[0]):
        base = phase[i] - omega[i] * t
        bow += gain[i] * math.sin(wavenumber[i] * (along + offset) + base)
        stern += gain[i] * math.sin(wavenumber[i] * (along - offset) + base)
    tau0 = tau1 = tau2 = 0.0
    for x_strip, m in ((half, bow), (-half, stern)):
        ax, ay = m * d0, m * d1
        f0 = 0.5 * m11 * (c * ax + s * ay)
        f1 = 0.5 * m22 * (-s * ax + c * ay)
        tau0 += f0
        tau1 += f1
        tau2 += x_strip * f1
    return tau0, tau1, tau2
