"""``PoseSensor``: sampled, noisy [x y ψ r] behind ``pose_measurement``.

It stands in for Roboat II's lidar-SLAM pose and IMU yaw rate: the first four entries of the
measurement vector z = [x y ψ r f1 f2 f3 f4] of Roboat II eq. (8) (the forces come from
``ThrustSensor``). The model is

    z_k = [x y ψ r]ᵀ(t_k) + σ ⊙ w_k   (then ψ wrapped to [−π, π)),   t_k = k / rate,
    w_k ~ N(0, I) keyed by (seed, stream 501, k)

with the defaults σ = (√0.0005 m, √0.0005 m, √0.0005 rad, √0.0001 rad/s) ≈ (0.022, 0.022,
0.022, 0.01): the square roots of the measurement covariance RT⁻¹ of Roboat II eq. (16), so the
NMHE's weights are the true inverse covariances. The heading is wrapped as a SLAM or AHRS heading
is; the estimator unwraps it.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import LeafSystem

from usvdrake.random_streams import white_vector

STREAM_POSE = 501


@dataclass
class PoseSensorConfig:
    rate_hz: float = 10.0  # [Hz] sampling rate (Roboat II §VI: SLAM and estimator at 10 Hz)
    x_std: float = float(np.sqrt(0.0005))  # [m] 1σ east position error (Roboat II eq. 16)
    y_std: float = float(np.sqrt(0.0005))  # [m] 1σ north position error (Roboat II eq. 16)
    psi_std: float = float(np.sqrt(0.0005))  # [rad] 1σ heading error (Roboat II eq. 16)
    r_std: float = float(np.sqrt(0.0001))  # [rad/s] 1σ yaw-rate error (Roboat II eq. 16)

    def std(self) -> np.ndarray:
        """[σ_x, σ_y, σ_ψ, σ_r] [m, m, rad, rad/s]."""
        return np.array([self.x_std, self.y_std, self.psi_std, self.r_std])


def wrap_angle(a):
    """a wrapped to [−π, π) [rad] (float or array)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


def measure_pose(state: np.ndarray, std: np.ndarray, seed: int, k: int) -> np.ndarray:
    """Sample k of [x y ψ r] [m, m, rad, rad/s] from ``state`` = [x y ψ u v r], ψ wrapped."""
    q = np.asarray(state, float)
    z = q[[0, 1, 2, 5]] + std * white_vector(seed, STREAM_POSE, k, 4)
    z[2] = wrap_angle(z[2])
    return z


class PoseSensor(LeafSystem):
    """Samples the pose and yaw rate at ``cfg.rate_hz`` and adds seeded noise.

    .. pydrake_system::

        name: PoseSensor
        input_ports:
        - state
        output_ports:
        - pose_measurement

    ``state`` = [x y ψ u v r] [m, m, rad, m/s, m/s, rad/s]; ``pose_measurement`` = [x y ψ r]
    [m, m, rad, rad/s], ψ in [−π, π). The held sample and the sample counter are discrete state,
    updated periodically from t = 0 (sample k at t = k / rate); before the first update the
    output is zero.
    """

    def __init__(self, cfg: PoseSensorConfig, seed: int):
        super().__init__()
        if cfg.rate_hz <= 0:
            raise ValueError(f"PoseSensorConfig.rate_hz must be positive, got {cfg.rate_hz}")
        std = cfg.std()
        if np.any(std < 0) or not np.all(np.isfinite(std)):
            raise ValueError(f"PoseSensorConfig: stds must be finite and >= 0, got {std}")
        self._std = std
        self._seed = seed
        self._state = self.DeclareVectorInputPort("state", 6)
        self._z = self.DeclareDiscreteState(4)
        self._k = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / cfg.rate_hz, 0.0, self._update)
        self.DeclareStateOutputPort("pose_measurement", self._z)

    def _update(self, context, discrete_state):
        k = int(context.get_discrete_state(self._k).GetAtIndex(0))
        z = measure_pose(self._state.Eval(context), self._std, self._seed, k)
        discrete_state.get_mutable_vector(self._z).SetFromVector(z)
        discrete_state.get_mutable_vector(self._k).SetFromVector([k + 1])
