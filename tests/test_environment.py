"""Environment core: spectra and processes against closed forms; the LeafSystem is seeded."""

import dataclasses

import numpy as np
import pytest
from scipy.integrate import quad

from usvdrake.scenario import EnvironmentConfig, WaveConfig, WindConfig
from usvdrake.systems.vessel.environment import Environment
from usvdrake.systems.vessel.environment_model import (
    EnvironmentModel,
    gauss_markov_step,
    make_waves,
    pierson_moskowitz,
    wave_acceleration,
    white_sample,
)
from usvdrake.vessel import load_vessel


def test_pm_spectrum_zeroth_moment_is_hs2_over_16():
    hs, tp = 0.3, 2.5
    m0, _ = quad(pierson_moskowitz, 0.05, 60.0, args=(hs, tp), limit=200)
    assert m0 == pytest.approx(hs**2 / 16, rel=1e-3)


def test_pm_peak_at_tp():
    w = np.linspace(0.5, 10, 20000)
    assert w[np.argmax(pierson_moskowitz(w, 1.0, 2.0))] == pytest.approx(2 * np.pi / 2.0, rel=1e-3)


def test_wave_components_carry_the_spectrum_energy():
    waves = make_waves(WaveConfig(significant_height=0.2, peak_period=2.0, components=64), seed=3)
    # variance of a sum of random-phase components = Σ a_i² / 2 ≈ m0 (within the band 0.5-3 ω_p)
    assert np.sum(waves.amplitude**2) / 2 == pytest.approx(0.2**2 / 16, rel=0.08)


def test_gauss_markov_is_stationary_with_its_sigma():
    x, xs = 0.0, []
    for k in range(40000):
        x = gauss_markov_step(x, 1.5, 2.0, 0.1, white_sample(11, 1, k))
        xs.append(x)
    xs = np.asarray(xs[2000:])
    assert np.std(xs) == pytest.approx(1.5, rel=0.1)
    lag = 20  # 2 s = one time constant: autocorrelation e^-1
    r = np.corrcoef(xs[:-lag], xs[lag:])[0, 1]
    assert r == pytest.approx(np.exp(-1), abs=0.05)


def test_head_wind_pushes_back_and_beam_wind_sideways():
    v = load_vessel("roboat2")
    cfg = EnvironmentConfig(wind=WindConfig(mean_speed=5.0, direction_deg=180.0))  # air moving west
    model = EnvironmentModel(cfg, v, seed=0)
    f = model.wind_force(np.array([0, 0, 0.0, 0, 0, 0]), 0.0)  # bow east: head wind
    assert f[0] < 0 and abs(f[1]) < 1e-9
    expected = 0.5 * 1.225 * 0.6 * 1.0 * (0.475 - 0.107) * 25.0
    assert f[0] == pytest.approx(-expected)
    f = model.wind_force(
        np.array([0, 0, np.pi / 2, 0, 0, 0]), 0.0
    )  # bow north: wind from starboard
    assert f[1] > 0 and abs(f[0]) < 1e-9  # pushed to port (+y body)


def test_wave_force_averages_to_zero_and_scales_with_hs():
    v = load_vessel("roboat2")
    cfg = EnvironmentConfig(waves=WaveConfig(significant_height=0.1, peak_period=2.0))
    model = EnvironmentModel(cfg, v, seed=4)
    q = np.zeros(6)
    t = np.arange(0, 600, 0.05)
    fx = np.array([model.wave_force(q, ti)[0] for ti in t])
    assert abs(fx.mean()) < 0.05 * fx.std()
    cfg2 = dataclasses.replace(cfg, waves=WaveConfig(significant_height=0.2, peak_period=2.0))
    fx2 = np.array([EnvironmentModel(cfg2, v, seed=4).wave_force(q, ti)[0] for ti in t[:2000]])
    assert np.std(fx2) == pytest.approx(2 * np.std(fx[:2000]), rel=1e-9)


def test_environment_system_is_deterministic_and_off_by_default():
    v = load_vessel("roboat2")
    quiet = Environment(EnvironmentConfig(), v, seed=0)
    ctx = quiet.CreateDefaultContext()
    quiet.GetInputPort("state").FixValue(ctx, np.zeros(6))
    assert np.all(quiet.GetOutputPort("tau_env").Eval(ctx) == 0)
    assert np.all(quiet.GetOutputPort("current").Eval(ctx) == 0)

    from pydrake.systems.analysis import Simulator

    cfg = EnvironmentConfig(wind=WindConfig(mean_speed=3.0, gust_std=1.0))
    outs = []
    for _ in range(2):
        env = Environment(cfg, v, seed=5)
        sim = Simulator(env)
        env.GetInputPort("state").FixValue(sim.get_mutable_context(), np.zeros(6))
        sim.AdvanceTo(3.0)
        outs.append(env.GetOutputPort("tau_env").Eval(sim.get_context()).copy())
    np.testing.assert_array_equal(outs[0], outs[1])
    assert outs[0][0] != 0.0


def test_wave_force_is_the_two_strip_sum_of_the_wave_accelerations():
    """The vectorised two-strip force against wave_acceleration evaluated at each strip."""
    v = load_vessel("roboat2")
    cfg = EnvironmentConfig(waves=WaveConfig(significant_height=0.3, peak_period=2.5))
    model = EnvironmentModel(cfg, v, seed=7)
    h, half = v.hydrodynamics, 0.25 * v.hull.length
    rng = np.random.default_rng(0)
    for _ in range(100):
        q, t = rng.normal(size=6) * [50, 50, 3, 1, 1, 0.5], rng.uniform(0, 300)
        c, s = np.cos(q[2]), np.sin(q[2])
        expected = np.zeros(3)
        for x in (half, -half):
            a = wave_acceleration(model.waves, q[:2] + x * np.array([c, s]), t)
            ab = np.array([c * a[0] + s * a[1], -s * a[0] + c * a[1]])
            expected += [0.5 * h.m11 * ab[0], 0.5 * h.m22 * ab[1], 0.5 * h.m22 * ab[1] * x]
        np.testing.assert_allclose(model.wave_force(q, t), expected, rtol=1e-9, atol=1e-9)
