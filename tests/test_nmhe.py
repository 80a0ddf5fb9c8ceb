"""NMHE of Roboat II §IV-C (eqs. 15-17) and the pose sensor that feeds it.

The core is checked on trajectories of the discrete model itself (``rollout``, Roboat II) with
measurements drawn at the RT standard deviations of eq. (16): velocity accuracy against finite
differences of the same positions, exact convergence on noiseless data, heading wrap-around,
missing samples, a constant unmodelled force, and the thrust Jacobian against AutoDiffXd. The
LeafSystem runs in a small diagram (plant + mixer + sensors) against ground truth, deterministic,
and survives failing solves.
"""

from functools import cache

import numpy as np
import pytest
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.solvers import MathematicalProgramResult
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput, Sine

from usvdrake.sensors.imu import Imu
from usvdrake.sensors.imu_model import ImuConfig
from usvdrake.sensors.pose_sensor import PoseSensor, PoseSensorConfig, measure_pose, wrap_angle
from usvdrake.sensors.thrust_sensor import ThrustSensor, ThrustSensorConfig, thrust_noise_scale
from usvdrake.systems.estimation.imu_interval import ImuIntervalMean
from usvdrake.systems.estimation.nmhe_model import NmheConfig, _thrust_model, screen_sample
from usvdrake.systems.estimation.nmhe_problem import NmheProblem
from usvdrake.systems.estimation.nmhe_system import Nmhe
from usvdrake.systems.vessel.thrust_mixer import ThrustMixer
from usvdrake.systems.vessel.thrusters import configuration_matrix, mix
from usvdrake.systems.vessel.vessel_discrete import rollout
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import load_vessel

ROBOAT = load_vessel("roboat2")
XI = ROBOAT.hydrodynamics
DT = 0.1  # [s] Roboat II: 10 Hz
POSE_STD = np.sqrt([0.0005, 0.0005, 0.0005, 0.0001])  # [m, m, rad, rad/s] RT⁻¹ of eq. (16)
FORCE_STD = 1.0  # [N] RT⁻¹ of eq. (16), per thruster
WARM_UP = 30  # samples before the errors are scored (window of 20 full, transient gone)


def thrust_pattern(n: int) -> np.ndarray:
    """Forces f1..f4 [N] (n, 4): ~11 N per surge thruster (u ≈ 0.6 m/s against Xu = 38 kg/s),
    a differential ±4 N for turns of up to ~0.15 rad/s, and the sway pair for some v."""
    t = DT * np.arange(n)
    f = np.zeros((n, 4))
    f[:, 0] = 11.4 + 4.0 * np.sin(0.2 * t)
    f[:, 1] = 11.4 - 4.0 * np.sin(0.2 * t)
    f[:, 2] = 3.0 * np.sin(0.3 * t)
    f[:, 3] = 3.0 * np.sin(0.3 * t + 1.0)
    return f


def simulate(f: np.ndarray, q0, tau_extra=(0.0, 0.0, 0.0)) -> np.ndarray:
    """True states q_0..q_{n−1} of the discrete model under forces f (n, 4), row k over
    [t_k, t_{k+1})."""
    tau = f @ configuration_matrix(ROBOAT.thrusters).T + np.asarray(tau_extra)
    return rollout(XI, np.asarray(q0, float), tau, DT)[: len(f)]


def measure(q: np.ndarray, f: np.ndarray, noise: bool, seed: int = 0):
    """Pose samples (ψ wrapped) and thrust readings at the RT stds of eq. (16)."""
    rng = np.random.default_rng(seed)
    z = q[:, [0, 1, 2, 5]].copy()
    u = f.copy()
    if noise:
        z += POSE_STD * rng.standard_normal(z.shape)
        u += FORCE_STD * rng.standard_normal(u.shape)
    z[:, 2] = wrap_angle(z[:, 2])
    return z, u


def run_nmhe(z: np.ndarray, u: np.ndarray, cfg: NmheConfig | None = None):
    """Estimates at each newest sample (n, 6) and the solutions."""
    # The rollout's thrust row k acts over [t_k, t_{k+1}): no sensor delay.
    cfg = cfg or NmheConfig(thrust_delay_samples=0)
    problem = NmheProblem(XI, ROBOAT.thrusters, cfg)
    window = problem.empty_window()
    sols = []
    for k in range(len(z)):
        window, sol = problem.step(window, z[k], u[k])
        sols.append(sol)
    return np.array([s.estimate for s in sols]), sols


def rmse(e: np.ndarray) -> np.ndarray:
    return np.sqrt(np.mean(np.square(e), axis=0))


@cache
def noisy_run():
    f = thrust_pattern(400)
    q = simulate(f, [0.0, 0.0, 3.0, 0.6, 0.0, 0.0])
    z, u = measure(q, f, noise=True, seed=1)
    est, sols = run_nmhe(z, u)
    return q, z, u, est, sols


# --- pose sensor -------------------------------------------------------------------------------


def test_pose_sensor_noise_matches_eq16_and_wraps_heading():
    cfg = PoseSensorConfig()
    assert cfg.std() == pytest.approx(POSE_STD)
    state = np.array([3.0, -2.0, 4.0, 0.6, 0.1, 0.2])  # ψ = 4 rad → wrapped to 4 − 2π
    z = np.array([measure_pose(state, cfg.std(), seed=5, k=k) for k in range(4000)])
    assert np.all((z[:, 2] >= -np.pi) & (z[:, 2] < np.pi))
    err = z - np.array([3.0, -2.0, 4.0 - 2.0 * np.pi, 0.2])
    assert np.mean(err, axis=0) == pytest.approx(np.zeros(4), abs=0.002)
    assert np.std(err, axis=0) == pytest.approx(POSE_STD, rel=0.05)
    assert np.array_equal(measure_pose(state, cfg.std(), 5, 17), z[17])  # keyed by (seed, k)


def test_pose_sensor_samples_and_holds_at_its_rate():
    state = np.array([1.0, 2.0, -3.1, 0.5, 0.0, 0.1])
    outputs = []
    for _ in range(2):
        sensor = PoseSensor(PoseSensorConfig(), seed=9)
        sim = Simulator(sensor)
        sensor.GetInputPort("state").FixValue(sim.get_mutable_context(), state)
        port = sensor.GetOutputPort("pose_measurement")
        assert np.all(port.Eval(sim.get_context()) == 0)
        sim.AdvanceTo(0.25)  # samples at 0, 0.1, 0.2: the output holds sample k = 2
        z = port.Eval(sim.get_context()).copy()
        assert np.array_equal(z, measure_pose(state, PoseSensorConfig().std(), 9, 2))
        sim.AdvanceTo(0.29)
        assert np.array_equal(port.Eval(sim.get_context()), z)
        outputs.append(z)
    assert np.array_equal(outputs[0], outputs[1])


# --- core --------------------------------------------------------------------------------------


def test_velocity_rmse_beats_finite_differences():
    q, z, _, est, sols = noisy_run()
    assert all(s.success for s in sols)
    assert 0.5 < np.mean(q[:, 3]) < 0.7 and np.ptp(q[:, 5]) > 0.2  # ~0.6 m/s with turns
    k = np.arange(WARM_UP, len(q))
    nmhe = rmse(est[k, 3:5] - q[k, 3:5])
    # Backward differences of the same noisy positions, rotated into the body frame by ψ_k.
    dxy = (z[k, :2] - z[k - 1, :2]) / DT
    c, s = np.cos(z[k, 2]), np.sin(z[k, 2])
    fd = np.column_stack([c * dxy[:, 0] + s * dxy[:, 1], -s * dxy[:, 0] + c * dxy[:, 1]])
    fd_rmse = rmse(fd - q[k, 3:5])
    assert np.all(nmhe <= 0.02), nmhe
    assert np.all(nmhe < fd_rmse / 10), (nmhe, fd_rmse)
    assert rmse(est[k, 5] - q[k, 5]) < POSE_STD[3]  # better than the gyro itself
    assert rmse(est[k, :2] - q[k, :2]).max() < POSE_STD[0]  # better than the pose itself


def test_noiseless_measurements_converge_to_truth():
    f = thrust_pattern(120)
    q = simulate(f, [5.0, -3.0, -1.0, 0.6, 0.05, 0.1])
    z, u = measure(q, f, noise=False)
    est, sols = run_nmhe(z, u)
    err = np.abs(est - q)
    assert err[0, 3] == pytest.approx(0.6)  # first sample: the prior's zero velocity
    assert err[25:].max() < 1e-3
    assert err[-1].max() < 1e-4
    assert max(abs(s.bias).max() for s in sols) < 1e-2  # no fake disturbance learnt


def test_condensed_solve_is_clarabels_answer():
    """The default solve (bounds left out, condensed, one Cholesky) gives the interior point's
    estimates on the noisy run, with and without IMU interval means in the window."""
    _, z, u, est, sols = noisy_run()
    assert all(s.status == "condensed" for s in sols[1:])
    clarabel = NmheConfig(thrust_delay_samples=0, solver="clarabel")
    est_c, sols_c = run_nmhe(z, u, clarabel)
    np.testing.assert_allclose(est, est_c, rtol=0, atol=1e-7)
    np.testing.assert_allclose([s.bias for s in sols], [s.bias for s in sols_c], rtol=0, atol=1e-6)
    assert [s.cost for s in sols[1:]] == pytest.approx([s.cost for s in sols_c[1:]], rel=1e-6)
    rng = np.random.default_rng(5)
    imu = np.column_stack([0.05 * rng.standard_normal((20, 2)), 0.01 * rng.standard_normal(20)])
    window = (z[100:120], u[100:120], est[100], est[100:120])
    a = NmheProblem(XI, ROBOAT.thrusters, NmheConfig(thrust_delay_samples=0))
    b = NmheProblem(XI, ROBOAT.thrusters, clarabel)
    sa, sb = (p.solve(*window, sols[119].bias, imu_window=imu) for p in (a, b))
    assert sa.status == "condensed" and sb.status != "condensed"
    np.testing.assert_allclose(sa.trajectory, sb.trajectory, rtol=0, atol=1e-7)
    np.testing.assert_allclose(sa.accel_bias, sb.accel_bias, rtol=0, atol=1e-7)


def test_condensed_solve_hands_an_active_bound_to_clarabel():
    """A surge bound below the boat's speed (0.6 m/s) is active: the condensed minimiser
    breaks it, so the interior point solves those windows, and the estimates obey it."""
    _, z, u, _, _ = noisy_run()
    bound = {"thrust_delay_samples": 0, "velocity_max": [0.55, 2.0, 2.0]}
    est, sols = run_nmhe(z[:60], u[:60], NmheConfig(**bound))
    est_c, _ = run_nmhe(z[:60], u[:60], NmheConfig(**bound, solver="clarabel"))
    assert all(s.success for s in sols)
    assert sum(s.status != "condensed" for s in sols) >= 30
    assert np.all(est[:, 3] <= 0.55 + 1e-6)
    np.testing.assert_allclose(est, est_c, rtol=0, atol=1e-6)


def test_heading_wraparound_causes_no_jump():
    n = 250
    f = np.tile([8.0, 15.0, 0.0, 0.0], (n, 1))  # a steady turn, ~0.13 rad/s: ψ crosses ±π
    q = simulate(f, [0.0, 0.0, 2.8, 0.5, 0.0, 0.0])
    z, u = measure(q, f, noise=True, seed=2)
    assert np.any(np.abs(np.diff(z[:, 2])) > np.pi)  # the measurements wrap (twice)
    est, _ = run_nmhe(z, u)
    k = slice(WARM_UP, None)
    assert np.max(np.abs(np.diff(est[:, 2]))) < 0.1  # ψ̂ continuous: no 2π jumps
    assert np.max(np.abs(wrap_angle(est[k, 2] - q[k, 2]))) < 0.05
    assert np.all(rmse(est[k, 3:5] - q[k, 3:5]) < 0.02)


def test_missing_pose_samples_are_bridged():
    f = thrust_pattern(150)
    q = simulate(f, [0.0, 0.0, 0.0, 0.6, 0.0, 0.0])
    z, u = measure(q, f, noise=True, seed=3)
    z[60:65] = np.nan  # a 0.5 s SLAM outage
    z[90, 2] = np.nan  # one heading lost
    est, sols = run_nmhe(z, u)
    assert all(s.success for s in sols)
    k = np.arange(WARM_UP, len(q))
    assert np.all(np.isfinite(est))
    assert np.abs(est[k, 3:5] - q[k, 3:5]).max() < 0.05


def test_constant_unmodelled_force_is_learnt():
    f = thrust_pattern(400)
    tau_env = np.array([3.0, 5.0, 0.5])  # [N, N, N m], e.g. wind plus current drag
    q = simulate(f, [0.0, 0.0, 0.0, 0.6, 0.0, 0.0], tau_env)
    z, u = measure(q, f, noise=True, seed=4)
    est, sols = run_nmhe(z, u)
    assert sols[-1].bias == pytest.approx(tau_env, abs=1.0)
    k = slice(100, None)
    assert np.all(rmse(est[k, 3:5] - q[k, 3:5]) < 0.015)


def test_estimated_thrust_and_forces_reproduce_the_trajectory():
    """The QP carries the total force error e_k; the recovered û_k (eq. 8's forces) and d̂_k
    must reproduce the estimated trajectory through the nonlinear model."""
    q, z, u, est, sols = noisy_run()
    s = sols[-1]
    n = len(q)
    assert s.thrust.shape == (19, 4) and s.disturbance.shape == (19, 3)
    readings = u[n - 20 : n - 1]
    assert np.abs(s.thrust - readings).max() < 4.0 * FORCE_STD
    tau = s.thrust @ configuration_matrix(ROBOAT.thrusters).T + s.disturbance + s.bias
    replay = rollout(XI, s.trajectory[0], tau, DT)
    assert np.abs(replay - s.trajectory).max() < 1e-3
    assert np.isfinite(s.cost) and s.cost > 0


def test_thrust_model_matches_mix_and_autodiff():
    for name in ("roboat2", "ntnu_round"):
        thrusters = load_vessel(name).thrusters
        rng = np.random.default_rng(0)
        n_u = sum(2 if t.azimuth else 1 for t in thrusters)
        cmd = rng.uniform(0.1, 2.0, (3, n_u))
        tau, jac = _thrust_model(thrusters, cmd)
        for i in range(3):
            x = InitializeAutoDiff(cmd[i]).ravel()
            t_ad = mix(thrusters, x)
            np.testing.assert_allclose(tau[i], ExtractValue(t_ad).ravel(), atol=1e-12)
            np.testing.assert_allclose(jac[i], ExtractGradient(t_ad), atol=1e-12)


def test_azimuth_vessel_runs():
    vessel = load_vessel("ntnu_round")
    problem = NmheProblem(vessel.hydrodynamics, vessel.thrusters, NmheConfig())
    window = problem.empty_window()
    cmd = np.array([0.5, 0.0, 0.5, 0.0, 0.5, 0.0])
    for k in range(25):
        window, sol = problem.step(window, [0.02 * k, 0.0, 0.0, 0.0], cmd)
        assert sol.success
    assert sol.estimate[3] == pytest.approx(0.2, abs=0.02)


def test_core_is_deterministic_and_rejects_bad_config():
    f = thrust_pattern(60)
    q = simulate(f, [0.0, 0.0, 0.0, 0.6, 0.0, 0.0])
    z, u = measure(q, f, noise=True, seed=5)
    a, _ = run_nmhe(z, u)
    b, _ = run_nmhe(z, u)
    assert np.array_equal(a, b)
    # Without the slow force the problem is eq. (15) plus d_k; b stays zero.
    c, sols = run_nmhe(z, u, NmheConfig(thrust_delay_samples=0, bias_std=[0.0, 0.0, 0.0]))
    assert all(s.success and not s.bias.any() for s in sols)
    assert np.abs(c[WARM_UP:, 3:5] - q[WARM_UP:, 3:5]).max() < 0.05
    for bad in (
        {"horizon": 1},
        {"pose_variance": [0.0, 1.0, 1.0, 1.0]},
        {"velocity_min": [3.0, -2.0, -2.0]},
        {"bias_std": [-1.0, 0.0, 0.0]},
        {"solver": "gurobi"},
    ):
        with pytest.raises(ValueError):
            NmheProblem(XI, ROBOAT.thrusters, NmheConfig(**bad))


# --- LeafSystem --------------------------------------------------------------------------------

COMMAND = np.array([9.0, 14.0, 2.0, 2.0])  # [N] constant: ~0.6 m/s in a left turn
Q0 = np.array([0.0, 0.0, 3.0, 0.6, 0.0, 0.0])  # ψ0 = 3 rad: the turn crosses ψ = π


def build_diagram(seed: int = 7, nmhe: Nmhe | None = None, imu: bool = False, waves: bool = False):
    """Plant + mixer + sensors + ``Nmhe`` under a constant command; ``imu``: with the IMU and
    its interval means wired in; ``waves``: a wave-like force (±40 N surge, ±30 N sway, ±8 N m
    yaw at 0.4-0.6 Hz) on the plant, which the NMHE's model does not know."""
    builder = DiagramBuilder()
    cmd = builder.AddNamedSystem("command", ConstantVectorSource(COMMAND))
    mixer = builder.AddNamedSystem("thrust_mixer", ThrustMixer(ROBOAT.thrusters))
    plant = builder.AddNamedSystem("plant", VesselPlant(ROBOAT, Q0))
    pose = builder.AddNamedSystem("pose_sensor", PoseSensor(PoseSensorConfig(), seed))
    tcfg = ThrustSensorConfig()
    thrust = builder.AddNamedSystem(
        "thrust_sensor", ThrustSensor(tcfg, seed, thrust_noise_scale(ROBOAT.thrusters, tcfg))
    )
    nmhe = builder.AddNamedSystem("nmhe", nmhe or Nmhe(ROBOAT))
    builder.Connect(cmd.get_output_port(), mixer.GetInputPort("thruster_command"))
    builder.Connect(mixer.GetOutputPort("tau"), plant.GetInputPort("tau"))
    builder.Connect(mixer.GetOutputPort("thrust_applied"), thrust.GetInputPort("thrust_applied"))
    builder.Connect(plant.GetOutputPort("state"), pose.GetInputPort("state"))
    builder.Connect(pose.GetOutputPort("pose_measurement"), nmhe.GetInputPort("pose_measurement"))
    builder.Connect(thrust.GetOutputPort("thrust_measured"), nmhe.GetInputPort("thrust_measured"))
    if waves:
        sine = builder.AddNamedSystem(
            "waves", Sine([40.0, 30.0, 8.0], [2.8, 3.5, 3.1], [0.0, 1.0, 2.0], 3)
        )
        builder.Connect(sine.get_output_port(0), plant.GetInputPort("tau_env"))
    if imu:
        sensor = builder.AddNamedSystem("imu", Imu(ImuConfig(), seed))
        mean = builder.AddNamedSystem(
            "imu_mean", ImuIntervalMean(DT, 0.01, offset=0.5 * NmheConfig().update_offset)
        )
        builder.Connect(plant.GetOutputPort("state"), sensor.GetInputPort("state"))
        builder.Connect(plant.GetOutputPort("acceleration"), sensor.GetInputPort("acceleration"))
        builder.Connect(sensor.GetOutputPort("imu"), mean.GetInputPort("imu"))
        builder.Connect(mean.GetOutputPort("imu_mean"), nmhe.GetInputPort("imu_mean"))
    logs = {
        "truth": LogVectorOutput(plant.GetOutputPort("state"), builder, DT),
        "estimate": LogVectorOutput(nmhe.GetOutputPort("state_estimate"), builder, DT),
        "estimate_time": LogVectorOutput(nmhe.GetOutputPort("estimate_time"), builder, DT),
        "failures": LogVectorOutput(nmhe.GetOutputPort("nmhe_failures"), builder, DT),
        "solve_ms": LogVectorOutput(nmhe.GetOutputPort("nmhe_solve_ms"), builder, DT),
    }
    return builder.Build(), nmhe, logs


def truth_at(truth: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The logged truth (rows at k·DT) interpolated linearly at ``times``."""
    grid = DT * np.arange(len(truth))
    return np.column_stack([np.interp(times, grid, truth[:, i]) for i in range(6)])


def run_diagram(diagram, logs, duration: float):
    sim = Simulator(diagram)
    sim.AdvanceTo(duration)
    ctx = sim.get_context()
    return ctx, {k: log.FindLog(ctx).data().T.copy() for k, log in logs.items()}


@cache
def diagram_run():
    diagram, nmhe, logs = build_diagram()
    ctx, data = run_diagram(diagram, logs, 20.0)
    return diagram, nmhe, logs, ctx, data


def test_leaf_system_ports():
    nmhe = Nmhe(ROBOAT)
    assert [nmhe.get_input_port(i).get_name() for i in range(3)] == [
        "pose_measurement",
        "thrust_measured",
        "imu_mean",
    ]
    assert nmhe.GetInputPort("thrust_measured").size() == 4
    assert [nmhe.get_output_port(i).get_name() for i in range(5)] == [
        "state_estimate",
        "tau_env_estimate",
        "nmhe_failures",
        "nmhe_solve_ms",
        "estimate_time",
    ]
    # Before the first solve the output is the initial guess.
    q0 = np.array([1.0, 2.0, 0.5, 0.3, 0.0, 0.0])
    est = Nmhe(ROBOAT, initial_state=q0)
    ctx = est.CreateDefaultContext()
    assert np.array_equal(est.GetOutputPort("state_estimate").Eval(ctx), q0)


def test_leaf_system_tracks_ground_truth_in_a_diagram():
    _, nmhe, _, ctx, data = diagram_run()
    truth, est = data["truth"], data["estimate"]
    assert truth[:, 2].max() > np.pi + 0.5  # the heading crossed π
    # The update at t_k + 1 ms estimates q(t_k) from the samples just taken and holds it
    # propagated to t_k + 2 ms (when the NMPC reads it): a logger at t_{k+1} sees that one.
    t_est = data["estimate_time"][:, 0]
    assert np.allclose(t_est[2:], DT * np.arange(1, len(t_est) - 1) + 0.002)
    k = slice(WARM_UP, None)
    err = est[k] - truth_at(truth, t_est)[k]
    err[:, 2] = wrap_angle(err[:, 2])
    assert np.all(rmse(err[:, 3:5]) <= 0.02), rmse(err)
    assert np.all(rmse(err[:, :2]) <= 0.03), rmse(err)
    assert rmse(err[:, 2]) < 0.02
    assert np.max(np.abs(np.diff(est[k, 2]))) < 0.1  # ψ̂ continuous across ±π
    assert data["failures"][-1, 0] == 0
    assert np.all(data["solve_ms"][2:, 0] > 0)
    diag = nmhe.diagnostics(nmhe.GetMyContextFromRoot(ctx))
    assert diag["failures"] == 0 and diag["solves"] == 200  # updates at 0.001 … 19.901 s
    window = nmhe.window(nmhe.GetMyContextFromRoot(ctx))
    assert window.count == 20 and np.all(np.isfinite(window.z))


def test_leaf_system_is_deterministic():
    diagram, _, logs, _, data = diagram_run()
    _, again = run_diagram(diagram, logs, 20.0)  # a fresh context of the same diagram
    assert np.array_equal(again["estimate"], data["estimate"])
    diagram2, _, logs2 = build_diagram()
    _, rebuilt = run_diagram(diagram2, logs2, 20.0)
    assert np.array_equal(rebuilt["estimate"], data["estimate"])


class FailingSolver:
    """Stands in for Clarabel: every solve fails (or raises)."""

    def __init__(self, raise_error: bool = False):
        self.raise_error = raise_error

    def Solve(self, prog, initial_guess=None, options=None):
        if self.raise_error:
            raise RuntimeError("solver crashed")
        return MathematicalProgramResult()  # solution_result not set: is_success() is False


@pytest.mark.parametrize("raise_error", [False, True])
def test_failed_solves_are_counted_and_the_estimate_coasts(raise_error):
    # the interior-point path (the condensed solve never calls Clarabel with inactive bounds)
    nmhe = Nmhe(ROBOAT, NmheConfig(solver="clarabel"), initial_state=Q0)
    diagram, nmhe, logs = build_diagram(nmhe=nmhe)
    ok_ctx, ok = run_diagram(diagram, logs, 1.0)
    nmhe.problem._solver = FailingSolver(raise_error)
    ctx, data = run_diagram(diagram, logs, 1.0)
    assert data["failures"][-1, 0] == 10  # every update from 0.001 to 0.901 s
    est, truth = data["estimate"], data["truth"]
    assert np.all(np.isfinite(est))
    # Coasting on the model from the initial state: the constant-thrust motion is predicted.
    assert np.abs(est[-1, :2] - truth[-1, :2]).max() < 0.1
    assert nmhe.diagnostics(nmhe.GetMyContextFromRoot(ctx))["failures"] == 10
    assert nmhe.diagnostics(nmhe.GetMyContextFromRoot(ok_ctx))["failures"] == 0


# --- insane readings ----------------------------------------------------------------------------
def test_insane_readings_are_screened_counted_and_bridged():
    f = thrust_pattern(150)
    q = simulate(f, [0.0, 0.0, 0.0, 0.6, 0.0, 0.0])
    z, u = measure(q, f, noise=True, seed=3)
    z[60, 0] = np.inf  # a broken x
    z[61] = 1e300  # a corrupt record
    z[62, 3] = -np.inf  # a broken gyro
    u[70] = np.nan  # a thrust reading lost
    u[71, 0] = 1e12  # a unit-confused force
    problem = NmheProblem(XI, ROBOAT.thrusters, NmheConfig(thrust_delay_samples=0))
    window, est, screened = problem.empty_window(), [], 0
    for k in range(len(z)):
        zk, uk, skipped = screen_sample(z[k], u[k], window.u[-1])
        screened += skipped
        window, sol = problem.step(window, zk, uk)
        assert sol.success
        est.append(sol.estimate)
    est = np.array(est)
    assert screened == 5
    assert np.all(np.isfinite(est))
    k = np.arange(WARM_UP, len(q))
    assert np.abs(est[k, 3:5] - q[k, 3:5]).max() < 0.05


def test_leaf_system_screens_non_finite_poses_and_counts_them():
    nmhe = Nmhe(ROBOAT, initial_state=np.array([0.0, 0.0, 0.0, 0.5, 0.0, 0.0]))
    sim = Simulator(nmhe)
    ctx = sim.get_mutable_context()
    nmhe.GetInputPort("pose_measurement").FixValue(ctx, [np.inf, 0.0, np.nan, 1e9])
    nmhe.GetInputPort("thrust_measured").FixValue(ctx, [np.nan, 1e30, 0.0, 0.0])
    sim.AdvanceTo(1.05)
    diag = nmhe.GetOutputPort("nmhe_diagnostics").Eval(ctx)
    assert diag[6] == diag[1] >= 10  # every sample screened
    assert np.all(np.isfinite(nmhe.GetOutputPort("state_estimate").Eval(ctx)))
