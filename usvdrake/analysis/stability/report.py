"""The top-level analysis: :func:`analyze_stability` builds the loops of a scenario's controller,
their eigenvalues and margins, the plant linearisation and, for the explore PD, the region of
attraction report, and writes ``analysis.json`` with the plots; :func:`format_table` renders
that result as text."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from scipy.linalg import solve_discrete_lyapunov
from scipy.optimize import linear_sum_assignment

from usvdrake.analysis.stability.controller_loops import (
    baseline_loop,
    nmpc_loop,
    observer_error_matrix,
    pd_loop,
    pd_observer_loop,
    sampled_pd_observer_loop,
)
from usvdrake.analysis.stability.linearisation import (
    DEFAULT_TRIM_SPEED,
    input_matrix,
    linearize_plant,
    straight_run_eigenvalues,
    zoh,
)
from usvdrake.analysis.stability.loops import LinearLoop, sampled_state_feedback
from usvdrake.analysis.stability.lyapunov import thrust_box
from usvdrake.analysis.stability.plots import _plot_bode, _plot_poles, _plot_roa
from usvdrake.analysis.stability.roa import (
    ERROR_STATES,
    check_region_by_sampling,
    region_of_attraction,
)
from usvdrake.jsonable import jsonable
from usvdrake.scenario import Scenario, read_scenario
from usvdrake.systems.control.pd_controller import pd_gains
from usvdrake.systems.estimation.observer_dynamics import fossen_gains
from usvdrake.systems.vessel.thrust_allocation_problem import ThrustAllocator
from usvdrake.systems.vessel.vessel_dynamics import straight_run_jacobian
from usvdrake.vessel import VesselParams, load_vessel


# --- the top level -----------------------------------------------------------------------------
def _eig_list(ev) -> list[list[float]]:
    ev = np.asarray(ev, complex)
    ev = ev[np.lexsort((ev.imag, ev.real))]
    return [[float(x.real), float(x.imag)] for x in ev]


def _loop_entry(cont: LinearLoop | None, samp: LinearLoop | None, description: str) -> dict:
    out = {"description": description}
    ref = cont if cont is not None else samp
    out["states"] = list(ref.states)
    out["unregulated"] = list(ref.unregulated)
    if cont is not None:
        out["continuous"] = {
            "eigenvalues": _eig_list(cont.eigenvalues()),
            "max_real": cont.stability_measure(),
            "stable": cont.is_stable(),
        }
    else:
        out["continuous"] = "not applicable (discrete-time controller)"
    if samp is not None:
        out["sampled"] = {
            "period_s": samp.dt,
            "eigenvalues": _eig_list(samp.eigenvalues()),
            "max_abs": samp.stability_measure(),
            "stable": samp.is_stable(),
        }
    margins = {}
    for i, ch in enumerate(ref.channels):
        margins[ch] = {
            "continuous": cont.margins(i) if cont is not None else None,
            "sampled": samp.margins(i) if samp is not None else None,
        }
    out["margins"] = margins
    return out


def _default_trim(vessel: VesselParams) -> float:
    return min(DEFAULT_TRIM_SPEED, vessel.max_speed)


def analyze_stability(
    scenario: str | Path | Scenario,
    out_dir: str | Path | None = None,
    *,
    trim_speed: float | None = None,
    roa_samples: int = 10_000,
    allocator_samples: int = 2000,
    seed: int = 0,
) -> dict:
    """Stability of ``scenario``'s vessel and controller (module docstring); returns the JSON-able
    content of ``analysis.json`` and, with ``out_dir``, writes it with the plots (pole map, Bode
    plots with margins, region-of-attraction slices)."""
    sc = scenario if isinstance(scenario, Scenario) else read_scenario(scenario)
    vessel = load_vessel(sc.vessel)
    xi = vessel.hydrodynamics
    result = {
        "scenario": sc.name,
        "vessel": vessel.name,
        "controller": sc.controller,
        "estimator": sc.estimator,
        "notes": [],
    }
    loops: dict[str, tuple] = {}
    roa_data = None
    if sc.controller == "explore":
        u0 = 0.0
        cont = pd_loop(xi, sc.exploration.pd)
        samp = sampled_state_feedback(cont, 1.0 / sc.exploration.pd.rate_hz)
        loops["pd"] = (cont, samp, "DP PD on the exact state about rest (Fossen 2011 §12.2)")
        if sc.estimator == "observer":
            o = sc.exploration.observer
            obs = fossen_gains(xi, o.cutoff, T=o.bias_time_constant, rate_hz=o.rate_hz)
            c2 = pd_observer_loop(xi, sc.exploration.pd, obs)
            try:
                s2 = sampled_pd_observer_loop(xi, sc.exploration.pd, obs)
            except ValueError as exc:
                s2 = None
                result["notes"].append(f"sampled observer loop not analysed: {exc}")
            loops["pd_observer"] = (
                c2,
                s2,
                "PD on the passive observer's estimate (exact pose, commanded τ)",
            )
            result["separation"] = {
                "observer_error_eigenvalues": _eig_list(
                    np.linalg.eigvals(observer_error_matrix(obs, xi))
                ),
                "max_mismatch": _set_distance(
                    c2.eigenvalues(),
                    np.concatenate(
                        [cont.eigenvalues(), np.linalg.eigvals(observer_error_matrix(obs, xi))]
                    ),
                ),
            }
        roa_data = _roa_report(vessel, sc.exploration.pd, roa_samples, allocator_samples, seed)
        result["lyapunov"] = roa_data["report"]
    elif sc.controller == "baseline":
        u0 = _default_trim(vessel) if trim_speed is None else trim_speed
        inner = baseline_loop(vessel, sc.control, u0, los=False).reduced(["x", "y"])
        outer = baseline_loop(vessel, sc.control, u0, los=True).reduced(["x"])
        period = 1.0 / sc.control.rate_hz
        loops["heading_speed"] = (
            inner,
            sampled_state_feedback(inner, period),
            "heading/speed PD alone (x, y not regulated)",
        )
        loops["los_heading_speed"] = (
            outer,
            sampled_state_feedback(outer, period),
            f"LOS (Δ = {sc.control.lookahead} m) + heading/speed PD, path along x",
        )
        result["lyapunov"] = "not analysed (the Lyapunov/ROA analysis covers the explore PD)"
    else:
        u0 = _default_trim(vessel) if trim_speed is None else trim_speed
        try:
            loops["nmpc_lq"] = (
                None,
                nmpc_loop(vessel, sc.nmpc, u0),
                "NMPC's receding-horizon LQ gain about the straight run, offset-free filter "
                "included, exact state (the NMHE is not modelled)",
            )
        except ValueError as exc:
            result["notes"].append(f"NMPC loop not analysed: {exc}")
        result["lyapunov"] = "not analysed (the Lyapunov/ROA analysis covers the explore PD)"
    a, b = linearize_plant(vessel, u0)
    result["plant"] = {
        "trim_surge_speed_m_s": u0,
        "eigenvalues": _eig_list(np.linalg.eigvals(a)),
        "closed_form_eigenvalues": _eig_list(straight_run_eigenvalues(xi, u0)),
        "A": a.tolist(),
        "B": b.tolist(),
    }
    result["loops"] = {name: _loop_entry(c, s, d) for name, (c, s, d) in loops.items()}
    result = jsonable(result)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "analysis.json").write_text(json.dumps(result, indent=2))
        files = [_plot_poles(loops, out / "poles.png", sc.name)]
        for name, (c, s, _) in loops.items():
            files.append(_plot_bode(c, s, out / f"bode_{name}.png", name))
        if roa_data is not None:
            files.append(_plot_roa(roa_data, out / "roa.png"))
        result["files"] = [str(f) for f in files]
        (out / "analysis.json").write_text(json.dumps(result, indent=2))
    return result


def _set_distance(a, b) -> float:
    """Largest distance of an optimal one-to-one matching of two eigenvalue sets."""
    a, b = np.asarray(a, complex), np.asarray(b, complex)
    if len(a) != len(b):
        return float("inf")
    cost = np.abs(a[:, None] - b[None, :])
    r, c = linear_sum_assignment(cost)
    return float(cost[r, c].max())


def _roa_report(vessel, pd_cfg, n, n_alloc, seed) -> dict:
    xi = vessel.hydrodynamics
    kp, kd = pd_gains(xi, pd_cfg)
    t0 = time.perf_counter()
    tau_max, _ = thrust_box(vessel)
    box_s = time.perf_counter() - t0
    roa = region_of_attraction(xi, kp, kd, tau_max)
    check = check_region_by_sampling(xi, kp, kd, roa, n=n, seed=seed)
    check_u = check_region_by_sampling(xi, kp, kd, roa, roa.rho_unsaturated, n=n, seed=seed + 1)
    report = {
        "loop": "round vessel PD on the exact state (no observer), continuous-time law",
        "coordinates": ERROR_STATES,
        "Q": roa.Q.tolist(),
        "P": roa.P.tolist(),
        "tau_max": roa.tau_max.tolist(),
        "thrust_box_seconds": box_s,
        "rho": roa.rho,
        "rho_unsaturated": roa.rho_unsaturated,
        "rho_box_per_channel": roa.rho_box.tolist(),
        "rho_wrap": roa.rho_wrap,
        "rho_polynomial_sos": roa.rho_polynomial,
        "rho_saturated_sos_per_channel": None
        if roa.rho_channels is None
        else roa.rho_channels.tolist(),
        "decomposed": roa.decomposed,
        "coupling_remainder": roa.remainder,
        "solver": roa.solver,
        "solve_seconds": roa.solve_seconds,
        "extent": roa.extents(),
        "extent_unsaturated": roa.extents(roa.rho_unsaturated),
        "sampling_check": {k: v for k, v in check.items() if k not in ("z", "vdot", "saturated")},
        "sampling_check_unsaturated": {
            k: v for k, v in check_u.items() if k not in ("z", "vdot", "saturated")
        },
    }
    if n_alloc > 0:
        alloc = ThrustAllocator(vessel.thrusters, vessel.allocation_weight)
        chk = check_region_by_sampling(xi, kp, kd, roa, n=n_alloc, seed=seed + 2, allocator=alloc)
        report["allocator_check"] = {
            "note": "the real thrust allocation instead of the box clip (not certified)",
            **{k: v for k, v in chk.items() if k not in ("z", "vdot", "saturated")},
        }
    a_cl = straight_run_jacobian(xi, 0.0) + input_matrix(xi) @ roa.K
    phi, gam = zoh(straight_run_jacobian(xi, 0.0), input_matrix(xi), 1.0 / pd_cfg.rate_hz)
    pd_ = solve_discrete_lyapunov((phi + gam @ roa.K).T, np.eye(6))
    report["sampled_lyapunov_min_eig"] = float(np.linalg.eigvalsh(0.5 * (pd_ + pd_.T)).min())
    report["continuous_lyapunov_residual"] = float(
        np.abs(a_cl.T @ roa.P + roa.P @ a_cl + roa.Q).max()
    )
    return {"report": report, "roa": roa, "check": check}


def format_table(result: dict) -> str:
    """A readable text summary of :func:`analyze_stability`'s result."""

    def fmt(x, spec=".3g", none="inf"):
        return none if x is None else format(x, spec)

    def eigs(ev):
        parts = []
        for re, im in ev:
            parts.append(f"{re:.4g}" if abs(im) < 1e-12 else f"{re:.4g}{im:+.4g}j")
        return ", ".join(parts)

    lines = [
        f"Stability analysis: {result['scenario']} (vessel {result['vessel']}, controller "
        f"{result['controller']}, estimator {result['estimator']})",
        "",
        f"Plant about u0 = {result['plant']['trim_surge_speed_m_s']} m/s: eigenvalues "
        + eigs(result["plant"]["eigenvalues"]),
        "",
        f"{'loop':<20}{'continuous max Re':>19}{'stable':>8}{'sampled max |z|':>17}"
        f"{'T [s]':>7}{'stable':>8}",
    ]
    for name, lp in result["loops"].items():
        c, s = lp["continuous"], lp.get("sampled")
        cre = f"{c['max_real']:.4f}" if isinstance(c, dict) else "n/a"
        cst = ("yes" if c["stable"] else "NO") if isinstance(c, dict) else "n/a"
        sab = f"{s['max_abs']:.4f}" if s else "n/a"
        sdt = f"{s['period_s']:.3g}" if s else ""
        sst = ("yes" if s["stable"] else "NO") if s else "n/a"
        lines.append(f"{name:<20}{cre:>19}{cst:>8}{sab:>17}{sdt:>7}{sst:>8}")
        if lp["unregulated"]:
            lines.append(
                f"{'':<20}(unregulated integrators dropped: {', '.join(lp['unregulated'])})"
            )
    lines += [
        "",
        "Margins, loop broken at the plant input (others closed): GM [dB] / PM [deg] @ ω_c [rad/s]",
        f"{'loop':<20}{'channel':<8}{'continuous':>30}{'sampled':>30}",
    ]
    for name, lp in result["loops"].items():
        for ch, m in lp["margins"].items():
            cols = []
            for key in ("continuous", "sampled"):
                v = m[key]
                if v is None:
                    cols.append("n/a")
                else:
                    cols.append(
                        f"{fmt(v['gain_margin_db'], '.1f')} / {fmt(v['phase_margin_deg'], '.1f')}"
                        f" @ {fmt(v['gain_crossover_rad_s'], '.3f', 'none')}"
                    )
            lines.append(f"{name:<20}{ch:<8}{cols[0]:>30}{cols[1]:>30}")
    if "separation" in result:
        lines += [
            "",
            "Separation principle (PD + observer): max eigenvalue mismatch "
            f"{result['separation']['max_mismatch']:.2e}",
        ]
    ly = result.get("lyapunov")
    if isinstance(ly, dict):
        ext, extu = ly["extent"], ly["extent_unsaturated"]
        chk = ly["sampling_check"]
        lines += [
            "",
            f"Lyapunov / region of attraction ({ly['loop']})",
            f"  box |τ| ≤ [{ly['tau_max'][0]:.3f} N, {ly['tau_max'][1]:.3f} N, "
            f"{ly['tau_max'][2]:.3f} N m]",
            f"  unsaturated region ρ = {ly['rho_unsaturated']:.4g}: at rest |e| ≤ "
            f"{extu['at_rest_position_error_m']:.2f} m or |ψ̃| ≤ "
            f"{extu['at_rest_heading_error_deg']:.1f}°",
            f"  with box saturation ρ = {ly['rho']:.4g}: at rest |e| ≤ "
            f"{ext['at_rest_position_error_m']:.2f} m or |ψ̃| ≤ "
            f"{ext['at_rest_heading_error_deg']:.1f}°; extents |e| {ext['position_error_m']:.2f} "
            f"m, |u|,|v| {ext['surge_m_s']:.2f} m/s, |r| {ext['yaw_rate_deg_s']:.0f}°/s",
            f"  SOS: {ly['solver']}, {ly['solve_seconds']:.2f} s, "
            f"{'per-channel' if ly['decomposed'] else 'full'} programme",
            f"  sampling check: {chk['samples']} states, {chk['violations']} with V̇ ≥ 0, "
            f"max V̇/V = {chk['max_vdot_over_v']:.3g}, "
            f"saturated {100 * chk['saturated_fraction']:.0f} %",
        ]
        if "allocator_check" in ly:
            ac = ly["allocator_check"]
            lines.append(
                f"  real allocation (not certified): {ac['violations']}/{ac['samples']} with V̇ ≥ 0"
            )
    elif ly:
        lines += ["", f"Lyapunov: {ly}"]
    for note in result.get("notes", []):
        lines.append(f"note: {note}")
    return "\n".join(lines)
