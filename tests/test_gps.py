"""GPS core: outages, noise statistics against the configured stds, degradation, the altitude
bias, determinism; the ``Gps`` LeafSystem in a small diagram."""

import dataclasses

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from usvdrake.sensors.gps import Gps
from usvdrake.sensors.gps_model import GpsConfig, GpsModel, world_velocity

WHITE = GpsConfig(noise_time_constant=0.0, altitude_error_std=0.0)
POS, VEL = np.array([120.0, -40.0]), np.array([1.0, 0.5])


def run(model: GpsModel, n: int, sky_blocked: float = 0.0, denied: bool = False):
    """n consecutive fixes at a fixed true position and velocity."""
    errors, fixes = model.initial_errors(), []
    for k in range(n):
        errors = model.step_errors(errors, k)
        fixes.append(model.fix(errors, POS, VEL, k, denied=denied, sky_blocked=sky_blocked))
    return fixes


def enu_errors(model: GpsModel, fixes) -> np.ndarray:
    lat, lon, h = (
        np.array([getattr(f, a) for f in fixes]) for a in ("latitude", "longitude", "altitude")
    )
    e, n, u = model.frame.to_local(lat, lon, h)
    return np.column_stack([e - POS[0], n - POS[1], u - model.cfg.antenna_height])


def test_denied_fixes_are_all_invalid():
    fixes = run(GpsModel(GpsConfig(), seed=1), 300, denied=True)
    assert not any(f.valid for f in fixes)
    assert all(f.satellites == 0 for f in fixes)
    assert [f.time for f in fixes[:3]] == pytest.approx([0.0, 0.2, 0.4])
    fixes = run(GpsModel(dataclasses.replace(GpsConfig(), enabled=False), seed=1), 10)
    assert not any(f.valid for f in fixes)


def test_white_noise_matches_the_configured_std_and_the_reported_covariance():
    model = GpsModel(WHITE, seed=2)
    fixes = run(model, 4000)
    assert all(f.valid for f in fixes)
    err = enu_errors(model, fixes)
    # sample std of 4000 normals: relative standard error 1/√8000 ≈ 1.1 %
    assert np.std(err, axis=0) == pytest.approx([1.5, 1.5, 3.0], rel=0.05)
    assert np.abs(np.mean(err, axis=0)).max() < 0.15
    assert np.diag(fixes[-1].covariance_enu) == pytest.approx([1.5**2, 1.5**2, 3.0**2])
    assert abs(np.corrcoef(err[:-1, 0], err[1:, 0])[0, 1]) < 0.05  # white: uncorrelated
    # speed and course over ground: Doppler noise 0.05 m/s per axis around the true velocity
    speed = np.array([f.speed for f in fixes])
    course = np.array([f.course for f in fixes])
    assert np.mean(speed) == pytest.approx(np.hypot(*VEL), abs=0.005)
    assert np.std(speed) == pytest.approx(0.05, rel=0.08)
    assert np.mean(course) == pytest.approx(np.arctan2(VEL[1], VEL[0]), abs=0.005)


def test_position_noise_is_gauss_markov_with_its_time_constant():
    cfg = GpsConfig()  # 30 s at 5 Hz: lag 150 samples = one time constant
    model = GpsModel(cfg, seed=3)
    errors, xs = model.initial_errors(), np.empty((30000, 4))
    for k in range(len(xs)):
        errors = model.step_errors(errors, k)
        xs[k] = errors
    assert np.std(xs[:, :3], axis=0) == pytest.approx([1.0, 1.0, 1.0], rel=0.15)
    lag = 150
    r = np.corrcoef(xs[:-lag, 0], xs[lag:, 0])[0, 1]
    assert r == pytest.approx(np.exp(-1), abs=0.1)


def test_blocked_sky_degrades_noise_satellites_and_hdop():
    model = GpsModel(WHITE, seed=4)
    open_sky, canyon = run(model, 2000), run(model, 2000, sky_blocked=1.0)
    std_open = np.std(enu_errors(model, open_sky)[:, :2])
    std_canyon = np.std(enu_errors(model, canyon)[:, :2])
    assert std_canyon / std_open == pytest.approx(WHITE.degraded_std_factor, rel=0.05)
    assert np.diag(canyon[0].covariance_enu)[0] == pytest.approx((5 * 1.5) ** 2)
    half = run(model, 1, sky_blocked=0.5)[0]
    assert open_sky[0].satellites > half.satellites > canyon[0].satellites >= 4
    assert open_sky[0].hdop < half.hdop < canyon[0].hdop
    assert half.covariance_enu[0, 0] == pytest.approx((3 * 1.5) ** 2)  # s = 1 + 4 × 0.5


def test_altitude_bias_statistics():
    # a fast version of the process to check its stationary std and its reported variance
    cfg = dataclasses.replace(
        GpsConfig(), vertical_std=0.0, altitude_error_std=20.0, altitude_error_time_constant=4.0
    )
    model = GpsModel(cfg, seed=5)
    errors, b = model.initial_errors(), []
    for k in range(20000):
        errors = model.step_errors(errors, k)
        b.append(errors[3])
    assert b[0] != 0.0 and abs(b[0]) < 20.0  # starts from 0: one step of growth
    assert np.std(b[1000:]) == pytest.approx(20.0, rel=0.1)
    assert model.altitude_bias_variance(0) == pytest.approx(400 * (1 - np.exp(-2 * 0.2 / 4)))
    assert model.altitude_bias_variance(10**6) == pytest.approx(400.0)
    assert model.covariance_enu(10**6)[2, 2] == pytest.approx(400.0)


def test_default_altitude_error_reaches_tens_of_metres_over_three_hours():
    """Roboat II §VI-A: "altitude errors approximating 100 m" over a 3-hour run."""
    cfg = dataclasses.replace(GpsConfig(), rate_hz=1.0)
    peaks = []
    for seed in range(4):
        model = GpsModel(cfg, seed)
        errors, peak = model.initial_errors(), 0.0
        for k in range(3 * 3600):
            errors = model.step_errors(errors, k)
            peak = max(peak, abs(errors[3]))
        peaks.append(peak)
    assert 40.0 < np.mean(peaks) < 200.0


def test_same_seed_same_fixes_other_seed_other_fixes():
    a, b = run(GpsModel(GpsConfig(), 7), 50), run(GpsModel(GpsConfig(), 7), 50)
    c = run(GpsModel(GpsConfig(), 8), 50)
    for fa, fb in zip(a, b, strict=True):
        assert (fa.latitude, fa.longitude, fa.altitude, fa.speed) == (
            fb.latitude,
            fb.longitude,
            fb.altitude,
            fb.speed,
        )
    assert all(fa.latitude != fc.latitude for fa, fc in zip(a, c, strict=True))
    # the noise of step k does not depend on what was evaluated before
    m = GpsModel(GpsConfig(), 7)
    e = m.initial_errors()
    late = m.step_errors(e, 40)
    m.step_errors(e, 3)
    assert np.array_equal(m.step_errors(e, 40), late)


def gps_diagram(gps: Gps):
    builder = DiagramBuilder()
    builder.AddNamedSystem("gps", gps)
    builder.ExportInput(gps.GetInputPort("state"), "state")
    builder.ExportOutput(gps.GetOutputPort("gps"), "gps")
    return builder.Build()


def test_gps_system_fixes_at_its_rate_and_repeats_itself():
    q = np.array([30.0, 10.0, 0.5, 1.0, 0.2, 0.0])
    results = []
    for _ in range(2):
        diagram = gps_diagram(Gps(GpsConfig(rate_hz=5.0), seed=9))
        sim = Simulator(diagram)
        diagram.get_input_port(0).FixValue(sim.get_mutable_context(), q)
        assert not diagram.get_output_port(0).Eval(sim.get_context()).valid  # before any fix
        times = []
        for t in np.arange(0.05, 2.06, 0.05):
            sim.AdvanceTo(t)
            fix = diagram.get_output_port(0).Eval(sim.get_context())
            if not times or fix.time != times[-1]:
                times.append(fix.time)
        results.append(fix)
        assert times == pytest.approx(np.arange(0.0, 2.01, 0.2))
        assert fix.valid and fix.speed == pytest.approx(np.hypot(1.0, 0.2), abs=0.3)
    assert results[0].latitude == results[1].latitude  # state in the Context, seeded
    assert results[0].altitude == results[1].altitude
    assert world_velocity(q) == pytest.approx(
        [np.cos(0.5) - 0.2 * np.sin(0.5), np.sin(0.5) + 0.2 * np.cos(0.5)]
    )


def test_gps_system_is_invalid_in_the_denied_region():
    gps = Gps(
        GpsConfig(rate_hz=10.0), seed=1, denied=lambda x, y: x > 0.0, sky_blocked=lambda x, y: 0.5
    )
    sim = Simulator(gps)
    ctx = sim.get_mutable_context()
    gps.GetInputPort("state").FixValue(ctx, np.array([5.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    for t in np.arange(0.05, 1.0, 0.1):
        sim.AdvanceTo(t)
        assert not gps.GetOutputPort("gps").Eval(sim.get_context()).valid
    gps.GetInputPort("state").FixValue(ctx, np.array([-5.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    sim.AdvanceTo(1.15)
    fix = gps.GetOutputPort("gps").Eval(sim.get_context())
    assert fix.valid and fix.covariance_enu[0, 0] == pytest.approx((3 * 1.5) ** 2)
