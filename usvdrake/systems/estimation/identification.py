"""Grey-box identification of ξ = [m11 m22 m33 Xu Yv Nr] by SQP: Roboat II §IV-A, eq. (9).

    min_ξ  Σ_trials Σ_t ε(t)ᵀ w ε(t)                                   (9a)
    s.t.   ξl ≤ ξ ≤ ξu                                                  (9b)
           ν̇ = M⁻¹ (τ − C(ν) ν − D ν)      (the velocity part of 9c)

Form implemented (output error / simulation error): for each trial the model is integrated from
that trial's *first measured* ν with the recorded τ = B f held between samples (zero-order hold),
by classical RK4 with ``substeps`` steps per sample interval; ε(t) = ν_measured(t) − ν_simulated(t)
at every later sample. (Starting from a *measured* ν puts that sample's noise into a transient
that decays over m/d ≲ 4.5 s; on 150 s trials this is negligible, on trials of tens of seconds
it biases ξ̂ by up to a few % — estimating ν(0) per trial would remove it, not done here.)
The kinematics (eq. 1) do not enter: in still water ν̇ does not depend on
η. Every trial is simulated in one batch (trials padded to the longest; padding has h = 0 and no
weight). The weight w (3×3) defaults to diag(σ_u⁻², σ_v⁻², σ_r⁻²) from the log's measurement
noise, which makes (9a) the negative log-likelihood of white Gaussian velocity noise (up to a
constant) and the cost dimensionless, ≈ the number of residuals at the truth.

The gradient is exact for this discrete cost: the forward sensitivities S = ∂ν_sim/∂ξ (3×6 per
sample) are propagated through the same RK4 stages (RK4 applied to the variational equation
Ṡ = ∂f/∂ν S + ∂f/∂ξ gives exactly the derivative of the RK4 map), in numpy over the trial batch.

SNOPT (an SQP method, as Roboat II uses because it keeps the bounds at every iterate) solves (9)
through Drake's MathematicalProgram. Decision variables are θ = log(ξ / ξ0), ξ0 the initial guess,
so all six are O(1) although ξ spans 16-190; the objective handed to SNOPT is (9a) divided by the
number of residuals. Uncertainty: the Gauss-Newton cov ξ̂ ≈ s² (Σ Sᵀ w S)⁻¹, s² = J / (n_residuals −
6), and, reported as σ, a robust sandwich estimate that allows for residuals correlated in time
(noise on the recorded thrust makes them so; see :meth:`OutputErrorProblem.covariance`).
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from pydrake.autodiffutils import AutoDiffXd, ExtractGradient, ExtractValue
from pydrake.solvers import CommonSolverOption, MathematicalProgram, SnoptSolver, SolverOptions

from usvdrake.systems.estimation.identification_data import (
    VELOCITY_NAMES,
    VELOCITY_UNITS,
    XI_NAMES,
    XI_UNITS,
    IdentificationLog,
)
from usvdrake.systems.estimation.output_error import (
    OutputErrorData,
    OutputErrorProblem,
    default_weight,
    simulate_velocities,
    xi_from_vector,
    xi_vector,
)
from usvdrake.typed_yaml import ConfigError
from usvdrake.vessel import Hydrodynamics

# Default start of a fit relative to the vessel file's ξ: each component 35-50 % off, in mixed
# directions, so that a fit on data simulated with that same file has to find its way.
DEFAULT_GUESS_FACTORS = (0.6, 1.4, 1.5, 0.65, 1.4, 0.6)


# --- the SQP fit ----------------------------------------------------------------------------


@dataclass
class IdentificationOptions:
    """Settings of :func:`identify` (bounds relative to the initial guess ξ0)."""

    lower_factor: float = 0.2  # ξl = lower_factor × ξ0 (eq. 9b)
    upper_factor: float = 5.0  # ξu = upper_factor × ξ0 (eq. 9b)
    substeps: int = 1  # RK4 steps per sample interval of the model (1 at 10 Hz: error ≪ noise)
    optimality_tolerance: float = 1e-8  # SNOPT "Major optimality tolerance"
    correlation_window_s: float = 10.0  # [s] lag window of the robust covariance (≈ 2 m11/Xu)
    major_iterations_limit: int = 300  # SNOPT "Major iterations limit"


@dataclass
class IdentificationResult:
    """ξ̂ and how it was found. Arrays are ordered [m11 m22 m33 Xu Yv Nr]."""

    xi: Hydrodynamics  # ξ̂ [kg, kg, kg m², kg/s, kg/s, kg m²/s]
    std: np.ndarray  # (6,) standard deviation of ξ̂ (robust sandwich), same units as ξ
    std_gauss_newton: np.ndarray  # (6,) the same from s² (Σ Sᵀ w S)⁻¹ (white-residual theory)
    xi_initial: Hydrodynamics  # ξ0, where SNOPT started
    lower: np.ndarray  # (6,) ξl
    upper: np.ndarray  # (6,) ξu
    cost: float  # (9a) at ξ̂
    initial_cost: float  # (9a) at ξ0
    n_residuals: int  # scalar residuals in (9a)
    residual_variance: float  # s² = cost / (n_residuals − 6); ≈ 1 if w matches the noise
    iterations: int  # SNOPT major iterations
    evaluations: int  # cost + gradient evaluations
    solve_time_s: float  # [s] wall time of the SNOPT solve
    success: bool  # SNOPT reported an optimal point
    status: str  # SNOPT's result, e.g. "SolutionResult.kSolutionFound (info 1)"
    at_bound: list[str] = field(default_factory=list)  # components within 0.1 % of a bound


class ScaledObjective:
    """The cost handed to SNOPT: (9a) / n_residuals as a function of θ = log(ξ / ξ0).

    Called with floats it returns a float; with AutoDiffXd (as Drake does for SNOPT) it returns
    an AutoDiffXd whose derivatives are the exact gradient ∂/∂θ = ξ ∘ ∂/∂ξ from the forward
    sensitivities, chained onto θ's own derivatives."""

    def __init__(self, problem: OutputErrorProblem, xi0: np.ndarray):
        self.problem, self.xi0 = problem, xi_vector(xi0)
        self.scale = 1.0 / problem.data.n_residuals
        self.evaluations = 0  # gradient evaluations so far

    def __call__(self, theta):
        if isinstance(theta[0], AutoDiffXd):
            xi = self.xi0 * np.exp(ExtractValue(theta).ravel())
            cost, grad, _ = self.problem.evaluate(xi)
            self.evaluations += 1
            return AutoDiffXd(cost * self.scale, (self.scale * grad * xi) @ ExtractGradient(theta))
        return self.problem.cost(self.xi0 * np.exp(np.asarray(theta, dtype=float))) * self.scale


def _major_iterations(print_file: Path) -> int | None:
    """SNOPT's "No. of major iterations" from its print file, if it wrote one."""
    if not print_file.is_file():
        return None
    for line in print_file.read_text(errors="replace").splitlines():
        if "No. of major iterations" in line:
            return int(line.split("No. of major iterations")[1].split()[0])
    return None


def identify(
    data: OutputErrorData,
    initial_guess: Hydrodynamics | np.ndarray,
    weight: np.ndarray,
    options: IdentificationOptions | None = None,
    lower: np.ndarray | None = None,
    upper: np.ndarray | None = None,
) -> IdentificationResult:
    """Solve eq. (9) with SNOPT from ``initial_guess`` ξ0 (bounds: ``lower``/``upper`` or the
    options' factors × ξ0; all in ξ's units [kg, kg, kg m², kg/s, kg/s, kg m²/s]). ``weight`` is
    w of (9a) [(s/m)², (s/m)², (s/rad)² for the default :func:`default_weight`]."""
    opt = options if options is not None else IdentificationOptions()
    xi0 = xi_vector(initial_guess)
    if xi0.shape != (6,) or np.any(~(xi0 > 0)):
        raise ConfigError("identification", "initial_guess", "six positive numbers", xi0)
    lo = xi_vector(lower) if lower is not None else opt.lower_factor * xi0
    hi = xi_vector(upper) if upper is not None else opt.upper_factor * xi0
    if np.any(~(lo > 0)) or np.any(~(lo <= xi0)) or np.any(~(xi0 <= hi)):
        raise ConfigError("identification", "bounds", "0 < ξl ≤ ξ0 ≤ ξu", f"{lo} / {hi}")
    problem = OutputErrorProblem(data, weight, opt.substeps)
    objective = ScaledObjective(problem, xi0)

    prog = MathematicalProgram()
    theta = prog.NewContinuousVariables(6, "log_xi_over_xi0")
    prog.AddCost(objective, theta, description="eq. 9a output error")
    prog.AddBoundingBoxConstraint(np.log(lo / xi0), np.log(hi / xi0), theta)
    solver = SnoptSolver()
    with tempfile.TemporaryDirectory() as tmp:
        print_file = Path(tmp) / "snopt.out"
        solver_options = SolverOptions()
        solver_options.SetOption(CommonSolverOption.kPrintFileName, str(print_file))
        solver_options.SetOption(solver.id(), "Major print level", 1)
        solver_options.SetOption(
            solver.id(), "Major optimality tolerance", opt.optimality_tolerance
        )
        solver_options.SetOption(solver.id(), "Major iterations limit", opt.major_iterations_limit)
        t0 = time.perf_counter()
        result = solver.Solve(prog, np.zeros(6), solver_options)
        solve_time = time.perf_counter() - t0
        iterations = _major_iterations(print_file)

    xi_hat = np.clip(xi0 * np.exp(result.GetSolution(theta)), lo, hi)
    cost = problem.cost(xi_hat)
    s2 = cost / max(data.n_residuals - 6, 1)
    try:
        cov_gn, cov_robust = problem.covariance(xi_hat, opt.correlation_window_s)
        std_gn, std = np.sqrt(np.diag(cov_gn)), np.sqrt(np.diag(cov_robust))
    except np.linalg.LinAlgError:  # Σ Sᵀ w S singular: the data do not excite every component
        std_gn = std = np.full(6, np.inf)
    info = result.get_solver_details().info
    near = (np.abs(np.log(xi_hat / lo)) < 1e-3) | (np.abs(np.log(hi / xi_hat)) < 1e-3)
    return IdentificationResult(
        xi=xi_from_vector(xi_hat),
        std=std,
        std_gauss_newton=std_gn,
        xi_initial=xi_from_vector(xi0),
        lower=lo,
        upper=hi,
        cost=cost,
        initial_cost=problem.cost(xi0),
        n_residuals=data.n_residuals,
        residual_variance=s2,
        iterations=iterations if iterations is not None else objective.evaluations,
        evaluations=objective.evaluations,
        solve_time_s=solve_time,
        success=result.is_success(),
        status=f"{result.get_solution_result()} (info {info})",
        at_bound=[name for name, b in zip(XI_NAMES, near, strict=True) if b],
    )


def identify_log(
    log: IdentificationLog,
    b: np.ndarray,
    initial_guess: Hydrodynamics | np.ndarray,
    options: IdentificationOptions | None = None,
    weight: np.ndarray | None = None,
) -> tuple[IdentificationResult, OutputErrorData]:
    """Fit ξ to a log (τ = B f, B (3 × n)); w defaults to the log's inverse noise variances."""
    data = OutputErrorData.from_trials(log.trials, b)
    w = weight if weight is not None else default_weight(log.velocity_std)
    return identify(data, initial_guess, w, options), data


# --- reporting ------------------------------------------------------------------------------


def result_dict(result: IdentificationResult, true_xi: Hydrodynamics | None = None) -> dict:
    """A JSON-ready summary (ξ̂, σ, ξ0, bounds, the truth and relative errors when known)."""
    out = {
        "xi": dataclasses.asdict(result.xi),
        "std": dict(zip(XI_NAMES, map(float, result.std), strict=True)),
        "std_gauss_newton": dict(zip(XI_NAMES, map(float, result.std_gauss_newton), strict=True)),
        "initial_xi": dataclasses.asdict(result.xi_initial),
        "lower": dict(zip(XI_NAMES, map(float, result.lower), strict=True)),
        "upper": dict(zip(XI_NAMES, map(float, result.upper), strict=True)),
        "units": dict(zip(XI_NAMES, XI_UNITS, strict=True)),
        "cost": result.cost,
        "initial_cost": result.initial_cost,
        "n_residuals": result.n_residuals,
        "residual_variance": result.residual_variance,
        "iterations": result.iterations,
        "evaluations": result.evaluations,
        "solve_time_s": result.solve_time_s,
        "success": result.success,
        "status": result.status,
        "at_bound": result.at_bound,
        "method": "Roboat II eq. (9): output-error least squares, RK4 + exact sensitivities, SNOPT",
    }
    if true_xi is not None:
        t = true_xi.as_vector()
        out["true_xi"] = dataclasses.asdict(true_xi)
        rel = np.abs(result.xi.as_vector() - t) / t
        out["rel_error"] = dict(zip(XI_NAMES, map(float, rel), strict=True))
    return out


def format_summary(result: IdentificationResult, true_xi: Hydrodynamics | None = None) -> str:
    """The fit as a table: component, ξ̂ ± σ, unit, ξ0 (and the truth with the relative error)."""
    est, x0 = result.xi.as_vector(), result.xi_initial.as_vector()
    head = f"{'':<4} {'estimate':>9} {'± σ':>8}  {'unit':<9} {'start':>8}"
    if true_xi is not None:
        head += f" {'true':>8} {'rel.err':>8}"
    lines = [head]
    for i, name in enumerate(XI_NAMES):
        line = f"{name:<4} {est[i]:>9.2f} {result.std[i]:>8.2f}  {XI_UNITS[i]:<9} {x0[i]:>8.2f}"
        if true_xi is not None:
            t = true_xi.as_vector()[i]
            line += f" {t:>8.2f} {100 * abs(est[i] - t) / t:>7.2f}%"
        if name in result.at_bound:
            line += "  (at a bound)"
        lines.append(line)
    lines.append(
        f"cost (9a) {result.initial_cost:.4g} → {result.cost:.4g} over {result.n_residuals} "
        f"residuals (s² = {result.residual_variance:.3f}); SNOPT {result.iterations} major "
        f"iterations, {result.evaluations} gradient evaluations, {result.solve_time_s:.2f} s, "
        f"{'converged' if result.success else 'NOT converged: ' + result.status}"
    )
    return "\n".join(lines)


def plot_fit(
    data: OutputErrorData,
    result: IdentificationResult,
    path: str | Path,
    trial: int = 0,
    substeps: int = 1,
    title: str = "",
) -> Path:
    """Measured vs simulated u, v, r of one trial with ξ̂ and with ξ0, plus the recorded τ."""
    n = int(data.mask[trial].sum()) + 1
    t = data.t[trial, :n]
    fitted, _ = simulate_velocities(result.xi.as_vector(), data, False, substeps)
    start, _ = simulate_velocities(result.xi_initial.as_vector(), data, False, substeps)
    fig = Figure(figsize=(11, 9.5), layout="constrained")
    axes = fig.subplots(4, 1, sharex=True)
    for j, ax in enumerate(axes[:3]):
        ax.plot(t, data.nu[trial, :n, j], ".", ms=2.5, color="0.55", label="measured")
        ax.plot(t, start[trial, :n, j], "--", lw=1.2, color="tab:orange", label="initial ξ0")
        ax.plot(t, fitted[trial, :n, j], lw=1.6, color="tab:blue", label="fitted ξ̂")
        meas = data.nu[trial, 1:n, j]
        rms_fit = np.sqrt(np.mean((meas - fitted[trial, 1:n, j]) ** 2))
        rms_start = np.sqrt(np.mean((meas - start[trial, 1:n, j]) ** 2))
        ax.set_ylabel(f"{VELOCITY_NAMES[j]} [{VELOCITY_UNITS[j]}]")
        ax.text(
            0.005,
            0.96,
            f"RMS error: fitted {rms_fit:.3g}, initial {rms_start:.3g} {VELOCITY_UNITS[j]}",
            transform=ax.transAxes,
            va="top",
            fontsize=8,
            bbox={"facecolor": "white", "alpha": 0.8, "edgecolor": "none"},
        )
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", ncol=3, fontsize=8)
    for j, (label, color) in enumerate(
        (("τu [N]", "tab:green"), ("τv [N]", "tab:purple"), ("τr [N m]", "tab:brown"))
    ):
        axes[3].step(t, data.tau[trial, :n, j], where="post", lw=0.9, color=color, label=label)
    axes[3].set_ylabel("recorded τ")
    axes[3].legend(loc="upper right", ncol=3, fontsize=8)
    axes[3].grid(alpha=0.3)
    axes[3].set_xlabel("time [s]")
    est = ", ".join(f"{k} {v:.4g}" for k, v in zip(XI_NAMES, result.xi.as_vector(), strict=True))
    fig.suptitle(
        (f"log {title}\n" if title else "")
        + f"trial {trial + 1}: output-error fit of Roboat II eq. (9) — ξ̂ = {est}",
        fontsize=10,
    )
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path
