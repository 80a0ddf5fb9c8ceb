"""The region of attraction of the round vessel's PD loop: the ROA coordinate names,
:class:`RegionOfAttraction` (the certificate and its extents), :func:`region_of_attraction`
(the Lyapunov function and SOS levels from the programmes of
:mod:`usvdrake.analysis.stability.lyapunov`, whose docstring derives them) and the check of a
claimed region by sampling the true nonlinear closed loop.

The claimed region is checked by sampling (:func:`check_region_by_sampling`): uniform states in
{V ≤ ρ}, mapped to full plant states about random set-points, the *true* vector field
(``vessel_derivatives`` with ``pd_tau`` clipped to the box), V̇ by the chain rule. Outside the
box the real allocation (W-weighted projection onto the attainable set) is not the box clip: the
saturated region certifies the clip model, the unsaturated one the real vessel (inside the box
the allocator reproduces τ exactly).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from usvdrake.analysis.stability.linearisation import input_matrix
from usvdrake.analysis.stability.lyapunov import (
    coupling_remainder,
    dp_error_feedback,
    lyapunov_matrix,
    sos_rho_channel,
    sos_rho_full,
    sos_rho_polynomial,
)
from usvdrake.angles import wrap_angle
from usvdrake.systems.control.pd_controller import pd_tau
from usvdrake.systems.vessel.vessel_dynamics import straight_run_jacobian, vessel_derivatives
from usvdrake.vessel import Hydrodynamics

ERROR_STATES = ["e_x", "e_y", "psi_err", "u", "v", "r"]  # the ROA coordinates (body frame)
_CHANNEL_STATES = ([0, 3], [1, 4], [2, 5])  # (position-like, velocity-like) per DOF


@dataclass
class RegionOfAttraction:
    """The Lyapunov certificate of the round vessel's PD loop (module docstring)."""

    P: np.ndarray  # V = zᵀ P z, z = [e_x, e_y, ψ̃, u, v, r]
    Q: np.ndarray
    K: np.ndarray  # τ = K z
    tau_max: np.ndarray  # [N, N, N m] the box
    rho: float  # claimed level with the box-clip saturation model
    rho_unsaturated: float  # claimed level of the unsaturated region
    rho_box: np.ndarray  # per channel: {V ≤ ρ} inside |τ_i| ≤ τ_max,i
    rho_wrap: float  # {V ≤ ρ} inside |ψ̃| ≤ π
    rho_polynomial: float | None  # SOS level of the unsaturated dynamics (None: ≥ the cap)
    rho_channels: np.ndarray | None  # saturated SOS level per channel (decomposed programme)
    decomposed: bool
    remainder: float  # max |coefficient| of the coupling terms of V̇
    solver: str
    solve_seconds: float

    def extents(self, rho: float | None = None) -> dict:
        """Largest |z_i| over {V ≤ ρ} in physical units, and the at-rest slices."""
        rho = self.rho if rho is None else rho
        pinv = np.linalg.inv(self.P)
        ext = np.sqrt(rho * np.diag(pinv))
        return {
            "position_error_m": float(max(ext[0], ext[1])),
            "heading_error_deg": float(np.degrees(ext[2])),
            "surge_m_s": float(ext[3]),
            "sway_m_s": float(ext[4]),
            "yaw_rate_deg_s": float(np.degrees(ext[5])),
            "at_rest_position_error_m": float(np.sqrt(rho / max(self.P[0, 0], self.P[1, 1]))),
            "at_rest_heading_error_deg": float(np.degrees(np.sqrt(rho / self.P[2, 2]))),
        }


def region_of_attraction(
    xi: Hydrodynamics,
    kp: np.ndarray,
    kd: np.ndarray,
    tau_max: np.ndarray,
    q: np.ndarray | None = None,
    solver_name: str = "clarabel",
    method: str = "auto",
    back_off: float = 1e-3,
) -> RegionOfAttraction:
    """Quadratic Lyapunov function and SOS region estimates (module docstring). ``method``:
    "auto" (decompose when the coupling terms vanish), "full" (the 9-variable programme)."""
    t0 = time.perf_counter()
    k = dp_error_feedback(kp, kd)
    a = straight_run_jacobian(xi, 0.0) + input_matrix(xi) @ k
    q = np.eye(6) if q is None else np.asarray(q, float)
    p = lyapunov_matrix(a, q)
    pinv = np.linalg.inv(p)
    rho_box = np.array([tau_max[i] ** 2 / (k[i] @ pinv @ k[i]) for i in range(3)])
    rho_wrap = float(np.pi**2 / pinv[2, 2])
    cap = 1e3 * float(max(rho_box.max(), rho_wrap))
    rho_poly = sos_rho_polynomial(xi, k, p, cap, solver_name)
    rho_poly = None if rho_poly > 0.99 * cap else rho_poly
    remainder = coupling_remainder(xi, p)
    block_diag = all(
        np.max(np.abs(p[np.ix_(ci, cj)])) == 0.0
        for i, ci in enumerate(_CHANNEL_STATES)
        for j, cj in enumerate(_CHANNEL_STATES)
        if i != j
    )
    k_diag = all(
        np.max(np.abs(k[i, [c for c in range(6) if c not in _CHANNEL_STATES[i]]])) == 0.0
        for i in range(3)
    )
    decomposed = method == "auto" and block_diag and k_diag and remainder <= 1e-12 * np.abs(p).max()
    a_open = straight_run_jacobian(xi, 0.0)
    b_open = input_matrix(xi)
    if decomposed:
        rho_ch = []
        for i, idx in enumerate(_CHANNEL_STATES):
            ix = np.ix_(idx, idx)
            rho_ch.append(
                sos_rho_channel(
                    p[ix], a_open[ix], b_open[idx, i], k[i, idx], tau_max[i], cap, solver_name
                )
            )
        rho_channels = np.array(rho_ch)
        rho_sat = float(rho_channels.min())
    else:
        rho_channels = None
        rho_sat = sos_rho_full(xi, k, p, tau_max, cap, solver_name)
    scale = 1.0 - back_off
    rho_unsat = min(float(rho_box.min()), rho_wrap, np.inf if rho_poly is None else rho_poly)
    return RegionOfAttraction(
        P=p,
        Q=q,
        K=k,
        tau_max=np.asarray(tau_max, float),
        rho=scale * min(rho_sat, rho_wrap),
        rho_unsaturated=scale * rho_unsat,
        rho_box=rho_box,
        rho_wrap=rho_wrap,
        rho_polynomial=rho_poly,
        rho_channels=rho_channels,
        decomposed=decomposed,
        remainder=remainder,
        solver=solver_name,
        solve_seconds=time.perf_counter() - t0,
    )


def sample_ellipsoid(p: np.ndarray, rho: float, n: int, rng: np.random.Generator) -> np.ndarray:
    """n points uniform in {zᵀ P z ≤ ρ} (n × dim)."""
    dim = len(p)
    d = rng.standard_normal((n, dim))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    radius = rng.random(n) ** (1.0 / dim)
    ell = np.linalg.cholesky(p)  # P = L Lᵀ, z = L⁻ᵀ y with ‖y‖² ≤ ρ
    return np.linalg.solve(ell.T, (np.sqrt(rho) * radius[:, None] * d).T).T


def true_vdot(
    xi: Hydrodynamics,
    kp: np.ndarray,
    kd: np.ndarray,
    tau_max: np.ndarray,
    p: np.ndarray,
    z: np.ndarray,
    rng: np.random.Generator,
    allocator=None,
) -> tuple[np.ndarray, np.ndarray]:
    """(V̇, saturated (n × 3, per channel)) at error states z (n × 6) through the true closed
    loop: each z becomes a plant state about a random set-point η_d, τ = ``pd_tau`` clipped to
    the box (or passed through ``allocator``, a ``ThrustAllocator``), q̇ =
    ``vessel_derivatives``, and V̇ = 2 zᵀ P ż with ż from q̇ by the chain rule
    (e = Rᵀ(ψ)(p − p_d))."""
    n = len(z)
    eta_d = np.column_stack(
        [rng.uniform(-50, 50, n), rng.uniform(-50, 50, n), rng.uniform(-np.pi, np.pi, n)]
    )
    psi = wrap_angle(eta_d[:, 2] + z[:, 2])
    c, s = np.cos(psi), np.sin(psi)
    pos = eta_d[:, :2] + np.column_stack([c * z[:, 0] - s * z[:, 1], s * z[:, 0] + c * z[:, 1]])
    q = np.column_stack([pos, psi, z[:, 3:6]])
    tau = np.empty((n, 3))
    for i in range(n):
        ref = np.concatenate([eta_d[i], np.zeros(6)])
        tau[i] = pd_tau(xi, kp, kd, q[i], ref)
    saturated = np.abs(tau) > tau_max
    if allocator is None:
        applied = np.clip(tau, -tau_max, tau_max)
    else:
        applied = np.array([allocator.allocate(t).tau_achieved for t in tau])
    zeros = np.zeros(n)
    qdot = vessel_derivatives(xi, q.T, applied.T, (zeros, zeros, zeros), (zeros, zeros)).T
    # z recomputed from q (the true map), and its derivative
    dp = pos - eta_d[:, :2]
    e = np.column_stack([c * dp[:, 0] + s * dp[:, 1], -s * dp[:, 0] + c * dp[:, 1]])
    w = qdot[:, 2]
    de = np.column_stack(
        [
            c * qdot[:, 0] + s * qdot[:, 1] + w * (-s * dp[:, 0] + c * dp[:, 1]),
            -s * qdot[:, 0] + c * qdot[:, 1] + w * (-c * dp[:, 0] - s * dp[:, 1]),
        ]
    )
    zz = np.column_stack([e, wrap_angle(psi - eta_d[:, 2]), q[:, 3:6]])
    zdot = np.column_stack([de, w, qdot[:, 3:6]])
    return 2.0 * np.einsum("ij,jk,ik->i", zz, p, zdot), saturated


def check_region_by_sampling(
    xi: Hydrodynamics,
    kp: np.ndarray,
    kd: np.ndarray,
    roa: RegionOfAttraction,
    rho: float | None = None,
    n: int = 10_000,
    seed: int = 0,
    allocator=None,
) -> dict:
    """Sample n states uniformly in {V ≤ ρ} and evaluate the true V̇ (:func:`true_vdot`)."""
    rho = roa.rho if rho is None else rho
    rng = np.random.default_rng(seed)
    z = sample_ellipsoid(roa.P, rho, n, rng)
    vdot, sat = true_vdot(xi, kp, kd, roa.tau_max, roa.P, z, rng, allocator)
    v = np.einsum("ij,jk,ik->i", z, roa.P, z)
    return {
        "samples": int(n),
        "rho": float(rho),
        "all_decreasing": bool(np.all(vdot < 0.0)),
        "violations": int(np.sum(vdot >= 0.0)),
        "max_vdot": float(vdot.max()),
        "max_vdot_over_v": float(np.max(vdot / v)),
        "saturated_fraction": float(np.mean(np.any(sat, axis=1))),
        "saturated_fraction_per_channel": np.mean(sat, axis=0).tolist(),
        "z": z,
        "vdot": vdot,
        "saturated": sat,
    }
