"""Thrust sensor: per-entry noise scale from the vessel files, noise statistics, pass-through of
unperturbed entries, sampling at the sensor rate, determinism."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from usvdrake.sensors.thrust_sensor import (
    ThrustSensor,
    ThrustSensorConfig,
    measure_thrust,
    thrust_noise_scale,
)
from usvdrake.vessel import load_vessel


def test_noise_scale_follows_the_command_layout():
    cfg = ThrustSensorConfig()
    assert thrust_noise_scale(load_vessel("roboat2").thrusters, cfg) == pytest.approx([1.0] * 4)
    az = thrust_noise_scale(load_vessel("ntnu_round").thrusters, cfg)  # [f, α] per azimuth
    assert az == pytest.approx([0.05, 0.0175] * 3)


def test_noise_statistics_and_exact_unperturbed_entries():
    u = np.array([10.0, -20.0, 1.5, 0.3])
    scale = np.array([1.0, 0.5, 0.0, 0.02])
    z = np.array([measure_thrust(u, scale, seed=3, k=k) for k in range(5000)])
    assert np.all(z[:, 2] == 1.5)
    assert np.mean(z, axis=0) == pytest.approx(u, abs=0.05)
    assert np.std(z[:, [0, 1, 3]], axis=0) == pytest.approx(scale[[0, 1, 3]], rel=0.04)
    assert np.array_equal(measure_thrust(u, scale, 3, 17), z[17])  # keyed by (seed, k)
    assert not np.array_equal(measure_thrust(u, scale, 4, 17), z[17])


def test_thrust_sensor_samples_and_holds_at_its_rate():
    scale = np.array([1.0, 1.0, 0.0, 0.0])
    u = np.array([5.0, -5.0, 2.0, 0.0])
    outputs = []
    for _ in range(2):
        sensor = ThrustSensor(ThrustSensorConfig(rate_hz=10.0), seed=8, noise_scale=scale)
        sim = Simulator(sensor)
        sensor.GetInputPort("thrust_applied").FixValue(sim.get_mutable_context(), u)
        assert np.all(sensor.GetOutputPort("thrust_measured").Eval(sim.get_context()) == 0)
        sim.AdvanceTo(0.25)  # samples at 0, 0.1, 0.2: the output holds sample k = 2
        z = sensor.GetOutputPort("thrust_measured").Eval(sim.get_context())
        assert np.array_equal(z, measure_thrust(u, scale, 8, 2))
        assert z[2:] == pytest.approx([2.0, 0.0], abs=0)
        outputs.append(z.copy())
    assert np.array_equal(outputs[0], outputs[1])
