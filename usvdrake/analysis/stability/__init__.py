"""Closed-loop stability analysis: linearisations, pole maps, margins, Lyapunov/SOS regions.

Everything here is numerical and checkable by hand; the tests compare each piece with a closed
form. Conventions: plant state q = [x y ψ u v r] (Roboat II eq. 7), generalised force τ = [X Y N]
(body frame), a controller is linearised as τ − τ* = H (state − trim).

The package is cut by job: ``linearisation`` (the plant about a straight run, ZOH, Jacobians),
``loops`` (:class:`LinearLoop`: closed-loop eigenvalues, loop transfer functions, margins),
``controller_loops`` (the PD, PD + observer, baseline/LOS and NMPC loops), ``lyapunov`` (thrust
box, error dynamics, Lyapunov matrix, SOS programmes), ``roa`` (the region of attraction and its
check by sampling), ``plots`` (pole map, Bode, ROA figures) and ``report`` (the top-level
:func:`analyze_stability` and :func:`format_table`). This module re-exports the names imported
elsewhere in the repository."""

from __future__ import annotations

from usvdrake.analysis.stability.controller_loops import (
    baseline_closed_form,
    baseline_feedback,
    baseline_loop,
    nmpc_feedback_gain,
    nmpc_loop,
    observer_error_matrix,
    pd_characteristic_roots,
    pd_loop,
    pd_observer_loop,
    sampled_pd_observer_loop,
)
from usvdrake.analysis.stability.linearisation import (
    input_matrix,
    linearize_plant,
    straight_run_eigenvalues,
    zoh,
)
from usvdrake.analysis.stability.loops import (
    LinearLoop,
    pd_phase_margin,
    sampled_state_feedback,
)
from usvdrake.analysis.stability.lyapunov import (
    coupling_remainder,
    dp_error_dynamics,
    dp_error_feedback,
    lyapunov_matrix,
    sos_rho_full,
    thrust_box,
)
from usvdrake.analysis.stability.report import (
    analyze_stability,
    format_table,
)
from usvdrake.analysis.stability.roa import (
    check_region_by_sampling,
    region_of_attraction,
    sample_ellipsoid,
    true_vdot,
)

__all__ = [
    "LinearLoop",
    "analyze_stability",
    "baseline_closed_form",
    "baseline_feedback",
    "baseline_loop",
    "check_region_by_sampling",
    "coupling_remainder",
    "dp_error_dynamics",
    "dp_error_feedback",
    "format_table",
    "input_matrix",
    "linearize_plant",
    "lyapunov_matrix",
    "nmpc_feedback_gain",
    "nmpc_loop",
    "observer_error_matrix",
    "pd_characteristic_roots",
    "pd_loop",
    "pd_observer_loop",
    "pd_phase_margin",
    "region_of_attraction",
    "sample_ellipsoid",
    "sampled_pd_observer_loop",
    "sampled_state_feedback",
    "sos_rho_full",
    "straight_run_eigenvalues",
    "thrust_box",
    "true_vdot",
    "zoh",
]
