"""A MEMS IMU/AHRS on a planar vessel as seeded random processes (numerical core of ``Imu``).

Measurement model in the body frame (x forward, y left, z up), sample k at t_k = k / rate:

    ω̃ = [0, 0, r]ᵀ + b_g⁰ + b_g,k + n_g,k                                   [rad/s]
    f̃ = [u̇ − r v − ṙ l_y − r² l_x,  v̇ + r u + ṙ l_x − r² l_y,  g]ᵀ + b_a⁰ + b_a,k + n_a,k   [m/s²]
    q̃ = quaternion of yaw ψ + δψ_k (roll = pitch = 0), order x y z w

* f is the **specific force** (what an accelerometer senses: acceleration minus gravity, so
  +g on z at rest in a z-up frame). For planar motion the body-frame acceleration of the origin
  is ν̇ + ω × ν = [u̇ − r v, v̇ + r u, 0] (Fossen 2011 §3.3, ω = [0, 0, r]); an IMU mounted at
  the lever arm l = (l_x, l_y) adds the tangential ṙ × l and centripetal −r² l terms. A vessel
  turning at r = 0.2 rad/s at u = 1 m/s therefore senses f_y = +0.2 m/s² (towards the centre
  of the turn, to port for a left turn).
* n_g, n_a: white noise. A datasheet gives the continuous-time **noise density** σ_c
  [unit/√Hz]; sampled at ``rate_hz`` (the sensor integrates over the sample interval Δt) the
  per-sample std is σ_d = σ_c / √Δt = σ_c √rate (Kalibr IMU noise model).
* b⁰: turn-on bias, constant over a run, drawn once from the seed ("initial bias error").
* b_k: in-run bias, first-order Gauss-Markov with stationary std = the datasheet's **bias
  instability** and correlation time T, stepped exactly: b_{k+1} = φ b_k + σ √(1 − φ²) w_k,
  φ = e^{−Δt/T}. For t ≪ T it is a random walk of density σ √(2/T) [unit/s/√Hz] (per step
  σ_rw √Δt), which :func:`bias_random_walk_density` returns for estimators that model a walk
  (gtsam's ``PreintegrationParams``).
* δψ: the AHRS heading error, Gauss-Markov with std ``yaw_std`` and time constant
  ``yaw_time_constant`` (magnetic disturbances near steel quays and bridges change slowly);
  0 gives white noise.

Default numbers: **LORD/HBK MicroStrain 3DM-GX5-25** AHRS — the IMU of LIO-SAM's datasets
(Shan et al. 2020), the lidar-inertial SLAM the Roboat II system follows (Roboat II §V). Datasheet
8400-0093 rev N: gyro noise density 0.005 °/s/√Hz, bias instability 8 °/h, initial bias error
±0.04 °/s; accelerometer noise density 20 µg/√Hz (0.00002 g/√Hz), bias instability 0.04 mg,
initial bias error ±0.002 g; EKF heading accuracy ±0.8° RMS. The two noise densities are as
quoted from rev N by the DARPA SubT virtual-vehicle docs (MARBLE Husky, 3DM-GX5-25); NOT checked
against the datasheet itself here (another secondary summary gives 80 µg/√Hz for the
accelerometer); the initial bias errors and the heading accuracy are read as 1σ. Re-check all
of these against the current datasheet revision before trusting absolute noise levels. The
correlation times are not on the datasheet: 300 s (bias) and 20 s
(heading) are modelling choices.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from usvdrake.random_streams import white_vector
from usvdrake.sensors.gps_model import gauss_markov_phi
from usvdrake.sensors.messages import ImuSample

STANDARD_GRAVITY = 9.80665  # [m/s^2] the "g" of datasheets (µg, mg)
STREAM_IMU_INITIAL, STREAM_IMU = 201, 202


@dataclass
class ImuConfig:
    enabled: bool = True  # the station builder adds the IMU only if True
    rate_hz: float = 100.0  # [Hz] sample rate (3DM-GX5-25: up to 1000 Hz IMU data)
    gyro_noise_density: float = math.radians(0.005)  # [rad/s/√Hz] 0.005 °/s/√Hz
    gyro_bias_instability: float = math.radians(8.0) / 3600.0  # [rad/s] 8 °/h
    gyro_bias_time_constant: float = 300.0  # [s] Gauss-Markov correlation of the in-run bias
    gyro_initial_bias_std: float = math.radians(0.04)  # [rad/s] turn-on bias, ±0.04 °/s
    accel_noise_density: float = 20e-6 * STANDARD_GRAVITY  # [m/s^2/√Hz] 20 µg/√Hz
    accel_bias_instability: float = 0.04e-3 * STANDARD_GRAVITY  # [m/s^2] 0.04 mg
    accel_bias_time_constant: float = 300.0  # [s] Gauss-Markov correlation of the in-run bias
    accel_initial_bias_std: float = 0.002 * STANDARD_GRAVITY  # [m/s^2] turn-on bias, ±0.002 g
    yaw_std: float = math.radians(0.8)  # [rad] AHRS heading error (EKF heading ±0.8° RMS)
    yaw_time_constant: float = 20.0  # [s] correlation time of the heading error; 0: white
    gravity: float = 9.81  # [m/s^2] local gravity sensed on z (the plant's g)
    lever_arm: list[float] = field(default_factory=lambda: [0.0, 0.0])  # [m] IMU at (x fwd, y left)


def white_noise_std(density: float, rate_hz: float) -> float:
    """Per-sample std σ_d = σ_c √rate of white noise of density σ_c [unit/√Hz]."""
    return density * math.sqrt(rate_hz)


def bias_random_walk_density(std: float, time_constant: float) -> float:
    """Random-walk density σ √(2/T) [unit/s/√Hz] matching a Gauss-Markov bias (std σ, time
    constant T) over times much shorter than T."""
    return std * math.sqrt(2.0 / time_constant) if time_constant > 0 else 0.0


def specific_force(q: np.ndarray, nu_dot: np.ndarray, gravity: float, lever_arm=(0.0, 0.0)):
    """Body-frame specific force [m/s²] of a planar vessel at the lever arm (see module doc).

    q = [x y ψ u v r], nu_dot = [u̇ v̇ ṙ] (Roboat II eq. 2)."""
    u, v, r = q[3], q[4], q[5]
    du, dv, dr = nu_dot[0], nu_dot[1], nu_dot[2]
    lx, ly = lever_arm[0], lever_arm[1]
    return np.array([du - r * v - dr * ly - r * r * lx, dv + r * u + dr * lx - r * r * ly, gravity])


def yaw_quaternion(yaw: float) -> np.ndarray:
    """Unit quaternion [x y z w] of a rotation by ``yaw`` [rad] about z."""
    return np.array([0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)])


class ImuModel:
    """Samples of one IMU. Immutable (the turn-on biases are fixed by the seed); the random
    process states ``processes`` = [b_g (3), b_a (3), δψ] are passed in and out."""

    def __init__(self, cfg: ImuConfig, seed: int):
        if cfg.rate_hz <= 0:
            raise ValueError(f"ImuConfig.rate_hz must be positive, got {cfg.rate_hz}")
        self.cfg, self.seed = cfg, seed
        self.period = 1.0 / cfg.rate_hz  # [s]
        h = self.period
        sigma = np.array(
            [cfg.gyro_bias_instability] * 3 + [cfg.accel_bias_instability] * 3 + [cfg.yaw_std]
        )
        tau = [cfg.gyro_bias_time_constant] * 3 + [cfg.accel_bias_time_constant] * 3
        self._phi = np.array([gauss_markov_phi(h, t) for t in tau + [cfg.yaw_time_constant]])
        self._sigma = sigma
        self._drive = sigma * np.sqrt(1.0 - self._phi**2)
        self.noise_std = np.array(  # per-sample white-noise std, gyro then accel
            [white_noise_std(cfg.gyro_noise_density, cfg.rate_hz)] * 3
            + [white_noise_std(cfg.accel_noise_density, cfg.rate_hz)] * 3
        )
        w0 = white_vector(seed, STREAM_IMU_INITIAL, 0, 13)
        turn_on = np.array([cfg.gyro_initial_bias_std] * 3 + [cfg.accel_initial_bias_std] * 3)
        self.turn_on_bias = turn_on * w0[:6]  # [rad/s ×3, m/s² ×3]
        self._initial = sigma * w0[6:]  # in-run processes start stationary

    def initial_processes(self) -> np.ndarray:
        """[b_g, b_a, δψ] before the first sample, drawn from their stationary distribution."""
        return self._initial.copy()

    def step(self, processes: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(processes at sample k, white noise of sample k [gyro ×3, accel ×3])."""
        w = white_vector(self.seed, STREAM_IMU, k, 13)
        new = self._phi * np.asarray(processes, float) + self._drive * w[:7]
        return new, self.noise_std * w[7:]

    def sample(
        self, q: np.ndarray, nu_dot: np.ndarray, processes: np.ndarray, noise: np.ndarray, t: float
    ) -> ImuSample:
        """The sample at time t [s] from the true state q, ν̇ = [u̇ v̇ ṙ] and the errors."""
        bias = self.turn_on_bias + processes[:6]
        gyro = np.array([0.0, 0.0, q[5]]) + bias[:3] + noise[:3]
        accel = specific_force(q, nu_dot, self.cfg.gravity, self.cfg.lever_arm)
        accel = accel + bias[3:] + noise[3:]
        return ImuSample(
            time=t,
            angular_velocity=gyro,
            linear_acceleration=accel,
            orientation=yaw_quaternion(float(q[2]) + float(processes[6])),
        )
