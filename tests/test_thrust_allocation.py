"""ThrustAllocation: exact inside the attainable set, the documented weighted minimum outside,
limits always (property-based, hypothesis)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import lsq_linear, minimize

from usvdrake.systems.vessel.thrust_allocation import ThrustAllocation
from usvdrake.systems.vessel.thrust_allocation_problem import ThrustAllocator
from usvdrake.systems.vessel.thrust_mixer import ThrustMixer
from usvdrake.systems.vessel.thrusters import (
    command_size,
    configuration_matrix,
    extended_matrix,
    mix,
    saturate,
    split_command,
)
from usvdrake.vessel import load_vessel

VESSELS = ["roboat2", "usv2000", "ntnu_round"]
_ALLOCATORS = {}


def allocator(name):
    if name not in _ALLOCATORS:
        v = load_vessel(name)
        _ALLOCATORS[name] = (v, ThrustAllocator(v.thrusters, v.allocation_weight))
    return _ALLOCATORS[name]


def within_limits(v, command, tol=1e-9):
    for t, (f, _) in zip(v.thrusters, split_command(v.thrusters, command), strict=True):
        lo = 0.0 if t.azimuth else t.min_force
        if not (lo - tol <= f <= t.max_force + tol):
            return False
    return True


def feasible_command(v, fractions, angles):
    """A command inside every limit, from numbers in [0, 1] and angles."""
    out = []
    for t, a, ang in zip(v.thrusters, fractions, angles, strict=False):
        if t.azimuth:
            out += [a * t.max_force, ang]
        else:
            out.append(t.min_force + a * (t.max_force - t.min_force))
    return np.array(out)


unit = st.floats(0.0, 1.0)
angle = st.floats(-np.pi, np.pi)


@pytest.mark.parametrize("name", VESSELS)
@settings(max_examples=150, deadline=None)
@given(fr=st.lists(unit, min_size=4, max_size=4), ang=st.lists(angle, min_size=4, max_size=4))
def test_attainable_tau_is_reproduced_exactly(name, fr, ang):
    v, al = allocator(name)
    tau = mix(v.thrusters, feasible_command(v, fr, ang))  # attainable by construction
    res = al.allocate(tau)
    assert within_limits(v, res.command)
    np.testing.assert_allclose(mix(v.thrusters, res.command), tau, atol=1e-6)
    np.testing.assert_allclose(res.tau_achieved, tau, atol=1e-6)
    assert res.attainable


def weighted_minimum_box(v, tau):
    """Independent: bounded linear least squares (scipy BVLS) for fixed-thruster layouts."""
    b = configuration_matrix(v.thrusters)
    w = np.sqrt(np.diag(v.allocation_weight))
    lo = [t.min_force for t in v.thrusters]
    hi = [t.max_force for t in v.thrusters]
    sol = lsq_linear(w @ b, w @ tau, bounds=(lo, hi), method="bvls", tol=1e-12)
    return np.linalg.norm(w @ (b @ sol.x - tau))


def weighted_minimum_azimuth(v, tau):
    """Independent: SLSQP on the extended thrust vector with disc constraints, several starts."""
    b = extended_matrix(v.thrusters)
    w = np.diag(v.allocation_weight)
    cons = [
        {
            "type": "ineq",
            "fun": lambda z, k=k, t=t: t.max_force**2 - z[2 * k] ** 2 - z[2 * k + 1] ** 2,
        }
        for k, t in enumerate(v.thrusters)
    ]
    best = np.inf
    rng = np.random.default_rng(0)
    for _ in range(4):
        z0 = rng.uniform(-0.5, 0.5, b.shape[1])
        r = minimize(
            lambda z: (b @ z - tau) @ w @ (b @ z - tau),
            z0,
            constraints=cons,
            method="SLSQP",
            options={"ftol": 1e-14, "maxiter": 500},
        )
        if all(c["fun"](r.x) > -1e-7 for c in cons):
            best = min(best, np.sqrt(max(r.fun, 0.0)))
    return best


@pytest.mark.parametrize("name", VESSELS)
@settings(max_examples=60, deadline=None)
@given(direction=st.lists(st.floats(-1, 1), min_size=3, max_size=3), magnitude=st.floats(0.0, 6.0))
def test_any_tau_respects_limits_and_minimises_weighted_error(name, direction, magnitude):
    v, al = allocator(name)
    d = np.asarray(direction)
    if np.linalg.norm(d) < 1e-3:
        d = np.array([1.0, 0.0, 0.0])
    fmax = max(t.max_force for t in v.thrusters)
    scale = np.array([fmax, fmax, fmax * v.hull.length / 2])
    tau = magnitude * scale * d / np.linalg.norm(d)  # up to ~6× the capacity: often outside
    res = al.allocate(tau)
    assert within_limits(v, res.command)
    w = np.sqrt(np.diag(v.allocation_weight))
    err = np.linalg.norm(w @ (mix(v.thrusters, res.command) - tau))
    assert err == pytest.approx(res.error, abs=1e-6)
    if any(t.azimuth for t in v.thrusters):
        ref = weighted_minimum_azimuth(v, tau)
        assert err <= ref + 1e-5 * max(1.0, ref)  # never worse than an independent local solver
    else:
        ref = weighted_minimum_box(v, tau)
        assert err == pytest.approx(ref, abs=1e-6 * max(1.0, ref))


@pytest.mark.parametrize("name", ["roboat2", "usv2000"])
def test_least_effort_among_exact_solutions(name):
    """Stage 2 picks the minimum Σ (f_i / f_max,i)² among commands that achieve τ exactly."""
    v, al = allocator(name)
    b = configuration_matrix(v.thrusters)
    fmax = np.array([t.max_force for t in v.thrusters])
    bounds = [(t.min_force, t.max_force) for t in v.thrusters]
    for tau in ([20.0, 5.0, 3.0], [-10.0, 12.0, -4.0], [40.0, 0.0, 0.0]):
        res = al.allocate(tau)
        r = minimize(
            lambda f: np.sum((f / fmax) ** 2),
            np.zeros(len(fmax)),
            constraints=[{"type": "eq", "fun": lambda f, tau=tau: b @ f - tau}],
            bounds=bounds,
            method="SLSQP",
            options={"ftol": 1e-14},
        )
        assert np.sum((res.command / fmax) ** 2) <= r.fun + 1e-7


def test_roboat2_configuration_matrix_is_eq3_mirrored():
    """Roboat II eq. (3) in the y-left frame with a = 0.6 m, b = 1.4 m (see roboat2.yaml)."""
    b = configuration_matrix(load_vessel("roboat2").thrusters)
    expected = np.array([[1, 1, 0, 0], [0, 0, 1, 1], [-0.3, 0.3, 0.7, -0.7]])
    np.testing.assert_allclose(b, expected, atol=1e-12)


def test_mixer_saturates_and_is_linear_in_force():
    v = load_vessel("roboat2")
    cmd = np.array([80.0, -70.0, 10.0, -5.0])
    sat = saturate(v.thrusters, cmd)
    np.testing.assert_allclose(sat, [50.0, -50.0, 10.0, -5.0])
    np.testing.assert_allclose(mix(v.thrusters, sat), configuration_matrix(v.thrusters) @ sat)


def test_mixer_system_autodiff_gradient_is_b():
    """∂τ/∂u of the AutoDiffXd mixer is B (inside the limits)."""
    from pydrake.autodiffutils import ExtractGradient, InitializeAutoDiff

    v = load_vessel("roboat2")
    mixer = ThrustMixer(v.thrusters).ToAutoDiffXd()
    ctx = mixer.CreateDefaultContext()
    mixer.GetInputPort("thruster_command").FixValue(
        ctx, InitializeAutoDiff(np.array([1.0, 2.0, -3.0, 4.0])).ravel()
    )
    tau = mixer.GetOutputPort("tau").Eval(ctx)
    np.testing.assert_allclose(ExtractGradient(tau), configuration_matrix(v.thrusters), atol=1e-12)


def test_azimuth_mixer_uses_angle():
    v = load_vessel("ntnu_round")
    n = command_size(v.thrusters)
    assert n == 6
    cmd = np.array([1.0, np.pi / 2, 0.0, 0.0, 0.0, 0.0])  # az1 at (0, 0.138) pushing +y
    np.testing.assert_allclose(mix(v.thrusters, cmd), [0.0, 1.0, 0.0], atol=1e-12)
    cmd = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # pushing +x from y = 0.138: yaw = −0.138
    np.testing.assert_allclose(mix(v.thrusters, cmd), [1.0, 0.0, -0.138], atol=1e-12)


@pytest.mark.parametrize("name", VESSELS)
def test_allocation_system_outputs(name):
    v = load_vessel(name)
    sys_ = ThrustAllocation(v)
    ctx = sys_.CreateDefaultContext()
    tau = np.array([0.5, 0.2, 0.05]) * v.thrusters[0].max_force
    sys_.GetInputPort("tau_desired").FixValue(ctx, tau)
    cmd = sys_.GetOutputPort("thruster_command").Eval(ctx)
    np.testing.assert_allclose(mix(v.thrusters, cmd), tau, atol=1e-6)
    np.testing.assert_allclose(sys_.GetOutputPort("tau_achieved").Eval(ctx), tau, atol=1e-6)


def test_allocation_rejects_non_finite():
    v, al = allocator("roboat2")
    with pytest.raises(ValueError, match="finite"):
        al.allocate([np.nan, 0, 0])
