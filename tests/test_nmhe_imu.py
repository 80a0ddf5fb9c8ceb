"""The IMU in the NMHE: the interval model against the IMU's own measurement model, the
interval means against closed forms, their timing in a diagram, and what the IMU buys the NMHE
under a wave-like force that its model does not know."""

import math
from functools import cache

import numpy as np
import pytest
from test_nmhe import DT, build_diagram, rmse, run_diagram, truth_at

from usvdrake.sensors.imu_model import specific_force
from usvdrake.sensors.messages import ImuSample
from usvdrake.systems.estimation.imu_interval import NAN_MEAN, interval_mean_step, level_imu
from usvdrake.systems.estimation.nmhe_model import NmheConfig, imu_interval_model
from usvdrake.systems.estimation.nmhe_problem import NmheProblem
from usvdrake.systems.slam.lidar_inertial import level_rotation
from usvdrake.vessel import load_vessel

LEVER = (0.4, -0.2)


def nu_of_t(t):
    """A smooth body velocity [u v r] with wave-like wiggles, and its derivative."""
    w = np.array([2.8, 3.5, 3.1])
    a = np.array([0.05, 0.04, 0.1])
    base = np.array([0.6, 0.05, 0.08])
    return base + a * np.sin(w * t), a * w * np.cos(w * t)


def state(t):
    nu, _ = nu_of_t(t)
    return np.array([0.0, 0.0, 0.0, *nu])


def test_interval_model_matches_the_imu_measurement_model():
    """h(q0, q1) against the time average of ``imu_model.specific_force`` (and r) over the
    interval by fine quadrature: within the trapezoid rule's error on the products."""
    for t0 in np.linspace(0.0, 3.0, 7):
        ts = np.linspace(t0, t0 + DT, 2001)
        f = np.array(
            [[*specific_force(state(t), nu_of_t(t)[1], 9.81, LEVER)[:2], state(t)[5]] for t in ts]
        )
        mean = np.trapezoid(f, ts, axis=0) / DT
        h, _, _ = imu_interval_model(state(t0), state(t0 + DT), DT, LEVER)
        assert np.allclose(h[0], mean, atol=2e-3), (h[0], mean)


def test_interval_model_jacobians_match_finite_differences():
    rng = np.random.default_rng(1)
    q0, q1 = rng.normal(size=6), rng.normal(size=6)
    _, j0, j1 = imu_interval_model(q0, q1, DT, LEVER)
    eps = 1e-6
    for i in range(6):
        d = np.zeros(6)
        d[i] = eps
        fd0 = (
            imu_interval_model(q0 + d, q1, DT, LEVER)[0]
            - imu_interval_model(q0 - d, q1, DT, LEVER)[0]
        ) / (2 * eps)
        fd1 = (
            imu_interval_model(q0, q1 + d, DT, LEVER)[0]
            - imu_interval_model(q0, q1 - d, DT, LEVER)[0]
        ) / (2 * eps)
        assert np.allclose(j0[0, :, i], fd0[0], atol=1e-6)
        assert np.allclose(j1[0, :, i], fd1[0], atol=1e-6)


def run_means(stamps, values, interval=DT, max_gap=0.025):
    """Feed readings through ``interval_mean_step``; returns every closed interval's
    [f_x f_y ω_z t_end]."""
    s = np.zeros(12)
    s[4] = np.nan
    s[8:12] = NAN_MEAN
    out = []
    for t, v in zip(stamps, values, strict=True):
        before = s[11]
        s = interval_mean_step(s, t, np.asarray(v, float), interval, max_gap)
        if not (s[11] == before or (np.isnan(s[11]) and np.isnan(before))):
            out.append(s[8:12].copy())
    return np.array(out)


def test_interval_means_are_exact_for_lines_and_close_for_waves():
    # A line is integrated exactly, whatever the stamps (here jittered by up to 3 ms).
    rng = np.random.default_rng(0)
    t = np.sort(0.01 * np.arange(300) + rng.uniform(-0.003, 0.003, 300))
    t[0] = 0.0
    out = run_means(t, np.column_stack([2.0 * t + 1.0, -t, 0.5 * t]))
    ends = out[:, 3]
    assert np.allclose(ends, DT * np.arange(1, len(out) + 1))
    mid = ends - 0.5 * DT
    assert np.allclose(out[:, :3], np.column_stack([2.0 * mid + 1.0, -mid, 0.5 * mid]), atol=1e-12)
    # A 0.5 Hz sine: the trapezoid of 100 Hz samples is within 1e-4 of the exact mean, where
    # averaging the samples stamped in [t_k, t_{k+1}) would lag by half a sample period (5 ms).
    w = math.pi
    t = 0.01 * np.arange(400)
    out = run_means(t, np.column_stack([np.sin(w * t), np.zeros_like(t), np.zeros_like(t)]))
    exact = (np.cos(w * (out[:, 3] - DT)) - np.cos(w * out[:, 3])) / (w * DT)
    assert np.abs(out[:, 0] - exact).max() < 1e-4  # (ω h)²/12 of the 10 ms trapezoids
    naive = np.array(
        [np.sin(w * t[(t >= e - DT - 1e-9) & (t < e - 1e-9)]).mean() for e in out[:, 3]]
    )
    assert np.abs(naive - exact).max() > 50 * np.abs(out[:, 0] - exact).max()


def test_an_interval_with_a_gap_is_missing():
    t = 0.01 * np.arange(60)
    t = np.delete(t, [14, 15, 16])  # 40 ms without readings inside [0.1, 0.2)
    out = run_means(t, np.ones((len(t), 3)))
    assert np.allclose(out[0, :3], 1.0) and np.all(np.isnan(out[1, :3])) and out[1, 3] == 0.2
    assert np.allclose(out[2:, :3], 1.0)


def test_level_imu_takes_out_roll_and_pitch():
    roll, pitch, yaw = math.radians(8.0), math.radians(-5.0), 1.2
    cr, sr, cp, sp = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    tilt = ry @ rx  # level frame ← body
    f_level = np.array([0.3, -0.2, 9.81])  # horizontal acceleration + gravity's reaction
    w_level = np.array([0.0, 0.0, 0.15])
    # quaternion (x y z w) of Rz(yaw) Ry(pitch) Rx(roll)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    cph, sph = math.cos(pitch / 2), math.sin(pitch / 2)
    crh, srh = math.cos(roll / 2), math.sin(roll / 2)
    q = [
        srh * cph * cy - crh * sph * sy,
        crh * sph * cy + srh * cph * sy,
        crh * cph * sy - srh * sph * cy,
        crh * cph * cy + srh * sph * sy,
    ]
    sample = ImuSample(1.0, tilt.T @ w_level, tilt.T @ f_level, np.array(q))
    assert np.allclose(level_imu(sample), [0.3, -0.2, 0.15], atol=1e-12)
    assert ImuSample().is_empty() and not sample.is_empty()


def test_level_imu_is_the_slams_level_rotation():
    """The scalar level_imu applies lidar_inertial.level_rotation(I, q), unnormalised q too."""
    rng = np.random.default_rng(8)
    for _ in range(200):
        q, f, w = rng.normal(size=4), rng.normal(size=3) * 5.0, rng.normal(size=3)
        tilt = level_rotation(np.eye(3), q)
        want = [(tilt @ f)[0], (tilt @ f)[1], (tilt @ w)[2]]
        got = level_imu(ImuSample(0.0, w, f, q))
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


@cache
def wave_runs():
    """40 s of the NMHE diagram under the wave-like force, without and with the IMU, scored
    over the last 20 s (the accelerometer's turn-on bias, 0.02 m/s² here, takes ~20 s to learn:
    accel_bias_std lets it move 2 mm/s² per sample)."""
    out = {}
    for imu in (False, True):
        cfg = NmheConfig(disturbance_std=[30.0, 30.0, 10.0]) if imu else NmheConfig()
        from usvdrake.systems.estimation.nmhe_system import Nmhe

        nmhe = Nmhe(load_vessel("roboat2"), cfg)
        diagram, _, logs = build_diagram(nmhe=nmhe, imu=imu, waves=True)
        _, data = run_diagram(diagram, logs, 40.0)
        err = data["estimate"] - truth_at(data["truth"], data["estimate_time"][:, 0])
        out[imu] = rmse(err[200:])
    return out


def test_the_imu_lets_the_nmhe_follow_wave_motion():
    """The waves move the boat by ~0.05 m/s but only ~1.5 cm, under the pose noise (2.2 cm):
    from poses alone the NMHE cannot see that motion; with the IMU's interval means it can."""
    without, with_imu = wave_runs()[False], wave_runs()[True]
    assert np.all(with_imu[3:5] <= 0.02), with_imu
    assert np.all(with_imu[3:5] < 0.5 * without[3:5]), (with_imu, without)
    assert with_imu[5] < 0.5 * without[5]  # the gyro's yaw rate


def test_imu_means_reach_the_nmhe_for_the_right_interval():
    """At the NMHE's update (t_k + 1 ms) the mean it reads covers [t_{k−1}, t_k), the interval
    that ends at the pose sample just taken; its window holds the means in that row."""
    from pydrake.systems.analysis import Simulator

    diagram, nmhe, _ = build_diagram(imu=True, waves=True)
    sim = Simulator(diagram)
    sim.AdvanceTo(3.0015)  # just after the NMHE's update at 3.001
    ctx = sim.get_context()
    mean = diagram.GetSubsystemByName("imu_mean")
    m = mean.GetOutputPort("imu_mean").Eval(mean.GetMyContextFromRoot(ctx))
    assert m[3] == pytest.approx(3.0)
    window = nmhe.window(nmhe.GetMyContextFromRoot(ctx))
    assert np.array_equal(window.imu[-2], m[:3]) and np.all(np.isnan(window.imu[-1]))
    assert np.all(np.isfinite(window.imu[:-1]))


def test_core_rejects_bad_imu_config_and_windows():
    ves = load_vessel("roboat2")
    for bad in (
        {"accel_std": 0.0},
        {"gyro_std": -1.0},
        {"accel_bias_std": -0.1},
        {"imu_lever_arm": [1.0]},
    ):
        with pytest.raises(ValueError):
            NmheProblem(ves.hydrodynamics, ves.thrusters, NmheConfig(**bad))
    p = NmheProblem(ves.hydrodynamics, ves.thrusters)
    z = np.zeros((p.M, 4))
    u = np.zeros((p.M, 4))
    with pytest.raises(ValueError, match="imu_window"):
        p.solve(z, u, np.zeros(6), imu_window=np.zeros((p.M, 2)))
