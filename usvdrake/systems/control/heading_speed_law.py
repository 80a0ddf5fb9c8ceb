"""Baseline heading + speed control law for 3-DOF vessels (the demo's controller).

Model-based PD with feedback linearisation of Roboat II eqs. (2), (4)-(6) (Fossen 2011 §12.2):
    τ_X = Xu u_d + m11 k_u (u_d − u) − m22 v r
    τ_Y = −m22 k_v v + m11 u r                       (holonomic vessels hold zero sway)
    τ_N = m33 (ω² e_ψ − 2 ζ ω r) + Nr r + (m22 − m11) u v,   e_ψ = wrap(ψ_d − ψ)
so that, on the nominal model, ψ follows ψ̈ + 2ζω ψ̇ + ω² (ψ − ψ_d) = 0 and u relaxes to u_d with
rate k_u. The papers' controllers (NMPC, PD + observer + reference model) replace it.
"""

import numpy as np

from usvdrake.angles import wrap_angle
from usvdrake.systems.guidance.line_of_sight import ControlConfig
from usvdrake.vessel import Hydrodynamics


def heading_speed_tau(
    xi: Hydrodynamics, gains: ControlConfig, q: np.ndarray, heading_ref: float, speed_ref: float
) -> np.ndarray:
    """Desired generalised force [N, N, N m] (body frame) for state q = [x y ψ u v r]."""
    _, _, psi, u, v, r = q
    w, z = gains.heading_natural_frequency, gains.heading_damping
    e_psi = wrap_angle(heading_ref - psi)
    tau_x = xi.Xu * speed_ref + xi.m11 * gains.surge_bandwidth * (speed_ref - u) - xi.m22 * v * r
    tau_y = -xi.m22 * gains.sway_bandwidth * v + xi.m11 * u * r
    tau_n = xi.m33 * (w * w * e_psi - 2.0 * z * w * r) + xi.Nr * r + (xi.m22 - xi.m11) * u * v
    return np.array([tau_x, tau_y, tau_n])
