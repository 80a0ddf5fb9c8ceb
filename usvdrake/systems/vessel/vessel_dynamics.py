"""3-DOF vessel dynamics of Roboat II §IV-A, eqs. (1)-(6), for any Drake scalar type.

    η̇ = T(ψ) ν                                             (1)
    ν̇ = M⁻¹ (τ + τ_env) − M⁻¹ (C(ν) ν + D (ν − ν_c))        (2) with drag on the relative velocity

η = [x y ψ] (world ENU), ν = [u v r] (body: x forward, y left). M = diag(m11, m22, m33) (4),
C(ν) exactly as eq. (5), D = diag(Xu, Yv, Nr) (6). The water current V_c (world frame, m/s) enters
through the drag only: ν_c = [R(ψ)ᵀ V_c, 0] (Fossen 2011 §10.3 relative-velocity form, linear
drag); the Coriolis term stays on ν as eq. (5) writes it. Eq. (5) keeps the same form in the
paper's y-starboard frame and in ours (flipping v and r maps it onto itself).

The functions take and return numpy arrays of float, AutoDiffXd or symbolic Expression, so the
LeafSystem, Linearize, MathematicalProgram and the tests share this one model.
"""

import math

import numpy as np

from usvdrake.vessel import Hydrodynamics


def rotation(psi):
    """T(ψ) of eq. (1): body → world rotation about z (3×3, object-safe)."""
    c, s = np.cos(psi), np.sin(psi)
    z = 0.0 * c
    return np.array([[c, -s, z], [s, c, z], [z, z, z + 1.0]])


def coriolis(xi: Hydrodynamics, nu) -> np.ndarray:
    """C(ν) of eq. (5): skew-symmetric Coriolis-centripetal matrix (rigid body + added mass)."""
    u, v, _ = nu
    z = 0.0 * u
    return np.array(
        [
            [z, z, -xi.m22 * v],
            [z, z, xi.m11 * u],
            [xi.m22 * v, -xi.m11 * u, z],
        ]
    )


def coriolis_times_velocity(xi: Hydrodynamics, nu) -> np.ndarray:
    """C(ν) ν of eq. (5) written out: [−m22 v r, m11 u r, (m22 − m11) u v]. Elementwise, so it
    also works on batches (each of u, v, r an array)."""
    u, v, r = nu[0], nu[1], nu[2]
    return np.array([-xi.m22 * v * r, xi.m11 * u * r, (xi.m22 - xi.m11) * u * v])


def current_in_body(psi, current_world) -> np.ndarray:
    """ν_c: the water velocity V_c = [Vx, Vy] (world) expressed in the body frame, zero yaw rate."""
    c, s = np.cos(psi), np.sin(psi)
    vx, vy = current_world[0], current_world[1]
    return np.array([c * vx + s * vy, -s * vx + c * vy, 0.0 * vx])


def vessel_derivatives(xi: Hydrodynamics, q, tau, tau_env, current_world) -> np.ndarray:
    """q̇ = f(q, τ) of eq. (7) for q = [x y ψ u v r]: eqs. (1), (2) with (4)-(6).

    Scalars may be float, AutoDiffXd or Expression; a batch works too (q of shape (6, N),
    τ (3, N), ...), which the discrete-time model of the controllers uses."""
    q = np.asarray(q)
    psi, nu = q[2], q[3:6]
    c, s = np.cos(psi), np.sin(psi)
    u, v, r = nu[0], nu[1], nu[2]
    eta_dot = [c * u - s * v, s * u + c * v, r]
    nu_c = current_in_body(psi, current_world)
    drag = [xi.Xu * (u - nu_c[0]), xi.Yv * (v - nu_c[1]), xi.Nr * r]
    cor = coriolis_times_velocity(xi, nu)
    m = (xi.m11, xi.m22, xi.m33)
    nu_dot = [(tau[i] + tau_env[i] - cor[i] - drag[i]) / m[i] for i in range(3)]
    return np.array(eta_dot + nu_dot)


def vessel_derivatives_float(xi: Hydrodynamics, q, tau, tau_env, current_world) -> np.ndarray:
    """:func:`vessel_derivatives` for one float state, in scalar math (a fifth of the cost; the
    plant calls it at every integrator stage)."""
    _, _, psi, u, v, r = np.asarray(q, dtype=float).tolist()
    c, s = math.cos(psi), math.sin(psi)
    vx, vy = float(current_world[0]), float(current_world[1])
    uc, vc = c * vx + s * vy, -s * vx + c * vy
    return np.array(
        [
            c * u - s * v,
            s * u + c * v,
            r,
            (float(tau[0]) + float(tau_env[0]) + xi.m22 * v * r - xi.Xu * (u - uc)) / xi.m11,
            (float(tau[1]) + float(tau_env[1]) - xi.m11 * u * r - xi.Yv * (v - vc)) / xi.m22,
            (float(tau[2]) + float(tau_env[2]) - (xi.m22 - xi.m11) * u * v - xi.Nr * r) / xi.m33,
        ]
    )


def trim_thrust(xi: Hydrodynamics, surge_speed: float) -> np.ndarray:
    """τ holding a straight run at ``surge_speed`` in still water: [Xu u, 0, 0] (eq. 2, ν̇ = 0)."""
    return np.array([xi.Xu * surge_speed, 0.0, 0.0])


def straight_run_jacobian(xi: Hydrodynamics, u0: float) -> np.ndarray:
    """∂f/∂q at a straight run q = [·, ·, 0, u0, 0, 0] with its trim thrust, derived by hand.

    Differentiating eqs. (1)-(6) at ψ = v = r = 0, u = u0:
      ẋ = u cosψ − v sinψ  → ∂/∂u = 1
      ẏ = u sinψ + v cosψ  → ∂/∂ψ = u0, ∂/∂v = 1
      ψ̇ = r
      m11 u̇ = m22 v r − Xu u            → −Xu/m11 on u (the v, r terms vanish at v = r = 0)
      m22 v̇ = −m11 u r − Yv v           → −Yv/m22 on v, −m11 u0/m22 on r
      m33 ṙ = −(m22 − m11) u v − Nr r    → −(m22 − m11) u0/m33 on v, −Nr/m33 on r
    The eigenvalues are therefore 0, 0, 0 (x, y, ψ: no restoring force), −Xu/m11 (surge), and
    the two eigenvalues of the 2×2 sway-yaw block.
    """
    a = np.zeros((6, 6))
    a[0, 3] = 1.0
    a[1, 2], a[1, 4] = u0, 1.0
    a[2, 5] = 1.0
    a[3, 3] = -xi.Xu / xi.m11
    a[4, 4], a[4, 5] = -xi.Yv / xi.m22, -xi.m11 * u0 / xi.m22
    a[5, 4], a[5, 5] = -(xi.m22 - xi.m11) * u0 / xi.m33, -xi.Nr / xi.m33
    return a
