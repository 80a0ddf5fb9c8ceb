"""Grey-box identification (Roboat II eq. 9): recovery, exact gradients, bounds, log format, CLI."""

import json

import numpy as np
import pytest
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, InitializeAutoDiff

from usvdrake import cli
from usvdrake.systems.estimation.identification import (
    DEFAULT_GUESS_FACTORS,
    IdentificationOptions,
    ScaledObjective,
    identify,
)
from usvdrake.systems.estimation.identification_data import (
    ExcitationExperiment,
    fixed_thruster_matrix,
    read_log,
    simulate_experiment,
    write_log,
)
from usvdrake.systems.estimation.output_error import (
    OutputErrorData,
    OutputErrorProblem,
    default_weight,
    simulate_velocities,
    velocity_derivatives,
    velocity_jacobians,
)
from usvdrake.systems.vessel.vessel_discrete import rk4
from usvdrake.systems.vessel.vessel_dynamics import vessel_derivatives
from usvdrake.typed_yaml import ConfigError
from usvdrake.vessel import Hydrodynamics, load_vessel

VESSEL = load_vessel("roboat2")
B = fixed_thruster_matrix(VESSEL)
XI_TRUE = VESSEL.hydrodynamics.as_vector()
START = XI_TRUE * np.array(DEFAULT_GUESS_FACTORS)  # every component 35-50 % off
SHORT = ExcitationExperiment(trials=2, duration_s=30.0)
WEIGHT = default_weight(SHORT.velocity_std)


@pytest.fixture(scope="module")
def noisy_log():
    return simulate_experiment(VESSEL, seed=3, experiment=SHORT)


@pytest.fixture(scope="module")
def noisy_data(noisy_log):
    return OutputErrorData.from_trials(noisy_log.trials, B)


def test_noiseless_data_recover_xi():
    exp = ExcitationExperiment(
        trials=2, duration_s=30.0, velocity_std=(0.0, 0.0, 0.0), thrust_std=0.0
    )
    log = simulate_experiment(VESSEL, seed=1, experiment=exp)
    result = identify(OutputErrorData.from_trials(log.trials, B), START, WEIGHT)
    assert result.success, result.status
    rel = np.abs(result.xi.as_vector() - XI_TRUE) / XI_TRUE
    assert rel.max() < 0.005, rel
    assert result.cost < 1e-3 * result.initial_cost


def test_fast_simulation_equals_the_shared_plant_model(noisy_data):
    """The batched velocity loop against vessel_discrete.rk4 on the full state (eqs. 1-6)."""
    nu_sim, _ = simulate_velocities(XI_TRUE, noisy_data)
    q = np.hstack([np.zeros((2, 3)), noisy_data.nu[:, 0]])
    for k in range(50):
        q = rk4(VESSEL.hydrodynamics, q, noisy_data.tau[:, k], 0.1)
    np.testing.assert_allclose(nu_sim[:, 50], q[:, 3:], atol=1e-12)


def test_model_jacobians_match_autodiff_of_the_plant_model():
    rng = np.random.default_rng(0)
    for _ in range(3):
        nu, tau = rng.normal(0, 0.5, 3), rng.normal(0, 30, 3)
        x = InitializeAutoDiff(np.concatenate([nu, XI_TRUE])).ravel()
        xi_ad = Hydrodynamics(*x[3:])
        q = np.concatenate([[AutoDiffXd(0.0)] * 2, [AutoDiffXd(0.4)], x[:3]])
        f = vessel_derivatives(xi_ad, q, tau, np.zeros(3), np.zeros(2))[3:]
        grad = ExtractGradient(f)
        nu_dot = velocity_derivatives(XI_TRUE, nu[None], tau[None])
        a, p = velocity_jacobians(XI_TRUE, nu[None], nu_dot)
        np.testing.assert_allclose(nu_dot[0], [fi.value() for fi in f], atol=1e-12)
        np.testing.assert_allclose(a[0], grad[:, :3], atol=1e-12)
        np.testing.assert_allclose(p[0], grad[:, 3:], atol=1e-12)


def test_gradient_matches_finite_differences(noisy_data):
    problem = OutputErrorProblem(noisy_data, WEIGHT)
    xi = XI_TRUE * np.array([1.1, 0.9, 1.2, 0.85, 1.05, 0.95])
    cost, grad, _ = problem.evaluate(xi)
    assert cost == pytest.approx(problem.cost(xi), rel=1e-12)
    for i in range(6):
        d = 1e-6 * xi[i] * np.eye(6)[i]
        fd = (problem.cost(xi + d) - problem.cost(xi - d)) / (2 * d[i])
        assert grad[i] == pytest.approx(fd, rel=1e-5, abs=1e-6 * abs(grad).max())


def test_snopt_objective_floats_and_autodiff_agree(noisy_data):
    objective = ScaledObjective(OutputErrorProblem(noisy_data, WEIGHT), START)
    theta = np.array([0.1, -0.2, 0.05, 0.3, -0.1, 0.2])
    value = objective(theta)
    ad = objective(InitializeAutoDiff(theta).ravel())
    assert isinstance(value, float) and ad.value() == pytest.approx(value, rel=1e-12)
    for i in range(6):
        d = 1e-6 * np.eye(6)[i]
        fd = (objective(theta + d) - objective(theta - d)) / 2e-6
        assert ad.derivatives()[i] == pytest.approx(fd, rel=1e-5, abs=1e-8)


def test_bounds_are_respected(noisy_data):
    upper = XI_TRUE * 1.5
    upper[0] = 0.9 * XI_TRUE[0]  # m11's bound excludes the truth
    lower = XI_TRUE * 0.5
    result = identify(noisy_data, START, WEIGHT, lower=lower, upper=upper)
    xi = result.xi.as_vector()
    assert np.all(xi >= lower) and np.all(xi <= upper)
    assert xi[0] == pytest.approx(upper[0], rel=1e-6)
    assert "m11" in result.at_bound


def test_noisy_fit_is_close(noisy_data):
    """Only 2 × 30 s here, so a few % (bench/identification.py: 5 × 150 s, < 1 %)."""
    result = identify(noisy_data, START, WEIGHT, IdentificationOptions())
    assert result.success, result.status
    assert np.all(np.abs(result.xi.as_vector() - XI_TRUE) / XI_TRUE < 0.1)
    assert 0.8 < result.residual_variance < 3.0  # velocity noise, plus thrust noise propagated
    assert np.all(np.isfinite(result.std)) and np.all(result.std > 0)


def test_log_round_trip(tmp_path, noisy_log):
    read = read_log(write_log(noisy_log, tmp_path / "log"))
    assert read.vessel == "roboat2" and read.rate_hz == 10.0 and read.seed == 3
    assert read.velocity_std == SHORT.velocity_std and read.thrust_std == SHORT.thrust_std
    assert read.true_xi == VESSEL.hydrodynamics
    assert len(read.trials) == len(noisy_log.trials)
    for a, b in zip(read.trials, noisy_log.trials, strict=True):
        np.testing.assert_allclose(a.t, b.t, atol=5e-4)
        np.testing.assert_allclose(a.thrust, b.thrust, atol=5e-5)
        np.testing.assert_allclose(a.nu, b.nu, atol=5e-7)
    header = (tmp_path / "log" / "trial_01.csv").read_text().splitlines()[:3]
    assert header[0].startswith("#") and "roboat2" in header[0] and "[m/s]" in header[1]
    assert header[2] == "t,f1,f2,f3,f4,u,v,r"


@pytest.mark.parametrize(
    "corrupt, where",
    [
        (lambda lines: lines.__setitem__(10, lines[10].replace(",", ",abc,", 1)), "line 11"),
        (lambda lines: lines.__setitem__(10, "0.9,1,2,3"), "line 11"),
        (lambda lines: lines.__setitem__(2, "t,f1,f2,u,v,r"), "line 3"),
        (lambda lines: lines.__setitem__(10, lines[9]), "line 11, column t"),
    ],
)
def test_malformed_csv_names_the_file_and_line(tmp_path, noisy_log, corrupt, where):
    folder = write_log(noisy_log, tmp_path / "log")
    file = folder / "trial_02.csv"
    lines = file.read_text().splitlines()
    corrupt(lines)
    file.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError) as e:
        read_log(folder)
    message = str(e.value)
    assert str(file) in message and where in message and "\n" not in message


def test_malformed_meta_names_the_file(tmp_path, noisy_log):
    folder = write_log(noisy_log, tmp_path / "log")
    meta = json.loads((folder / "meta.json").read_text())
    meta["noise_std"]["r"] = -1
    (folder / "meta.json").write_text(json.dumps(meta))
    with pytest.raises(ConfigError, match="meta.json: key 'noise_std.r'"):
        read_log(folder)


def test_cli_missing_folder_exits_2(tmp_path, capsys):
    assert cli.main(["identify", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "missing" in err and len(err.splitlines()) == 1


def test_cli_generates_fits_and_writes_outputs(tmp_path, capsys):
    data, out = tmp_path / "data", tmp_path / "fit"
    argv = ["identify-data", str(data), "--seed", "2", "--trials", "1", "--duration", "20"]
    assert cli.main(argv) == 0
    assert cli.main(["identify", str(data), "--out", str(out), "--initial-guess", "1.4"]) == 0
    text = capsys.readouterr().out
    assert "m33" in text and "rel.err" in text
    summary = json.loads((out / "xi.json").read_text())
    assert set(summary["xi"]) == {"m11", "m22", "m33", "Xu", "Yv", "Nr"}
    assert max(summary["rel_error"].values()) < 0.1
    assert (out / "fit.png").stat().st_size > 10_000
    assert cli.main(["identify", str(data), "--initial-guess", "0,1"]) == 2
