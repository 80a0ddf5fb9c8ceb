"""Closed-loop stability analysis (usvdrake.analysis.stability) against hand results, Drake
simulations of the real controllers, and sampling of the true nonlinear closed loop."""

import json

import control
import numpy as np
import pytest
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Demultiplexer
from scipy.linalg import expm
from scipy.optimize import linear_sum_assignment

from usvdrake.analysis import stability as st
from usvdrake.analysis.stability.roa import _CHANNEL_STATES
from usvdrake.scenario import ControlConfig
from usvdrake.systems.control.nmpc_problem import NmpcConfig, NmpcProblem
from usvdrake.systems.control.pd_controller import PdController, PdControllerConfig, pd_gains
from usvdrake.systems.estimation.observer_dynamics import fossen_gains
from usvdrake.systems.estimation.passive_observer import PassiveObserver
from usvdrake.systems.vessel.thrust_allocation_problem import ThrustAllocator
from usvdrake.systems.vessel.thrusters import configuration_matrix, extended_matrix
from usvdrake.systems.vessel.vessel_dynamics import straight_run_jacobian
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import load_vessel


def matched_distance(a, b) -> float:
    """Largest distance of the best one-to-one matching of two eigenvalue sets."""
    a, b = np.asarray(a, complex), np.asarray(b, complex)
    assert len(a) == len(b)
    cost = np.abs(a[:, None] - b[None, :])
    r, c = linear_sum_assignment(cost)
    return float(cost[r, c].max())


@pytest.fixture(scope="module")
def roboat():
    return load_vessel("roboat2")


@pytest.fixture(scope="module")
def rnd():
    return load_vessel("ntnu_round")


@pytest.fixture(scope="module")
def observer_cfg(rnd):
    return fossen_gains(rnd.hydrodynamics, [2.0, 2.0, 3.0], T=1000.0, rate_hz=20.0)


# --- 1. plant ----------------------------------------------------------------------------------
def test_plant_linearisation_roboat2_known_answer(roboat):
    xi = roboat.hydrodynamics
    a, b = st.linearize_plant(roboat, 0.6)
    np.testing.assert_allclose(a, straight_run_jacobian(xi, 0.6), atol=1e-12)
    np.testing.assert_allclose(b, st.input_matrix(xi), atol=1e-15)
    ev = np.linalg.eigvals(a)
    assert matched_distance(ev, st.straight_run_eigenvalues(xi, 0.6)) < 1e-6
    # NOTES.md: 0, 0, 0, −Xu/m11 = −0.2209, sway-yaw −0.298, −1.262
    notes = [0, 0, 0, -0.2209, -0.298, -1.262]
    assert matched_distance(ev, notes) < 5e-4
    assert abs(-xi.Xu / xi.m11 - (-0.2209)) < 5e-5


@pytest.mark.parametrize("name", ["usv2000", "ntnu_round"])
def test_plant_linearisation_other_vessels(name):
    v = load_vessel(name)
    for u0 in (0.0, 0.3):
        a, _ = st.linearize_plant(v, u0)
        np.testing.assert_allclose(a, straight_run_jacobian(v.hydrodynamics, u0), atol=1e-12)


def test_zoh_matches_python_control(rnd):
    a, b = straight_run_jacobian(rnd.hydrodynamics, 0.0), st.input_matrix(rnd.hydrodynamics)
    phi, gam = st.zoh(a, b, 0.1)
    d = control.c2d(control.ss(a, b, np.eye(6), 0), 0.1, "zoh")
    np.testing.assert_allclose(phi, d.A, atol=1e-12)
    np.testing.assert_allclose(gam, d.B, atol=1e-12)


# --- 2. closed loops ---------------------------------------------------------------------------
def test_round_pd_continuous_poles_are_characteristic_roots(rnd):
    xi, cfg = rnd.hydrodynamics, PdControllerConfig()
    loop = st.pd_loop(xi, cfg)
    kp, kd = pd_gains(xi, cfg)
    np.testing.assert_allclose(loop.H, -np.hstack([kp, kd]), atol=1e-14)
    assert matched_distance(loop.eigenvalues(), st.pd_characteristic_roots(xi, kp, kd)) < 1e-6
    assert loop.is_stable()
    # by design: ω_n = [0.5, 0.5, 1.5], ζ = 0.9 (no clip acted for ntnu_round)
    w, z = np.array([0.5, 0.5, 1.5]), 0.9
    design = np.concatenate(
        [-z * w + 1j * w * np.sqrt(1 - z * z), -z * w - 1j * w * np.sqrt(1 - z * z)]
    )
    assert matched_distance(loop.eigenvalues(), design) < 1e-6


def test_round_pd_sampled_poles(rnd):
    loop = st.pd_loop(rnd.hydrodynamics, PdControllerConfig())
    samp = st.sampled_state_feedback(loop, 0.1)
    zs = samp.eigenvalues()
    assert np.all(np.abs(zs) < 1.0) and samp.is_stable()
    s = loop.eigenvalues()
    cost = np.abs(zs[:, None] - np.exp(s * 0.1)[None, :])
    r, c = linear_sum_assignment(cost)
    # z ≈ e^{sT}: the ZOH state feedback deviates at second order in |s| T
    assert np.all(cost[r, c] <= (np.abs(s[c]) * 0.1) ** 2)
    slow = np.abs(s[c]) < 0.6
    assert np.all(cost[r, c][slow] < 1.5e-3)


def _simulate(builder_fn, t_end):
    builder = DiagramBuilder()
    handles = builder_fn(builder)
    diagram = builder.Build()
    sim = Simulator(diagram)
    ResetIntegratorFromFlags(sim, "runge_kutta5", 0.01)
    sim.get_mutable_integrator().set_target_accuracy(1e-11)
    ctx = sim.get_mutable_context()
    if "init" in handles:
        handles["init"](diagram, ctx)
    sim.Initialize()
    sim.AdvanceTo(t_end)
    return diagram, ctx, handles


def test_sampled_pd_model_matches_drake_simulation(rnd):
    """The real PdController (10 Hz, ZOH) on the VesselPlant follows (Φ + ΓK)^k x0."""
    xi, cfg = rnd.hydrodynamics, PdControllerConfig()
    samp = st.sampled_state_feedback(st.pd_loop(xi, cfg), 0.1)
    x0 = 1e-4 * np.array([1.0, -0.7, 0.5, 0.3, 0.2, -0.4])
    out = {}
    for sign in (1.0, -1.0):  # the odd part cancels the quadratic (Coriolis) terms

        def build(b, sign=sign):
            plant = b.AddSystem(VesselPlant(rnd, initial_state=sign * x0))
            pd = b.AddSystem(PdController(xi, cfg))
            ref = b.AddSystem(ConstantVectorSource(np.zeros(9)))
            b.Connect(plant.GetOutputPort("state"), pd.GetInputPort("state_estimate"))
            b.Connect(ref.get_output_port(), pd.GetInputPort("reference"))
            b.Connect(pd.GetOutputPort("tau_desired"), plant.GetInputPort("tau"))
            return {"plant": plant}

        diagram, ctx, h = _simulate(build, 1.0)
        pctx = h["plant"].GetMyContextFromRoot(ctx)
        out[sign] = pctx.get_continuous_state_vector().CopyToVector()
    sim = 0.5 * (out[1.0] - out[-1.0])
    pred = np.linalg.matrix_power(samp.closed, 10) @ x0
    assert np.linalg.norm(sim - pred) < 1e-6 * np.linalg.norm(x0)
    # and the continuous model would be visibly off: the sampling is resolved
    cont = expm(st.pd_loop(xi, cfg).closed * 1.0) @ x0
    assert np.linalg.norm(cont - pred) > 1e3 * np.linalg.norm(sim - pred)


def test_separation_principle_continuous(rnd, observer_cfg):
    xi, cfg = rnd.hydrodynamics, PdControllerConfig()
    pd = st.pd_loop(xi, cfg)
    loop = st.pd_observer_loop(xi, cfg, observer_cfg)
    err = st.observer_error_matrix(observer_cfg, xi)
    union = np.concatenate([pd.eigenvalues(), np.linalg.eigvals(err)])
    assert matched_distance(loop.eigenvalues(), union) < 1e-6
    assert loop.is_stable()
    # the hand error dynamics: per DOF s³ + (ω_c + d) s² + (ω_c d + k4) s + k3 (1/T → 0) has
    # its three roots near −p = −(ω_c + d)/3 (fossen_gains' triple-pole choice)
    m = np.array([xi.m11, xi.m22, xi.m33])
    p = (observer_cfg.K2 + np.array([xi.Xu, xi.Yv, xi.Nr]) / m) / 3.0
    ev = np.linalg.eigvals(err)
    for pi in p:
        assert np.sum(np.abs(ev + pi) < 0.15) >= 3


def test_sampled_observer_loop_matches_drake_simulation(rnd, observer_cfg):
    """The lifted model (PD 10 Hz on PassiveObserver 20 Hz, Drake timing) against the real
    systems wired as in the exploration diagram (τ to the plant and the observer)."""
    xi, cfg = rnd.hydrodynamics, PdControllerConfig()
    lifted = st.sampled_pd_observer_loop(xi, cfg, observer_cfg)
    assert lifted.is_stable()
    q0 = 1e-4 * np.array([1.0, -0.7, 0.5, 0.3, 0.2, -0.4])
    xh0 = 1e-4 * np.array([0.5, 0.2, -0.3, 0.1, -0.2, 0.05, 0.0, 0.1, 0.2])  # [η̂, b̂, ν̂]
    s0 = np.concatenate([q0, xh0, np.zeros(3)])
    out = {}
    for sign in (1.0, -1.0):

        def build(b, sign=sign):
            plant = b.AddSystem(VesselPlant(rnd, initial_state=sign * q0))
            obs = b.AddSystem(PassiveObserver(xi, observer_cfg))
            pd = b.AddSystem(PdController(xi, cfg))
            ref = b.AddSystem(ConstantVectorSource(np.zeros(9)))
            demux = b.AddSystem(Demultiplexer([3, 3]))
            b.Connect(plant.GetOutputPort("state"), demux.get_input_port())
            b.Connect(demux.get_output_port(0), obs.GetInputPort("pose_measurement"))
            b.Connect(pd.GetOutputPort("tau_desired"), obs.GetInputPort("tau"))
            b.Connect(obs.GetOutputPort("state_estimate"), pd.GetInputPort("state_estimate"))
            b.Connect(obs.GetOutputPort("bias_estimate"), pd.GetInputPort("bias_estimate"))
            b.Connect(ref.get_output_port(), pd.GetInputPort("reference"))
            b.Connect(pd.GetOutputPort("tau_desired"), plant.GetInputPort("tau"))

            def init(diagram, root, sign=sign):
                x = sign * xh0
                obs.set_initial_estimate(obs.GetMyContextFromRoot(root), x[0:3], x[6:9], x[3:6])

            return {"plant": plant, "obs": obs, "pd": pd, "init": init}

        diagram, ctx, h = _simulate(build, 1.0)
        q = h["plant"].GetMyContextFromRoot(ctx).get_continuous_state_vector().CopyToVector()
        xh = h["obs"].GetMyContextFromRoot(ctx).get_discrete_state(0).CopyToVector()
        tau = h["pd"].GetMyContextFromRoot(ctx).get_discrete_state(0).CopyToVector()
        out[sign] = np.concatenate([q, xh, tau])
    sim = 0.5 * (out[1.0] - out[-1.0])
    pred = np.linalg.matrix_power(lifted.closed, 10) @ s0
    assert np.linalg.norm(sim - pred) < 1e-6 * np.linalg.norm(s0)


def test_baseline_loops_roboat2_closed_form(roboat):
    xi, g = roboat.hydrodynamics, ControlConfig()
    for los, drop in ((False, ["x", "y"]), (True, ["x"])):
        full = st.baseline_loop(roboat, g, 0.6, los)
        # the dropped states are structural integrators (s = 0)
        assert np.sum(np.abs(full.eigenvalues()) < 1e-9) >= len(drop)
        loop = full.reduced(drop)
        hand = st.baseline_closed_form(xi, g, 0.6, los)
        # the yaw double root −ω (ζ = 1, no LOS) is defective: eigenvalues to √eps
        assert matched_distance(loop.eigenvalues(), hand) < 1e-6
        assert loop.is_stable()
        samp = st.sampled_state_feedback(loop, 1.0 / g.rate_hz)
        assert samp.is_stable()
    # LOS Routh condition 2ζωΔ > u0 and its violation
    fast = ControlConfig(lookahead=0.3, heading_natural_frequency=0.8, heading_damping=0.2)
    assert 2 * 0.2 * 0.8 * 0.3 < 0.6
    assert not st.baseline_loop(roboat, fast, 0.6, True).reduced(["x"]).is_stable()


def test_baseline_jacobian_by_hand(roboat):
    """∂τ/∂q of the feedback-linearising law at the straight run, written out."""
    xi, g = roboat.hydrodynamics, ControlConfig()
    h = st.baseline_feedback(xi, g, 0.6, los=True)
    w, z, u0 = g.heading_natural_frequency, g.heading_damping, 0.6
    hand = np.zeros((3, 6))
    hand[0, 3] = -xi.m11 * g.surge_bandwidth
    hand[1, 4], hand[1, 5] = -xi.m22 * g.sway_bandwidth, xi.m11 * u0
    hand[2, 1] = -xi.m33 * w * w / g.lookahead  # ψ_d = atan(−y/Δ)
    hand[2, 2] = -xi.m33 * w * w
    hand[2, 4] = (xi.m22 - xi.m11) * u0
    hand[2, 5] = -2 * z * w * xi.m33 + xi.Nr
    np.testing.assert_allclose(h, hand, atol=1e-7)


def test_nmpc_gain_matches_the_qp(roboat):
    cfg = NmpcConfig()
    k0, _, _ = st.nmpc_feedback_gain(roboat, cfg, 0.6)
    p = NmpcProblem(roboat, cfg)
    t = np.arange(p.N + 1) * cfg.dt
    q_ref = np.zeros((p.N + 1, 6))
    q_ref[:, 0], q_ref[:, 3] = 0.6 * t, 0.6
    u_ref = p.feedforward(q_ref, np.zeros((p.N + 1, 3)))
    rng = np.random.default_rng(3)
    for _ in range(2):
        dq = rng.normal(size=6) * np.array([0.5, 0.5, 0.1, 0.1, 0.05, 0.05])
        sol = p.solve(q_ref[0] + dq, q_ref, u_ref, (q_ref.copy(), u_ref.copy()))
        assert sol.success
        np.testing.assert_allclose(sol.u[0] - u_ref[0], k0 @ dq, atol=1e-6)
    loop = st.nmpc_loop(roboat, cfg, 0.6)
    assert loop.is_stable()
    # without the offset-free filter the error states close with Φ + Γ B_thr K0 exactly; d̂
    # then never moves (z = 1) and the stored prediction is a pure delay (z = 0)
    lq = st.nmpc_loop(roboat, NmpcConfig(disturbance_gain=0.0), 0.6)
    a, b = st.linearize_plant(roboat, 0.6)
    phi, gam = st.zoh(a, b, cfg.dt)
    e_only = np.linalg.eigvals(phi + gam @ configuration_matrix(roboat.thrusters) @ k0)
    assert matched_distance(lq.eigenvalues(), np.concatenate([e_only, [1, 1, 1, 0, 0, 0]])) < 1e-6


# --- 3. margins ----------------------------------------------------------------------------------
@pytest.mark.parametrize("m, d, kp, kd", [(8.0, 0.0, 2.0, 3.0), (2.0, 0.0, 5.0, 1.0)])
def test_margin_double_integrator_closed_form(m, d, kp, kd):
    loop = st.LinearLoop(
        "di",
        np.array([[0.0, 1.0], [0.0, -d / m]]),
        np.array([[0.0], [1.0 / m]]),
        np.array([[-kp, -kd]]),
        0.0,
        ["x", "v"],
        ["x"],
    )
    mg = loop.margins(0)
    # |L(jω)| = 1 for L = (kp + kd s)/(m s²): m² ω⁴ − kd² ω² − kp² = 0
    wc = np.sqrt((kd**2 + np.sqrt(kd**4 + 4 * m**2 * kp**2)) / (2 * m**2))
    pm = np.degrees(np.arctan2(kd * wc, kp))
    assert abs(mg["phase_margin_deg"] - pm) < 1e-6
    assert abs(mg["gain_crossover_rad_s"] - wc) < 1e-6
    assert mg["gain_margin_db"] is None  # phase never reaches −180°
    assert st.pd_phase_margin(m, d, kp, kd) == pytest.approx((pm, wc), abs=1e-12)


def test_margins_round_pd_closed_form(rnd):
    xi, cfg = rnd.hydrodynamics, PdControllerConfig()
    kp, kd = pd_gains(xi, cfg)
    loop = st.pd_loop(xi, cfg)
    samp = st.sampled_state_feedback(loop, 0.1)
    mvec, dvec = xi.as_vector()[:3], xi.as_vector()[3:]
    for i in range(3):
        pm, wc = st.pd_phase_margin(mvec[i], dvec[i], kp[i, i], kd[i, i])
        mc = loop.margins(i)
        assert abs(mc["phase_margin_deg"] - pm) < 1e-6
        assert abs(mc["gain_crossover_rad_s"] - wc) < 1e-6
        assert mc["gain_margin_db"] is None
        ms = samp.margins(i)
        # the ZOH's T/2 delay costs ≈ ω_c T/2 of phase
        assert ms["phase_margin_deg"] == pytest.approx(pm - np.degrees(wc * 0.05), abs=0.3)
        assert ms["gain_margin_db"] > 15.0
    # yaw: the sampled velocity loop L ≈ (kd T/m)/(z − 1) reaches −180° at Nyquist, GM ≈ 2m/(kd T)
    gm = samp.margins(2)
    assert gm["phase_crossover_rad_s"] == pytest.approx(np.pi / 0.1)
    assert gm["gain_margin_db"] == pytest.approx(
        20 * np.log10(2 * xi.m33 / (kd[2, 2] * 0.1)), abs=0.5
    )


# --- 4. thrust box, Lyapunov, SOS region of attraction ------------------------------------------
@pytest.fixture(scope="module")
def roa_setup(rnd):
    xi = rnd.hydrodynamics
    kp, kd = pd_gains(xi, PdControllerConfig())
    tau_max, corners = st.thrust_box(rnd)
    roa = st.region_of_attraction(xi, kp, kd, tau_max)
    return xi, kp, kd, tau_max, corners, roa


def test_thrust_box_is_attainable_and_maximal(rnd, roa_setup):
    _, _, _, tau_max, corners, _ = roa_setup
    np.testing.assert_allclose(tau_max, [4.898, 3.5854, 0.42652], rtol=2e-4)
    alloc = ThrustAllocator(rnd.thrusters, rnd.allocation_weight)
    b = extended_matrix(rnd.thrusters)
    signs = [(sx, sy, sn) for sx in (1, -1) for sy in (1, -1) for sn in (1, -1)]
    for sgn, z in zip(signs, corners, strict=True):
        corner = tau_max * np.array(sgn)
        np.testing.assert_allclose(b @ z, corner, atol=1e-6)
        assert np.all(np.hypot(z[0::2], z[1::2]) <= 2.5 + 1e-6)  # each azimuth ≤ 2.5 N
        assert alloc.allocate(corner).attainable
    # maximal: any 0.2 % bigger box has a corner the azimuths cannot produce
    assert any(not alloc.allocate(1.002 * tau_max * np.array(s)).attainable for s in signs)


def test_lyapunov_matrix_and_decomposition(roa_setup, roboat):
    xi, kp, kd, _, _, roa = roa_setup
    a = straight_run_jacobian(xi, 0.0) + st.input_matrix(xi) @ roa.K
    assert np.abs(a.T @ roa.P + roa.P @ a + np.eye(6)).max() < 1e-12
    assert np.linalg.eigvalsh(roa.P).min() > 0
    # round hull (m11 = m22): the Coriolis + kinematic part of V̇ vanishes identically
    assert roa.decomposed and roa.remainder == 0.0
    assert roa.rho_polynomial is None  # no limit from the polynomial terms: only saturation
    # Roboat II (m11 ≠ m22) with the same construction would not decompose
    rk, rd = pd_gains(roboat.hydrodynamics, PdControllerConfig())
    ar = straight_run_jacobian(roboat.hydrodynamics, 0.0)
    ar = ar + st.input_matrix(roboat.hydrodynamics) @ st.dp_error_feedback(rk, rd)
    assert st.coupling_remainder(roboat.hydrodynamics, st.lyapunov_matrix(ar)) > 1e-3


def test_roa_levels(roa_setup):
    _, _, _, tau_max, _, roa = roa_setup
    pinv = np.linalg.inv(roa.P)
    for i in range(3):  # the unsaturated ellipsoid touches |τ_i| = τ_max,i at ρ_box,i
        assert np.sqrt(roa.rho_box[i] * roa.K[i] @ pinv @ roa.K[i]) == pytest.approx(tau_max[i])
    assert roa.rho_unsaturated == pytest.approx(0.999 * roa.rho_box.min())
    assert roa.rho == pytest.approx(0.999 * min(roa.rho_channels.min(), roa.rho_wrap))
    assert roa.rho > 2 * roa.rho_unsaturated  # saturation handled exactly enlarges it


def _grid_rho_channel(roa, xi, ch, n=801):
    """Brute force in the channel's plane: min V_c over the points where V̇_c ≥ 0."""
    idx = _CHANNEL_STATES[ch]
    p = roa.P[np.ix_(idx, idx)]
    r = 1.3 * np.sqrt(roa.rho_channels[ch] * np.diag(np.linalg.inv(p)))
    g0, g1 = np.meshgrid(np.linspace(-r[0], r[0], n), np.linspace(-r[1], r[1], n))
    z = np.vstack([g0.ravel(), g1.ravel()])
    m = xi.as_vector()[ch]
    d = xi.as_vector()[3 + ch]
    tau = np.clip(roa.K[ch, idx] @ z, -roa.tau_max[ch], roa.tau_max[ch])
    zdot = np.vstack([z[1], (tau - d * z[1]) / m])
    v = np.einsum("in,ij,jn->n", z, p, z)
    vdot = 2 * np.einsum("in,ij,jn->n", z, p, zdot)
    bad = (vdot >= 0) & (v > 1e-9)
    return v[bad].min()


def test_sos_channel_levels_are_tight(roa_setup):
    xi, _, _, _, _, roa = roa_setup
    for ch in range(3):
        grid = _grid_rho_channel(roa, xi, ch)
        assert roa.rho_channels[ch] <= grid * (1 + 1e-6)  # a valid certificate
        assert roa.rho_channels[ch] >= 0.99 * grid  # and (nearly) the exact level


def test_roa_sampling_check_true_closed_loop(rnd, roa_setup):
    """Must hold: 10 000 states in {V ≤ ρ}, true nonlinear plant + saturated PD, V̇ < 0."""
    xi, kp, kd, _, _, roa = roa_setup
    chk = st.check_region_by_sampling(xi, kp, kd, roa, n=10_000, seed=11)
    assert chk["samples"] == 10_000
    assert np.all(chk["vdot"] < 0.0), chk["max_vdot"]
    assert chk["violations"] == 0
    assert chk["saturated_fraction"] > 0.1  # the saturation is exercised, not avoided
    v = np.einsum("ij,jk,ik->i", chk["z"], roa.P, chk["z"])
    assert v.max() <= roa.rho * (1 + 1e-12) and v.max() > 0.99 * roa.rho
    # the unsaturated region: no sample saturates, all decrease
    chk_u = st.check_region_by_sampling(xi, kp, kd, roa, roa.rho_unsaturated, n=10_000, seed=12)
    assert chk_u["violations"] == 0 and chk_u["saturated_fraction"] == 0.0
    # the check has teeth: twice the level contains states where V grows
    chk_2 = st.check_region_by_sampling(xi, kp, kd, roa, 2.0 * roa.rho, n=10_000, seed=13)
    assert chk_2["violations"] > 0


def test_true_vdot_matches_polynomial_model(roa_setup):
    """The chain-rule V̇ through vessel_derivatives + pd_tau equals 2 zᵀ P f(z, sat(Kz))."""
    xi, kp, kd, tau_max, _, roa = roa_setup
    rng = np.random.default_rng(5)
    z = st.sample_ellipsoid(roa.P, 3 * roa.rho, 200, rng)
    vdot, _ = st.true_vdot(xi, kp, kd, tau_max, roa.P, z, rng)
    w = np.clip(z @ roa.K.T, -tau_max, tau_max)
    f = st.dp_error_dynamics(xi, z.T, w.T).T
    np.testing.assert_allclose(vdot, 2 * np.einsum("ij,jk,ik->i", z, roa.P, f), atol=1e-9)


@pytest.mark.slow  # ~15-25 s SDP; still run by `make test` and CI
def test_full_sos_programme_agrees(roa_setup):
    xi, _, _, tau_max, _, roa = roa_setup
    full = st.sos_rho_full(xi, roa.K, roa.P, tau_max, 1e4)
    assert full == pytest.approx(roa.rho_channels.min(), rel=1e-4)


# --- 5. the top level --------------------------------------------------------------------------
def test_analyze_explore_writes_everything(tmp_path):
    r = st.analyze_stability("basin_explore", tmp_path, allocator_samples=300)
    data = json.loads((tmp_path / "analysis.json").read_text())
    assert data["scenario"] == "basin_explore"
    for name in ("poles.png", "bode_pd.png", "bode_pd_observer.png", "roa.png"):
        assert (tmp_path / name).stat().st_size > 10_000
    loops = data["loops"]
    assert loops["pd"]["continuous"]["stable"] and loops["pd"]["sampled"]["stable"]
    assert (
        loops["pd_observer"]["continuous"]["stable"] and loops["pd_observer"]["sampled"]["stable"]
    )
    assert data["separation"]["max_mismatch"] < 1e-6
    ly = data["lyapunov"]
    assert ly["sampling_check"]["violations"] == 0 and ly["sampling_check"]["samples"] == 10_000
    assert (
        ly["extent"]["at_rest_position_error_m"]
        > ly["extent_unsaturated"]["at_rest_position_error_m"]
    )
    text = st.format_table(r)
    assert "pd_observer" in text and "region of attraction" in text and "yaw" in text


def test_analyze_baseline_and_nmpc():
    r = st.analyze_stability("canal_demo")
    json.dumps(r)
    assert r["plant"]["trim_surge_speed_m_s"] == 0.6
    assert (
        matched_distance(
            [complex(*e) for e in r["plant"]["eigenvalues"]], [0, 0, 0, -0.2209, -0.298, -1.262]
        )
        < 5e-4
    )
    lp = r["loops"]["los_heading_speed"]
    assert lp["unregulated"] == ["x"] and lp["continuous"]["stable"] and lp["sampled"]["stable"]
    yaw = lp["margins"]["yaw"]
    assert yaw["continuous"]["phase_margin_deg"] > yaw["sampled"]["phase_margin_deg"] > 45
    assert "heading_speed" in st.format_table(r)
    n = st.analyze_stability("river_tracking")
    json.dumps(n)
    assert n["loops"]["nmpc_lq"]["sampled"]["stable"]
    assert isinstance(n["loops"]["nmpc_lq"]["continuous"], str)
    assert "nmpc_lq" in st.format_table(n)


def test_cli_analyze_stability_writes_json_and_plots(tmp_path, capsys):
    from usvdrake.cli import main

    assert (
        main(["analyze", "stability", "basin_explore", "--out", str(tmp_path), "--samples", "500"])
        == 0
    )
    out = capsys.readouterr().out
    assert "region of attraction" in out and "pd_observer" in out
    for name in ("analysis.json", "poles.png", "roa.png"):
        assert (tmp_path / name).is_file()
    assert main(["analyze", "stability", "no_such_scenario"]) == 2
