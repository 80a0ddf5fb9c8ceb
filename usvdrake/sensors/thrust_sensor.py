"""``ThrustSensor``: sampled, noisy per-thruster feedback behind ``thrust_measured``.

The Roboat II measurement vector z = [x y ψ r f1 f2 f3 f4] (Roboat II eq. 8) includes the four
thruster forces; on the water they come from the ESCs' RPM (T200: F ≈ c n|n|), and the NTNU
vessel measures RPM with Hall-effect sensors (Ueland 2017 §"hardware"). The model is

    z_k = u(t_k) + σ ⊙ w_k,        t_k = k / rate,   w_k ~ N(0, I) keyed by (seed, stream, k)

with u the forces (and azimuth angles) the thrusters really apply, held between samples.

**Noise: an absolute std per entry.** For forces it is a fraction of each thruster's maximum
force, not of the current force: an RPM reading has a roughly constant error (Hall pulse
counting over a 0.1 s window, ESC telemetry jitter) and F ∝ n², so a 1 % RPM error becomes a 2 %
force error near full thrust and a floor of that order elsewhere. The default 2 % of max force
(1 N for Roboat II's ±50 N thrusters, 0.05 N for the NTNU vessel's 2.5 N azimuths) is that
floor. Azimuth angles get ``angle_noise_std`` (an angle encoder or potentiometer, ~1°).
"""

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import LeafSystem

from usvdrake.random_streams import white_vector
from usvdrake.vessel import Thruster

STREAM_THRUST = 301


@dataclass
class ThrustSensorConfig:
    rate_hz: float = 10.0  # [Hz] sampling rate (Roboat II runs its estimator at 10 Hz)
    force_noise_fraction: float = 0.02  # [-] 1σ force error as a fraction of max_force
    angle_noise_std: float = 0.0175  # [rad] 1σ azimuth angle error (1°)


def thrust_noise_scale(thrusters: list[Thruster], cfg: ThrustSensorConfig) -> np.ndarray:
    """Per-entry std of the thruster command layout ([f] fixed, [f, α] azimuth) [N, rad]."""
    scale = []
    for t in thrusters:
        scale.append(cfg.force_noise_fraction * t.max_force)
        if t.azimuth:
            scale.append(cfg.angle_noise_std)
    return np.array(scale)


def measure_thrust(applied: np.ndarray, noise_scale: np.ndarray, seed: int, k: int) -> np.ndarray:
    """z_k = u + σ ⊙ w_k (entries with σ = 0 pass through exactly)."""
    applied = np.asarray(applied, float)
    return applied + noise_scale * white_vector(seed, STREAM_THRUST, k, len(applied))


class ThrustSensor(LeafSystem):
    """Samples the applied thrust at ``cfg.rate_hz`` and adds seeded noise.

    .. pydrake_system::

        name: ThrustSensor
        input_ports:
        - thrust_applied
        output_ports:
        - thrust_measured

    Both ports have the thruster command layout (per thruster [f] or [f, α], [N, rad]);
    ``noise_scale`` gives each entry's std (see :func:`thrust_noise_scale`). The held sample and
    the sample counter are discrete state, updated periodically from t = 0; before the first
    update the output is zero.
    """

    def __init__(self, cfg: ThrustSensorConfig, seed: int, noise_scale: np.ndarray):
        super().__init__()
        if cfg.rate_hz <= 0:
            raise ValueError(f"ThrustSensorConfig.rate_hz must be positive, got {cfg.rate_hz}")
        self._scale = np.array(noise_scale, float)
        self._seed = seed
        n = len(self._scale)
        self._applied = self.DeclareVectorInputPort("thrust_applied", n)
        self._z = self.DeclareDiscreteState(n)
        self._k = self.DeclareDiscreteState(1)
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / cfg.rate_hz, 0.0, self._update)
        self.DeclareStateOutputPort("thrust_measured", self._z)

    def _update(self, context, discrete_state):
        k = int(context.get_discrete_state(self._k).GetAtIndex(0))
        z = measure_thrust(self._applied.Eval(context), self._scale, self._seed, k)
        discrete_state.get_mutable_vector(self._z).SetFromVector(z)
        discrete_state.get_mutable_vector(self._k).SetFromVector([k + 1])
