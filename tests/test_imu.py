"""IMU core: specific force of a turning vessel against its closed form, white noise against the
datasheet density (sample std and Allan deviation), the bias processes, determinism; the ``Imu``
LeafSystem with fixed inputs."""

import dataclasses
import math

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from usvdrake.sensors.imu import Imu
from usvdrake.sensors.imu_model import (
    ImuConfig,
    ImuModel,
    bias_random_walk_density,
    specific_force,
    white_noise_std,
    yaw_quaternion,
)

NOISELESS = ImuConfig(
    gyro_noise_density=0.0,
    gyro_bias_instability=0.0,
    gyro_initial_bias_std=0.0,
    accel_noise_density=0.0,
    accel_bias_instability=0.0,
    accel_initial_bias_std=0.0,
    yaw_std=0.0,
)
# only white noise: no biases, exact heading
WHITE = dataclasses.replace(
    ImuConfig(),
    gyro_bias_instability=0.0,
    gyro_initial_bias_std=0.0,
    accel_bias_instability=0.0,
    accel_initial_bias_std=0.0,
    yaw_std=0.0,
)


def samples(model: ImuModel, q, nu_dot, n: int):
    proc, out = model.initial_processes(), []
    for k in range(n):
        proc, noise = model.step(proc, k)
        out.append(model.sample(q, nu_dot, proc, noise, k * model.period))
    return out


def test_turning_vessel_senses_the_centripetal_specific_force():
    model = ImuModel(NOISELESS, seed=0)
    q = np.array([3.0, 4.0, 0.7, 1.0, 0.0, 0.2])  # u = 1 m/s, r = 0.2 rad/s, steady turn
    s = samples(model, q, np.zeros(3), 3)[-1]
    assert s.linear_acceleration == pytest.approx([0.0, 0.2, 9.81])  # a_y = r u, +g on z
    assert s.angular_velocity == pytest.approx([0.0, 0.0, 0.2])
    assert s.orientation == pytest.approx([0.0, 0.0, math.sin(0.35), math.cos(0.35)])
    assert s.time == pytest.approx(0.02)
    # with sway and accelerations: a = [u̇ − r v, v̇ + r u]
    q = np.array([0.0, 0.0, 0.0, 1.5, -0.3, 0.4])
    f = specific_force(q, np.array([0.1, -0.2, 0.05]), 9.81)
    assert f == pytest.approx([0.1 - 0.4 * -0.3, -0.2 + 0.4 * 1.5, 9.81])


def test_lever_arm_adds_tangential_and_centripetal_terms():
    q = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.2])  # turning on the spot
    f = specific_force(q, np.array([0.0, 0.0, 0.5]), 9.81, lever_arm=(1.0, 0.0))
    # 1 m ahead of the pivot: centripetal −r² towards the pivot, tangential ṙ × l to port
    assert f == pytest.approx([-0.04, 0.5, 9.81])


def test_white_noise_matches_the_datasheet_density():
    cfg = WHITE
    model = ImuModel(cfg, seed=1)
    s = samples(model, np.zeros(6), np.zeros(3), 20000)
    gyro = np.array([x.angular_velocity for x in s])
    accel = np.array([x.linear_acceleration for x in s]) - [0.0, 0.0, 9.81]
    sigma_g = math.radians(0.005) * math.sqrt(100.0)  # 0.05 °/s per sample at 100 Hz
    sigma_a = 20e-6 * 9.80665 * math.sqrt(100.0)
    assert model.noise_std == pytest.approx([sigma_g] * 3 + [sigma_a] * 3)
    assert np.std(gyro, axis=0) == pytest.approx([sigma_g] * 3, rel=0.03)
    assert np.std(accel, axis=0) == pytest.approx([sigma_a] * 3, rel=0.03)
    # Allan deviation of white noise at τ = 1 s (clusters of 100) equals the density / √τ
    for x, density in ((gyro, cfg.gyro_noise_density), (accel, cfg.accel_noise_density)):
        clusters = x.reshape(-1, 100, 3).mean(axis=1)  # 200 clusters × 3 axes
        adev = np.sqrt(0.5 * np.mean(np.diff(clusters, axis=0) ** 2))
        assert adev == pytest.approx(density, rel=0.1)  # standard error ≈ 3 %
    assert white_noise_std(cfg.gyro_noise_density, 400.0) == pytest.approx(2 * sigma_g)


def test_bias_processes():
    # turn-on biases across seeds have the datasheet's initial bias error as their std
    cfg = ImuConfig()
    b0 = np.array([ImuModel(cfg, seed).turn_on_bias for seed in range(400)])
    assert np.std(b0[:, 0]) == pytest.approx(cfg.gyro_initial_bias_std, rel=0.12)
    assert np.std(b0[:, 5]) == pytest.approx(cfg.accel_initial_bias_std, rel=0.12)
    # the in-run bias is stationary with std = bias instability (a fast version: T = 1 s)
    fast = dataclasses.replace(NOISELESS, gyro_bias_instability=0.01, gyro_bias_time_constant=1.0)
    model = ImuModel(fast, seed=2)
    gz = np.array([x.angular_velocity[2] for x in samples(model, np.zeros(6), np.zeros(3), 20000)])
    assert np.std(gz) == pytest.approx(0.01, rel=0.1)
    assert np.corrcoef(gz[:-100], gz[100:])[0, 1] == pytest.approx(np.exp(-1), abs=0.08)
    # equivalent random walk for t ≪ T: σ √(2/T)
    assert bias_random_walk_density(0.01, 200.0) == pytest.approx(0.001)


def test_heading_error_has_its_std():
    cfg = dataclasses.replace(NOISELESS, yaw_std=0.02, yaw_time_constant=0.0)  # white
    s = samples(ImuModel(cfg, seed=3), np.array([0, 0, 1.0, 0, 0, 0]), np.zeros(3), 4000)
    yaw = np.array([2 * math.atan2(x.orientation[2], x.orientation[3]) for x in s])
    assert np.mean(yaw) == pytest.approx(1.0, abs=0.002)
    assert np.std(yaw) == pytest.approx(0.02, rel=0.05)
    assert yaw_quaternion(np.pi) == pytest.approx([0, 0, 1, 0], abs=1e-12)


def test_same_seed_same_samples():
    q, a = np.array([0, 0, 0.1, 1.0, 0.1, 0.05]), np.array([0.01, 0.0, 0.0])
    s1, s2 = (
        samples(ImuModel(ImuConfig(), 4), q, a, 20),
        samples(ImuModel(ImuConfig(), 4), q, a, 20),
    )
    s3 = samples(ImuModel(ImuConfig(), 5), q, a, 20)
    for x, y, z in zip(s1, s2, s3, strict=True):
        assert np.array_equal(x.angular_velocity, y.angular_velocity)
        assert np.array_equal(x.linear_acceleration, y.linear_acceleration)
        assert np.array_equal(x.orientation, y.orientation)
        assert not np.array_equal(x.linear_acceleration, z.linear_acceleration)


def test_imu_system_samples_at_its_rate_from_its_inputs():
    results = []
    for _ in range(2):
        imu = Imu(ImuConfig(), seed=6)
        sim = Simulator(imu)
        ctx = sim.get_mutable_context()
        imu.GetInputPort("state").FixValue(ctx, np.array([0, 0, 0.3, 1.0, 0.0, 0.2]))
        imu.GetInputPort("acceleration").FixValue(ctx, np.zeros(3))
        sim.AdvanceTo(0.505)
        s = imu.GetOutputPort("imu").Eval(sim.get_context())
        assert s.time == pytest.approx(0.5)  # 100 Hz from t = 0
        assert s.linear_acceleration == pytest.approx([0.0, 0.2, 9.81], abs=0.1)
        assert s.angular_velocity[2] == pytest.approx(0.2, abs=0.01)
        results.append(s)
    assert np.array_equal(results[0].linear_acceleration, results[1].linear_acceleration)
    noiseless = Imu(NOISELESS, seed=0)
    sim = Simulator(noiseless)
    ctx = sim.get_mutable_context()
    noiseless.GetInputPort("state").FixValue(ctx, np.array([0, 0, 0.3, 1.0, 0.0, 0.2]))
    noiseless.GetInputPort("acceleration").FixValue(ctx, np.array([0.1, 0.0, 0.0]))
    sim.AdvanceTo(0.015)
    s = noiseless.GetOutputPort("imu").Eval(sim.get_context())
    assert s.linear_acceleration == pytest.approx([0.1, 0.2, 9.81])
    assert s.time == pytest.approx(0.01)
