"""NMPC (Roboat II eqs. 10-14): RTI agrees with the converged NLP and with IPOPT; failure
handling."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from usvdrake.systems.control.nmpc_problem import (
    NmpcConfig,
    NmpcProblem,
    solve_nlp_ipopt,
    wrap_reference,
)
from usvdrake.systems.control.nmpc_system import Nmpc
from usvdrake.systems.vessel.vessel_discrete import rk4
from usvdrake.vessel import load_vessel

VESSEL = load_vessel("roboat2")


class StraightLine:
    """x = 0.6 t along the x axis (a timed reference with sample())."""

    def sample(self, times):
        q = np.zeros((len(times), 6))
        q[:, 0], q[:, 3] = 0.6 * np.asarray(times), 0.6
        return q, np.zeros((len(times), 3))


def test_weights_and_limits_are_the_papers():
    p = NmpcProblem(VESSEL, NmpcConfig())
    np.testing.assert_array_equal(p.Wq, [200, 200, 100, 10, 10, 10])
    np.testing.assert_array_equal(p.WN, [1000, 1000, 500, 50, 50, 150])
    np.testing.assert_array_equal(p.Wu, [1, 1, 1, 1])
    assert p.N == 40 and p.dt == 0.1
    np.testing.assert_array_equal(p.u_max, [50] * 4)


def test_converged_sqp_equals_ipopt_on_the_nlp():
    ref = StraightLine()
    p = NmpcProblem(VESSEL, NmpcConfig(mode="nlp"))
    q0 = np.array([0.0, 0.5, 0.3, 0.0, 0.0, 0.0])
    q_ref, nd = ref.sample(p.dt * np.arange(p.N + 1))
    u_ref = p.feedforward(q_ref, nd)
    sqp = p.solve(q0, q_ref, u_ref)
    ipopt = solve_nlp_ipopt(p, q0, q_ref, u_ref)
    assert sqp.success and ipopt.success and sqp.iterations > 1
    assert sqp.cost == pytest.approx(ipopt.cost, rel=1e-8)
    np.testing.assert_allclose(sqp.u, ipopt.u, atol=1e-4)
    # the RK4 dynamics hold exactly along the converged plan
    for k in range(p.N):
        nxt = rk4(p.xi, sqp.q[k : k + 1], (p.B_thr @ sqp.u[k])[None], p.dt)[0]
        np.testing.assert_allclose(sqp.q[k + 1], nxt, atol=1e-6)


def test_rti_closed_loop_converges_to_the_converged_nlp():
    """After the transient, one QP per step gives the same inputs as solving to convergence."""
    ref = StraightLine()
    rti, nlp = NmpcProblem(VESSEL, NmpcConfig()), NmpcProblem(VESSEL, NmpcConfig(mode="nlp"))
    q = np.array([0.0, 0.5, 0.3, 0.0, 0.0, 0.0])
    warm = None
    for j in range(150):
        q_ref, nd = ref.sample(j * 0.1 + 0.1 * np.arange(rti.N + 1))
        u_ref = rti.feedforward(q_ref, nd)
        sol = rti.solve(q, q_ref, u_ref, warm)
        assert sol.success and np.all(np.abs(sol.u) <= 50.0)
        warm = rti.shift(sol.q, sol.u)
        for _ in range(10):
            q = rk4(rti.xi, q[None], (rti.B_thr @ sol.u[0])[None], 0.01)[0]
    q_ref, nd = ref.sample(150 * 0.1 + 0.1 * np.arange(rti.N + 1))
    u_ref = rti.feedforward(q_ref, nd)
    a, b = rti.solve(q, q_ref, u_ref, warm), nlp.solve(q, q_ref, u_ref, warm)
    np.testing.assert_allclose(a.u[0], b.u[0], atol=0.05)
    assert np.hypot(q[0] - 0.6 * 15.0, q[1]) < 0.01  # on the line, where the reference is at 15 s


def test_heading_reference_is_unwrapped_to_the_estimate():
    q_ref = np.zeros((5, 6))
    q_ref[:, 2] = [3.1, -3.1, -3.0, 3.1, 3.0]
    w = wrap_reference(q_ref, psi_now=-3.1)
    assert np.all(np.abs(np.diff(w[:, 2])) < 0.3)
    assert abs(w[0, 2] - (-3.1)) < np.pi


class FailingProblem(NmpcProblem):
    def __init__(self, *a, fail_from: int = 3, **k):
        super().__init__(*a, **k)
        self.calls, self.fail_from = 0, fail_from

    def solve(self, *a, **k):
        self.calls += 1
        if self.calls >= self.fail_from:
            raise RuntimeError("solver died")
        return super().solve(*a, **k)


def test_failures_shift_the_plan_then_stop_the_thrusters():
    cfg = NmpcConfig(max_consecutive_failures=3)
    nmpc = Nmpc(VESSEL, cfg, StraightLine())
    nmpc._problem = FailingProblem(VESSEL, cfg, fail_from=3)
    sim = Simulator(nmpc)
    ctx = sim.get_mutable_context()
    nmpc.GetInputPort("state_estimate").FixValue(ctx, [0, 0.3, 0, 0, 0, 0])
    sim.AdvanceTo(0.25)  # solves at 0, 0.1 succeed; 0.2 fails → the shifted plan is used
    assert nmpc.GetOutputPort("nmpc_failures").Eval(ctx)[0] == 1
    assert np.any(nmpc.GetOutputPort("thruster_command").Eval(ctx) != 0)
    sim.AdvanceTo(0.65)  # 0.2 .. 0.6: five failures in a row (> 3) → zero thrust
    assert nmpc.GetOutputPort("nmpc_failures").Eval(ctx)[0] == 5
    np.testing.assert_array_equal(nmpc.GetOutputPort("thruster_command").Eval(ctx), np.zeros(4))


def test_azimuth_vessels_are_refused_clearly():
    with pytest.raises(ValueError, match="azimuth"):
        NmpcProblem(load_vessel("ntnu_round"), NmpcConfig())


@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")  # NaN on purpose
def test_non_finite_inputs_fail_cleanly_instead_of_aborting():
    """Drake aborts the process on NaN coefficients; the problem must refuse them first."""
    p = NmpcProblem(VESSEL, NmpcConfig())
    q_ref, nd = StraightLine().sample(p.dt * np.arange(p.N + 1))
    u_ref = p.feedforward(q_ref, nd)
    bad = p.solve(np.array([np.nan, 0, 0, 0, 0, 0]), q_ref, u_ref)
    assert not bad.success and "non-finite" in bad.status
    warm_q, warm_u = p.initial_guess(np.zeros(6), u_ref)
    warm_q[5, 3] = np.inf
    assert not p.solve(np.zeros(6), q_ref, u_ref, (warm_q, warm_u)).success


def test_offset_free_disturbance_is_bounded_by_the_thrusters():
    """A velocity jump of the estimator must not wind the disturbance up past what the
    thrusters could ever counter (it made every later QP infeasible)."""
    from usvdrake.systems.vessel.thrusters import thrust_envelope

    vessel = load_vessel("roboat2")
    p = NmpcProblem(vessel, NmpcConfig())
    limit = thrust_envelope(vessel.thrusters)
    np.testing.assert_allclose(limit[:2], sum(t.max_force for t in vessel.thrusters))
    d = np.zeros(3)
    for _ in range(50):
        d = p.update_disturbance(d, np.array([0.0, 0.4, 0.3]), np.zeros(3))
    np.testing.assert_allclose(d, [0.0, limit[1], limit[2]])


def test_campaign_run_145_no_longer_fails():
    """Monte Carlo run 145 of river_tracking (its randomised scenario, kept in tests/data):
    the NMHE's start-up transient wound the NMPC's disturbance up to 3.4 kN and every QP after
    t ≈ 0.6 s was infeasible. 20 s is enough to see it (~190 failures before the fix)."""
    from pathlib import Path

    from usvdrake import load_scenario, run_mission
    from usvdrake.diagrams import with_overrides

    path = Path(__file__).parent / "data" / "river_tracking_campaign_run_0145.yaml"
    m = run_mission(with_overrides(load_scenario(path), duration=20.0), record=False).metrics
    assert m["nmpc_failures"] == 0
