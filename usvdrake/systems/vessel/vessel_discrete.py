"""Discrete-time vessel model for the optimisers (NMPC, NMHE, identification).

q_{k+1} = F(q_k, τ_k) is one classical Runge-Kutta 4 step of Roboat II eq. (7)
(``vessel_derivatives``,
still water) over h seconds with τ held constant (zero-order hold), batched over many (q, τ)
pairs. :func:`rk4_with_jacobians` also returns A = ∂F/∂q and B = ∂F/∂τ, propagated exactly
through the four stages from the analytic continuous Jacobians of :func:`continuous_jacobians`
(differentiated by hand below; checked against AutoDiffXd in the tests).
"""

import numpy as np

from usvdrake.systems.vessel.vessel_dynamics import vessel_derivatives
from usvdrake.vessel import Hydrodynamics

ZERO2 = np.zeros(2)


def f_batch(xi: Hydrodynamics, q: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """q̇ for a batch: q (N, 6), τ (N, 3) → (N, 6), still water, no τ_env."""
    zeros = np.zeros(len(q))
    return vessel_derivatives(xi, q.T, tau.T, (zeros, zeros, zeros), (zeros, zeros)).T


def continuous_jacobians(xi: Hydrodynamics, q: np.ndarray) -> np.ndarray:
    """∂f/∂q (N, 6, 6) of eqs. (1)-(6) at a batch of states q (N, 6):

        ẋ = u cψ − v sψ,  ẏ = u sψ + v cψ,  ψ̇ = r
        m11 u̇ = τu + m22 v r − Xu u
        m22 v̇ = τv − m11 u r − Yv v
        m33 ṙ = τr − (m22 − m11) u v − Nr r
    (∂f/∂τ = [0; M⁻¹] is constant: :func:`input_jacobian`)."""
    psi, u, v, r = q[:, 2], q[:, 3], q[:, 4], q[:, 5]
    c, s = np.cos(psi), np.sin(psi)
    j = np.zeros((len(q), 6, 6))
    j[:, 0, 2], j[:, 0, 3], j[:, 0, 4] = -s * u - c * v, c, -s
    j[:, 1, 2], j[:, 1, 3], j[:, 1, 4] = c * u - s * v, s, c
    j[:, 2, 5] = 1.0
    j[:, 3, 3], j[:, 3, 4], j[:, 3, 5] = -xi.Xu / xi.m11, xi.m22 * r / xi.m11, xi.m22 * v / xi.m11
    j[:, 4, 3], j[:, 4, 4], j[:, 4, 5] = -xi.m11 * r / xi.m22, -xi.Yv / xi.m22, -xi.m11 * u / xi.m22
    d = (xi.m22 - xi.m11) / xi.m33
    j[:, 5, 3], j[:, 5, 4], j[:, 5, 5] = -d * v, -d * u, -xi.Nr / xi.m33
    return j


def input_jacobian(xi: Hydrodynamics) -> np.ndarray:
    """∂f/∂τ (6, 3)."""
    g = np.zeros((6, 3))
    g[3:, :] = np.diag([1.0 / xi.m11, 1.0 / xi.m22, 1.0 / xi.m33])
    return g


def rk4(xi: Hydrodynamics, q: np.ndarray, tau: np.ndarray, h: float) -> np.ndarray:
    """One RK4 step for a batch (N, 6) with inputs (N, 3) held over h [s]."""
    k1 = f_batch(xi, q, tau)
    k2 = f_batch(xi, q + 0.5 * h * k1, tau)
    k3 = f_batch(xi, q + 0.5 * h * k2, tau)
    k4 = f_batch(xi, q + h * k3, tau)
    return q + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4_with_jacobians(xi: Hydrodynamics, q: np.ndarray, tau: np.ndarray, h: float):
    """(q_next (N, 6), A (N, 6, 6), B (N, 6, 3)) of one RK4 step."""
    g = input_jacobian(xi)
    eye = np.eye(6)
    k1 = f_batch(xi, q, tau)
    q2 = q + 0.5 * h * k1
    k2 = f_batch(xi, q2, tau)
    q3 = q + 0.5 * h * k2
    k3 = f_batch(xi, q3, tau)
    q4 = q + h * k3
    k4 = f_batch(xi, q4, tau)
    j1, j2, j3, j4 = (continuous_jacobians(xi, x) for x in (q, q2, q3, q4))
    a1 = j1
    a2 = j2 @ (eye + 0.5 * h * a1)
    a3 = j3 @ (eye + 0.5 * h * a2)
    a4 = j4 @ (eye + h * a3)
    b1 = np.broadcast_to(g, (len(q), 6, 3))
    b2 = j2 @ (0.5 * h * b1) + g
    b3 = j3 @ (0.5 * h * b2) + g
    b4 = j4 @ (h * b3) + g
    q_next = q + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    a = eye + h / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
    b = h / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
    return q_next, a, b


def rollout(xi: Hydrodynamics, q0: np.ndarray, taus: np.ndarray, h: float) -> np.ndarray:
    """States (N + 1, 6) from q0 under inputs τ_0..τ_{N−1} (N, 3)."""
    out = np.empty((len(taus) + 1, 6))
    out[0] = q0
    for k in range(len(taus)):
        out[k + 1] = rk4(xi, out[k : k + 1], taus[k : k + 1], h)[0]
    return out
