"""The discrete-time model: RK4 against the plant, Jacobians against AutoDiffXd."""

import numpy as np
from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

from usvdrake.systems.vessel import vessel_discrete
from usvdrake.systems.vessel.vessel_discrete import (
    continuous_jacobians,
    input_jacobian,
    rk4,
    rk4_with_jacobians,
    rollout,
)
from usvdrake.systems.vessel.vessel_dynamics import (
    coriolis,
    coriolis_times_velocity,
    vessel_derivatives,
)
from usvdrake.vessel import load_vessel

XI = load_vessel("roboat2").hydrodynamics
RNG = np.random.default_rng(0)
Q = np.column_stack([RNG.normal(0, 5, (5, 2)), RNG.uniform(-3, 3, 5), RNG.normal(0, 0.5, (5, 3))])
TAU = RNG.normal(0, 30, (5, 3))


def test_coriolis_written_out_equals_eq5():
    for q in Q:
        np.testing.assert_allclose(
            coriolis_times_velocity(XI, q[3:]), coriolis(XI, q[3:]) @ q[3:], atol=1e-12
        )


def test_batch_derivatives_equal_scalar_ones():
    from usvdrake.systems.vessel.vessel_discrete import f_batch

    fb = f_batch(XI, Q, TAU)
    for i in range(len(Q)):
        np.testing.assert_allclose(
            fb[i], vessel_derivatives(XI, Q[i], TAU[i], np.zeros(3), np.zeros(2)), atol=1e-12
        )


def test_continuous_jacobian_matches_autodiff():
    j = continuous_jacobians(XI, Q)
    for i in range(len(Q)):
        x = InitializeAutoDiff(np.concatenate([Q[i], TAU[i]])).ravel()
        f = vessel_derivatives(XI, x[:6], x[6:], np.zeros(3), np.zeros(2))
        grad = ExtractGradient(f)
        np.testing.assert_allclose(j[i], grad[:, :6], atol=1e-10)
        np.testing.assert_allclose(input_jacobian(XI), grad[:, 6:], atol=1e-12)


def test_rk4_jacobians_match_autodiff():
    q1, a, b = rk4_with_jacobians(XI, Q, TAU, 0.1)
    np.testing.assert_allclose(q1, rk4(XI, Q, TAU, 0.1), atol=1e-12)
    for i in range(len(Q)):
        x = InitializeAutoDiff(np.concatenate([Q[i], TAU[i]])).ravel()
        h = 0.1

        def f(z, tau=x[6:]):
            return vessel_derivatives(XI, z[:6], tau, np.zeros(3), np.zeros(2))

        z = x[:6]
        k1 = f(z)
        k2 = f(z + 0.5 * h * k1)
        k3 = f(z + 0.5 * h * k2)
        k4 = f(z + h * k3)
        grad = ExtractGradient(z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
        np.testing.assert_allclose(a[i], grad[:, :6], atol=1e-10)
        np.testing.assert_allclose(b[i], grad[:, 6:], atol=1e-10)


def test_compiled_float_path_equals_the_numpy_path(monkeypatch):
    """Float batches take the compiled kernels; other scalar types the numpy functions. Same
    states to the bit, Jacobians to rounding."""
    fast = rk4_with_jacobians(XI, Q, TAU, 0.1), rk4(XI, Q, TAU, 0.1)
    monkeypatch.setattr(vessel_discrete, "_floats", lambda *arrays: False)
    slow = rk4_with_jacobians(XI, Q, TAU, 0.1), rk4(XI, Q, TAU, 0.1)
    assert np.array_equal(fast[0][0], slow[0][0]) and np.array_equal(fast[1], slow[1])
    for i in (1, 2):
        np.testing.assert_allclose(fast[0][i], slow[0][i], rtol=0, atol=1e-14)


def test_rollout_converges_to_the_continuous_plant():
    """RK4 at 0.1 s against Drake's error-controlled simulation of VesselPlant (60 s)."""
    from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator

    from usvdrake.systems.vessel.vessel_plant import VesselPlant

    v = load_vessel("roboat2")
    q0 = np.array([0.0, 0.0, 0.2, 0.5, 0.0, 0.0])
    tau = np.array([30.0, 5.0, 3.0])
    plant = VesselPlant(v, q0)
    ctx = plant.CreateDefaultContext()
    plant.GetInputPort("tau").FixValue(ctx, tau)
    sim = Simulator(plant, ctx)
    ResetIntegratorFromFlags(sim, "runge_kutta5", 0.05)
    sim.get_mutable_integrator().set_target_accuracy(1e-12)
    sim.AdvanceTo(60.0)
    traj = rollout(v.hydrodynamics, q0, np.tile(tau, (600, 1)), 0.1)
    assert np.max(np.abs(traj[-1] - ctx.get_continuous_state_vector().CopyToVector())) < 1e-5
    assert np.linalg.norm(traj[-1, :2] - q0[:2]) > 5.0  # it went somewhere (it turns in circles)
