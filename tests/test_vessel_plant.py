"""VesselPlant against an independent integration of Roboat II eqs. (1)-(6), and its
linearisation."""

import numpy as np
import pytest
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from scipy.integrate import solve_ivp

from usvdrake.systems.vessel.vessel_dynamics import (
    straight_run_jacobian,
    vessel_derivatives,
    vessel_derivatives_float,
)
from usvdrake.systems.vessel.vessel_plant import VesselPlant, VesselPlant_
from usvdrake.vessel import load_vessel

VESSELS = ["roboat2", "usv2000", "ntnu_round"]


def inputs(t, scale):
    """Varied, smooth inputs: generalised force, environmental force, current (world).
    ``scale`` = [force, force, moment] sized for the vessel."""
    tau = scale * np.array(
        [
            0.6 + 0.4 * np.sin(0.21 * t),
            0.3 * np.sin(0.37 * t + 1.0),
            0.2 * np.cos(0.13 * t) + 0.1 * np.sin(0.9 * t),
        ]
    )
    tau_env = scale * np.array(
        [0.05 * np.sin(1.3 * t), 0.08 * np.cos(0.7 * t), 0.02 * np.sin(0.5 * t)]
    )
    current = np.array([0.2 * np.cos(0.05 * t), 0.1 * np.sin(0.03 * t)])
    return tau, tau_env, current


def reference_rhs(xi):
    """Eqs. (1)-(6) written independently in matrix form: η̇ = T(ψ)ν,
    M ν̇ = τ + τ_env − C(ν)ν − D(ν − ν_c)."""
    m = np.diag([xi.m11, xi.m22, xi.m33])
    d = np.diag([xi.Xu, xi.Yv, xi.Nr])

    def rhs(t, q, scale):
        tau, tau_env, vc = inputs(t, scale)
        psi = q[2]
        nu = q[3:]
        rot = np.array([[np.cos(psi), -np.sin(psi), 0], [np.sin(psi), np.cos(psi), 0], [0, 0, 1]])
        c = np.array(
            [[0, 0, -xi.m22 * nu[1]], [0, 0, xi.m11 * nu[0]], [xi.m22 * nu[1], -xi.m11 * nu[0], 0]]
        )
        nu_c = np.concatenate([rot[:2, :2].T @ vc, [0.0]])
        nu_dot = np.linalg.solve(m, tau + tau_env - c @ nu - d @ (nu - nu_c))
        return np.concatenate([rot @ nu, nu_dot])

    return rhs


class InputSource(LeafSystem):
    def __init__(self, scale):
        super().__init__()
        self.scale = scale
        for i, (name, n) in enumerate([("tau", 3), ("tau_env", 3), ("current", 2)]):
            self.DeclareVectorOutputPort(
                name, n, lambda c, o, i=i: o.SetFromVector(inputs(c.get_time(), self.scale)[i])
            )


@pytest.mark.parametrize("name", VESSELS)
def test_plant_matches_independent_integration(name):
    v = load_vessel(name)
    f = v.thrusters[0].max_force  # forces and moments of the right size for each vessel
    scale = np.array([f, f, f * v.hull.length / 4])
    q0 = np.array([1.0, -2.0, 0.3, 0.1, 0.0, 0.05])
    builder = DiagramBuilder()
    plant = builder.AddSystem(VesselPlant(v, q0))
    src = builder.AddSystem(InputSource(scale))
    for port in ("tau", "tau_env", "current"):
        builder.Connect(src.GetOutputPort(port), plant.GetInputPort(port))
    diagram = builder.Build()
    sim = Simulator(diagram)
    ResetIntegratorFromFlags(sim, "runge_kutta5", 0.05)
    sim.get_mutable_integrator().set_target_accuracy(1e-13)
    times = np.arange(0.0, 120.0 + 1e-9, 5.0)
    ref = solve_ivp(
        reference_rhs(v.hydrodynamics),
        (0, 120),
        q0,
        args=(scale,),
        method="DOP853",
        rtol=1e-10,
        atol=1e-12,
        t_eval=times,
    )
    assert ref.success
    ctx = plant.GetMyContextFromRoot(sim.get_mutable_context())
    worst = 0.0
    for k, t in enumerate(times):
        sim.AdvanceTo(t)
        q = plant.GetOutputPort("state").Eval(ctx)
        worst = max(worst, np.max(np.abs(q - ref.y[:, k])))
    # the run must actually go somewhere for the comparison to mean anything
    assert np.linalg.norm(ref.y[:2, -1] - q0[:2]) > 1.0
    assert worst < 1e-6, f"{name}: max deviation {worst:.2e}"


@pytest.mark.parametrize("name", VESSELS)
def test_linearisation_about_straight_run(name):
    """Linearize (AutoDiffXd) about q = [0 0 0 u0 0 0] with the trim thrust τ = [Xu u0, 0, 0].

    By hand (see ``straight_run_jacobian``'s docstring): the eigenvalues are 0, 0, 0 (position and
    heading have no restoring force), −Xu/m11 (surge), and the roots of
        λ² + (Yv/m22 + Nr/m33) λ + (Yv Nr − (m22 − m11) m11 u0²) / (m22 m33) = 0
    from the coupled sway-yaw block."""
    v = load_vessel(name)
    xi = v.hydrodynamics
    u0 = 0.6
    from usvdrake.analysis.stability import linearize_plant

    A, B = linearize_plant(v, u0)  # Drake's Linearize on the AutoDiffXd plant
    np.testing.assert_allclose(A, straight_run_jacobian(xi, u0), atol=1e-12)
    np.testing.assert_allclose(
        B,
        np.vstack([np.zeros((3, 3)), np.diag([1 / xi.m11, 1 / xi.m22, 1 / xi.m33])]),
        atol=1e-12,
    )
    b = xi.Yv / xi.m22 + xi.Nr / xi.m33
    c = (xi.Yv * xi.Nr - (xi.m22 - xi.m11) * xi.m11 * u0**2) / (xi.m22 * xi.m33)
    quad = np.roots([1.0, b, c])
    expected = np.sort_complex(np.concatenate([[0, 0, 0, -xi.Xu / xi.m11], quad]))
    got = np.sort_complex(np.linalg.eigvals(A))
    np.testing.assert_allclose(got, expected, atol=1e-9)


def test_roboat2_eigenvalues_match_published_numbers():
    """NOTES.md: Roboat II at 0.6 m/s has eigenvalues 0, 0, 0, −0.2209, −0.298, −1.262."""
    a = straight_run_jacobian(load_vessel("roboat2").hydrodynamics, 0.6)
    ev = np.sort(np.linalg.eigvals(a).real)
    np.testing.assert_allclose(ev, [-1.262, -0.298, -0.2209, 0, 0, 0], atol=6e-4)


def test_scalar_conversion_symbolic_and_autodiff():
    from pydrake.symbolic import Expression, Variable

    v = load_vessel("roboat2")
    xi = v.hydrodynamics
    plant = VesselPlant(v)
    sym = plant.ToSymbolic()
    assert isinstance(sym, VesselPlant_[Expression])
    ctx = sym.CreateDefaultContext()
    x = [Variable(n) for n in ["x", "y", "psi", "u", "v", "r"]]
    ctx.SetContinuousState([Expression(xi_) for xi_ in x])
    sym.GetInputPort("tau").FixValue(ctx, [Expression(0.0)] * 3)
    xdot = sym.EvalTimeDerivatives(ctx).CopyToVector()
    # ṙ = ((m11 − m22) u v − Nr r) / m33, symbolically
    expected = ((xi.m11 - xi.m22) * x[3] * x[4] - xi.Nr * x[5]) / xi.m33
    assert (xdot[5] - expected).Expand().EqualTo(Expression(0.0))
    assert plant.ToAutoDiffXd() is not None
    assert not plant.HasDirectFeedthrough(0, 0)


def test_bad_initial_state_is_rejected():
    with pytest.raises(ValueError, match="6 values"):
        VesselPlant(load_vessel("roboat2"), [0, 0, 0])


@pytest.mark.parametrize("name", ["roboat2", "usv2000", "ntnu_round"])
def test_the_float_derivatives_equal_the_scalar_generic_ones(name):
    xi = load_vessel(name).hydrodynamics
    rng = np.random.default_rng(3)
    for _ in range(200):
        q = rng.normal(size=6) * [9, 9, 3, 1, 1, 0.5]
        tau, env, cur = rng.normal(size=3) * 50, rng.normal(size=3) * 10, rng.normal(size=2)
        a = vessel_derivatives(xi, q, tau, env, cur)
        np.testing.assert_allclose(vessel_derivatives_float(xi, q, tau, env, cur), a, rtol=1e-14)
