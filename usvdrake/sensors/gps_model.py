"""A standalone GNSS receiver as seeded random processes (numerical core of ``Gps``).

Measurement model, at fix k (time t_k = k / rate):

    p̃_E = x + s σ_h ε_E,k      p̃_N = y + s σ_h ε_N,k      p̃_U = z_a + s σ_v ε_U,k + b_k
    ṽ   = R(ψ) [u, v]ᵀ + s σ_vel w_k            (Doppler velocity → speed and course over ground)

* (x, y): true position in the world ENU frame; z_a the antenna height above the water (datum).
* ε_E, ε_N, ε_U: **unit first-order Gauss-Markov** processes (correlation time T_n), started in
  their stationary distribution. Standalone GNSS position errors are not white: multipath and
  residual ionospheric/tropospheric delays make a static receiver's fix wander over tens of
  seconds to minutes. White noise at 5 Hz would average down to centimetres within seconds in an
  estimator, which a real receiver never allows; the Gauss-Markov process keeps the simulated
  estimator as humble as the real one. ``noise_time_constant = 0`` gives white noise.
* b: a slow **altitude bias**, Gauss-Markov with std σ_b and time constant T_b, starting at 0 —
  the "altitude errors approximating 100 m" over the 3-hour Amsterdam run of Roboat II §VI-A. With
  σ_b = 50 m and T_b = 30 min the error wanders to ±50-100 m within the first hour.
* s = 1 + (κ − 1) β: the urban-canyon degradation for β ∈ [0, 1] the fraction of the sky above
  30° elevation hidden by buildings and κ = ``degraded_std_factor``. It scales the position and
  velocity noise and the HDOP; the satellite count falls from ``satellites_open_sky`` towards 4.
  Outages are not emergent: a fix is invalid exactly where the ``denied`` flag says so (bridges,
  tunnels), so a scenario controls them explicitly. The error processes keep running through an
  outage, as the physical error sources do.

``covariance_enu`` is the true covariance of the model's error at that fix: diag(s²σ_h², s²σ_h²,
s²σ_v² + σ_b²(1 − e^{−2 t_b/T_b})) with t_b = (k + 1)/rate the age of the altitude bias — what an
ideally calibrated receiver would report, so an estimator trusting it is statistically consistent.

Every Gauss-Markov step is the exact discretisation x_{k+1} = φ x_k + σ √(1 − φ²) w_k,
φ = e^{−h/T} (as ``environment_model.gauss_markov_step``), with w_k from a generator keyed by
(seed, stream, k): the same seed gives bit-identical fixes in any evaluation order.
"""

import math
from dataclasses import dataclass

import numpy as np

from usvdrake.random_streams import white_vector
from usvdrake.sensors.geodesy import LocalFrame
from usvdrake.sensors.messages import GpsFix

# Random streams of the sensors (the environment uses 1-3; keep the sensors clear of them).
STREAM_GPS_INITIAL, STREAM_GPS_POSITION, STREAM_GPS_VELOCITY = 101, 102, 103


@dataclass
class GpsConfig:
    enabled: bool = True  # False: the receiver never has a fix (every output invalid)
    datum: str = ""  # origin of the world ENU frame, a name in geodesy.DATUMS; "": the world's
    # [Hz] fix rate. u-blox M8/F9 receivers navigate at 1-10 Hz (F9P up to 20 Hz); 5 Hz leaves
    # SLAM's 10 Hz keyframes (Roboat II §VI) a fresh fix every other frame.
    rate_hz: float = 5.0
    # [m] 1σ per horizontal axis, open sky. u-blox ZED-F9P standalone: 1.5 m CEP; NEO-M8N:
    # 2.5 m CEP; CEP = 1.1774 σ for a circular normal → 1.3-2.1 m. 1.5 m sits between them.
    horizontal_std: float = 1.5
    vertical_std: float = 3.0  # [m] 1σ fast vertical noise, open sky (GNSS VDOP ≈ 2 × HDOP)
    noise_time_constant: float = 30.0  # [s] correlation time of the position noise; 0: white
    # [m] stationary std of the slow altitude bias; with the 30 min time constant it reaches
    # the ~100 m altitude errors Roboat II §VI-A reports over 3 hours (2σ).
    altitude_error_std: float = 50.0
    altitude_error_time_constant: float = 1800.0  # [s] correlation time of that bias
    # [-] noise multiplier when the whole sky above 30° is blocked. Urban-canyon fixes are
    # 5-10× worse than open-sky ones (multipath and non-line-of-sight signals).
    degraded_std_factor: float = 5.0
    velocity_std: float = 0.05  # [m/s] 1σ per axis of the Doppler velocity (u-blox M8/F9: 0.05)
    antenna_height: float = 1.0  # [m] antenna above the waterline (mast on a small USV)
    satellites_open_sky: int = 16  # [-] satellites used with open sky (multi-constellation)
    hdop_open_sky: float = 0.8  # [-] horizontal dilution of precision with open sky


def gauss_markov_phi(period: float, time_constant: float) -> float:
    """φ = e^{−h/T} of the exact Gauss-Markov step; T ≤ 0 means white noise (φ = 0)."""
    return math.exp(-period / time_constant) if time_constant > 0 else 0.0


def degradation(cfg: GpsConfig, sky_blocked: float) -> float:
    """s = 1 + (κ − 1) β, the noise multiplier for a blocked sky fraction β ∈ [0, 1]."""
    beta = min(max(float(sky_blocked), 0.0), 1.0)
    return 1.0 + (cfg.degraded_std_factor - 1.0) * beta


class GpsModel:
    """Fixes for one receiver. Immutable; the error states (``errors`` = [ε_E, ε_N, ε_U, b]:
    three unit Gauss-Markov states and the altitude bias [m]) are passed in and out."""

    def __init__(self, cfg: GpsConfig, seed: int):
        if cfg.rate_hz <= 0:
            raise ValueError(f"GpsConfig.rate_hz must be positive, got {cfg.rate_hz}")
        self.cfg, self.seed = cfg, seed
        # "" means the world's datum; the station fills it in, a bare model uses Amsterdam.
        self.frame = LocalFrame(cfg.datum or "amsterdam")
        self.period = 1.0 / cfg.rate_hz  # [s]
        phi_n = gauss_markov_phi(self.period, cfg.noise_time_constant)
        self._phi = np.array(
            [phi_n, phi_n, phi_n, gauss_markov_phi(self.period, cfg.altitude_error_time_constant)]
        )
        self._drive = np.sqrt(1.0 - self._phi**2) * np.array(
            [1.0, 1.0, 1.0, cfg.altitude_error_std]
        )

    def initial_errors(self) -> np.ndarray:
        """Errors before the first fix: noise drawn stationary, altitude bias 0."""
        return np.append(white_vector(self.seed, STREAM_GPS_INITIAL, 0, 3), 0.0)

    def step_errors(self, errors: np.ndarray, k: int) -> np.ndarray:
        """Errors at fix k from those at fix k − 1 (one exact Gauss-Markov step each)."""
        w = white_vector(self.seed, STREAM_GPS_POSITION, k, 4)
        return self._phi * np.asarray(errors, float) + self._drive * w

    def altitude_bias_variance(self, k: int) -> float:
        """σ_b²(1 − φ_b^{2(k+1)}): variance of the bias after k + 1 steps from 0 [m²]."""
        phi = self._phi[3]
        return self.cfg.altitude_error_std**2 * (1.0 - phi ** (2 * (k + 1)))

    def covariance_enu(self, k: int, sky_blocked: float = 0.0) -> np.ndarray:
        """True error covariance of fix k [m²] (E, N, U)."""
        s = degradation(self.cfg, sky_blocked)
        h2 = (s * self.cfg.horizontal_std) ** 2
        v2 = (s * self.cfg.vertical_std) ** 2 + self.altitude_bias_variance(k)
        return np.diag([h2, h2, v2])

    def fix(
        self,
        errors: np.ndarray,
        position: np.ndarray,
        velocity: np.ndarray,
        k: int,
        denied: bool = False,
        sky_blocked: float = 0.0,
    ) -> GpsFix:
        """The fix k given the errors at k (``step_errors``), the true ENU ``position`` [x, y] [m]
        and world ``velocity`` [v_E, v_N] [m/s]."""
        cfg = self.cfg
        t = k * self.period
        if denied or not cfg.enabled:
            return GpsFix(time=t, valid=False, hdop=99.0, satellites=0)
        s = degradation(cfg, sky_blocked)
        e = position[0] + s * cfg.horizontal_std * errors[0]
        n = position[1] + s * cfg.horizontal_std * errors[1]
        u = cfg.antenna_height + s * cfg.vertical_std * errors[2] + errors[3]
        lat, lon, h = self.frame.to_geodetic(e, n, u)
        wv = white_vector(self.seed, STREAM_GPS_VELOCITY, k, 2)
        v = np.asarray(velocity, float)[:2] + s * cfg.velocity_std * wv
        beta = min(max(float(sky_blocked), 0.0), 1.0)
        satellites = 4 + round((cfg.satellites_open_sky - 4) * (1.0 - beta))
        return GpsFix(
            time=t,
            valid=True,
            latitude=lat,
            longitude=lon,
            altitude=h,
            covariance_enu=self.covariance_enu(k, sky_blocked),
            hdop=cfg.hdop_open_sky * s,
            satellites=int(satellites),
            speed=float(np.hypot(v[0], v[1])),
            course=float(np.arctan2(v[1], v[0])),
        )


def world_velocity(q: np.ndarray) -> np.ndarray:
    """[v_E, v_N] [m/s] of a vessel state q = [x y ψ u v r] (Roboat II eq. 1)."""
    c, s = np.cos(q[2]), np.sin(q[2])
    return np.array([c * q[3] - s * q[4], s * q[3] + c * q[4]])
