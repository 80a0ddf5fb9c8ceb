"""Discrete-time vessel model for the optimisers (NMPC, NMHE, identification).

q_{k+1} = F(q_k, τ_k) is one classical Runge-Kutta 4 step of Roboat II eq. (7)
(``vessel_derivatives``,
still water) over h seconds with τ held constant (zero-order hold), batched over many (q, τ)
pairs. :func:`rk4_with_jacobians` also returns A = ∂F/∂q and B = ∂F/∂τ, propagated exactly
through the four stages from the analytic continuous Jacobians of :func:`continuous_jacobians`
(differentiated by hand below; checked against AutoDiffXd in the tests). Float batches take
compiled kernels (:func:`_rk4_kernel`, :func:`_rk4_jacobians_kernel`: the same arithmetic in
scalar loops, the NMPC and the NMHE call them every sample); other scalar types the numpy path.
"""

import numpy as np
from numba import njit

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


def _floats(*arrays) -> bool:
    return all(isinstance(a, np.ndarray) and a.dtype == np.float64 and a.ndim == 2 for a in arrays)


def rk4(xi: Hydrodynamics, q: np.ndarray, tau: np.ndarray, h: float) -> np.ndarray:
    """One RK4 step for a batch (N, 6) with inputs (N, 3) held over h [s]."""
    if _floats(q, tau):
        return _rk4_kernel(xi.as_vector(), q, tau, float(h))[0]
    k1 = f_batch(xi, q, tau)
    k2 = f_batch(xi, q + 0.5 * h * k1, tau)
    k3 = f_batch(xi, q + 0.5 * h * k2, tau)
    k4 = f_batch(xi, q + h * k3, tau)
    return q + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)


def rk4_with_jacobians(xi: Hydrodynamics, q: np.ndarray, tau: np.ndarray, h: float):
    """(q_next (N, 6), A (N, 6, 6), B (N, 6, 3)) of one RK4 step."""
    if _floats(q, tau):
        return _rk4_kernel(xi.as_vector(), q, tau, float(h), True)
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


@njit(cache=True)
def _derivative(p, q, tau, out):
    """q̇ of eq. (7) for one state (still water): the arithmetic of ``vessel_derivatives``."""
    m11, m22, m33, xu, yv, nr = p[0], p[1], p[2], p[3], p[4], p[5]
    psi, u, v, r = q[2], q[3], q[4], q[5]
    c, s = np.cos(psi), np.sin(psi)
    out[0] = c * u - s * v
    out[1] = s * u + c * v
    out[2] = r
    out[3] = (tau[0] - (-m22 * v * r) - xu * u) / m11
    out[4] = (tau[1] - m11 * u * r - yv * v) / m22
    out[5] = (tau[2] - (m22 - m11) * u * v - nr * r) / m33


@njit(cache=True)
def _jacobian(p, q, j):
    """∂f/∂q at one state, as :func:`continuous_jacobians`."""
    m11, m22, m33, xu, yv, nr = p[0], p[1], p[2], p[3], p[4], p[5]
    psi, u, v, r = q[2], q[3], q[4], q[5]
    c, s = np.cos(psi), np.sin(psi)
    j[:] = 0.0
    j[0, 2], j[0, 3], j[0, 4] = -s * u - c * v, c, -s
    j[1, 2], j[1, 3], j[1, 4] = c * u - s * v, s, c
    j[2, 5] = 1.0
    j[3, 3], j[3, 4], j[3, 5] = -xu / m11, m22 * r / m11, m22 * v / m11
    j[4, 3], j[4, 4], j[4, 5] = -m11 * r / m22, -yv / m22, -m11 * u / m22
    d = (m22 - m11) / m33
    j[5, 3], j[5, 4], j[5, 5] = -d * v, -d * u, -nr / m33


@njit(cache=True)
def _propagate(j, scale, prev, add_g, ginv, out):
    """out = j (I·[prev is None] + scale · prev) (+ G): one stage's sensitivity. For A (6 × 6)
    the identity is added to scale · prev; for B (6 × 3) G = [0; M⁻¹] is added after."""
    n_col = out.shape[1]
    for i in range(6):
        for k in range(n_col):
            acc = 0.0
            for m in range(6):
                x = scale * prev[m, k]
                if n_col == 6 and m == k:
                    x += 1.0
                acc += j[i, m] * x
            out[i, k] = acc
        if add_g and i >= 3:
            out[i, i - 3] += ginv[i - 3]


@njit(cache=True)
def _rk4_kernel(p, q, tau, h, jacobians=False):
    """RK4 steps of a batch (and A, B of each when asked; else empty arrays)."""
    n = q.shape[0]
    q_next = np.empty((n, 6))
    a = np.empty((n if jacobians else 0, 6, 6))
    b = np.empty((n if jacobians else 0, 6, 3))
    k1, k2, k3, k4 = np.empty(6), np.empty(6), np.empty(6), np.empty(6)
    x = np.empty(6)
    js = np.empty((4, 6, 6))
    sa = np.empty((4, 6, 6))
    sb = np.empty((4, 6, 3))
    ginv = np.array([1.0 / p[0], 1.0 / p[1], 1.0 / p[2]])
    for i in range(n):
        qi, ti = q[i], tau[i]
        _derivative(p, qi, ti, k1)
        if jacobians:
            _jacobian(p, qi, js[0])
        x[:] = qi + 0.5 * h * k1
        _derivative(p, x, ti, k2)
        if jacobians:
            _jacobian(p, x, js[1])
        x[:] = qi + 0.5 * h * k2
        _derivative(p, x, ti, k3)
        if jacobians:
            _jacobian(p, x, js[2])
        x[:] = qi + h * k3
        _derivative(p, x, ti, k4)
        if jacobians:
            _jacobian(p, x, js[3])
        q_next[i] = qi + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not jacobians:
            continue
        sa[0] = js[0]
        sb[0] = 0.0
        for m in range(3):
            sb[0, 3 + m, m] = ginv[m]
        for st, sc in ((1, 0.5 * h), (2, 0.5 * h), (3, h)):
            _propagate(js[st], sc, sa[st - 1], False, ginv, sa[st])
            _propagate(js[st], sc, sb[st - 1], True, ginv, sb[st])
        for r_ in range(6):
            for c_ in range(6):
                acc = sa[0, r_, c_] + 2 * sa[1, r_, c_] + 2 * sa[2, r_, c_] + sa[3, r_, c_]
                a[i, r_, c_] = (1.0 if r_ == c_ else 0.0) + h / 6.0 * acc
            for c_ in range(3):
                acc = sb[0, r_, c_] + 2 * sb[1, r_, c_] + 2 * sb[2, r_, c_] + sb[3, r_, c_]
                b[i, r_, c_] = h / 6.0 * acc
    return q_next, a, b
