"""The output-error model of the grey-box identification (Roboat II §IV-A, eq. 9a; the method is
described in ``identification``): ξ as a 6-vector, ν̇ of eq. (2) without current and its
Jacobians in ν and ξ, one RK4 step of ν with its exact step Jacobians, the trials of a log as
padded batches (``OutputErrorData``), their batched simulation from each trial's first measured ν
with the forward sensitivities S = ∂ν_sim/∂ξ (:func:`simulate_velocities`), and the cost, exact
gradient, Gauss-Newton Hessian and covariances of (9a) on one data set (``OutputErrorProblem``,
weighted by :func:`default_weight`). ``identification`` hands this to SNOPT and reports the fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usvdrake.systems.estimation.identification_data import XI_NAMES, Trial
from usvdrake.systems.vessel.vessel_dynamics import coriolis_times_velocity
from usvdrake.typed_yaml import ConfigError
from usvdrake.vessel import Hydrodynamics


def xi_vector(xi: Hydrodynamics | np.ndarray) -> np.ndarray:
    """ξ as the 6-vector [m11 m22 m33 Xu Yv Nr] of eq. (9)."""
    return xi.as_vector() if isinstance(xi, Hydrodynamics) else np.asarray(xi, dtype=float)


def xi_from_vector(x: np.ndarray) -> Hydrodynamics:
    return Hydrodynamics(**{k: float(v) for k, v in zip(XI_NAMES, x, strict=True)})


# --- the model: eq. (2) without current, and its derivatives ---------------------------------


def velocity_derivatives(xi: np.ndarray, nu: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """ν̇ = M⁻¹ (τ − C(ν) ν − D ν) of eq. (2) for a batch: ν, τ (M, 3) → (M, 3).

    ξ = [m11 m22 m33 Xu Yv Nr] as floats; C(ν)ν is the shared eq. (5) of ``vessel_dynamics``."""
    cor = coriolis_times_velocity(_Xi(xi), nu.T).T
    return (tau - cor - nu * xi[3:6]) / xi[0:3]


class _Xi:
    """ξ with attribute access for ``coriolis_times_velocity`` (a Hydrodynamics without the
    dataclass's construction cost, which would dominate the inner loop)."""

    __slots__ = ("m11", "m22")

    def __init__(self, xi: np.ndarray):
        self.m11, self.m22 = xi[0], xi[1]


def velocity_jacobians(
    xi: np.ndarray, nu: np.ndarray, nu_dot: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(∂ν̇/∂ν (M, 3, 3), ∂ν̇/∂ξ (M, 3, 6)) at a batch ν (M, 3) with ν̇ (M, 3) already computed.

        m11 u̇ = τu + m22 v r − Xu u
        m22 v̇ = τv − m11 u r − Yv v
        m33 ṙ = τr − (m22 − m11) u v − Nr r
    so e.g. ∂u̇/∂m11 = −u̇/m11, ∂u̇/∂m22 = v r/m11, ∂ṙ/∂m11 = u v/m33 (checked against
    AutoDiffXd in the tests)."""
    m11, m22, m33, xu, yv, nr = xi
    u, v, r = nu[:, 0], nu[:, 1], nu[:, 2]
    n = len(nu)
    a = np.empty((n, 3, 3))
    a[:, 0, 0], a[:, 0, 1], a[:, 0, 2] = -xu / m11, m22 * r / m11, m22 * v / m11
    a[:, 1, 0], a[:, 1, 1], a[:, 1, 2] = -m11 * r / m22, -yv / m22, -m11 * u / m22
    d = (m22 - m11) / m33
    a[:, 2, 0], a[:, 2, 1], a[:, 2, 2] = -d * v, -d * u, -nr / m33
    p = np.zeros((n, 3, 6))
    p[:, 0, 0], p[:, 0, 1], p[:, 0, 3] = -nu_dot[:, 0] / m11, v * r / m11, -u / m11
    p[:, 1, 0], p[:, 1, 1], p[:, 1, 4] = -u * r / m22, -nu_dot[:, 1] / m22, -v / m22
    uv = u * v / m33
    p[:, 2, 0], p[:, 2, 1], p[:, 2, 2], p[:, 2, 5] = uv, -uv, -nu_dot[:, 2] / m33, -r / m33
    return a, p


def rk4_velocity(xi: np.ndarray, nu: np.ndarray, tau: np.ndarray, h: np.ndarray) -> np.ndarray:
    """One classical RK4 step of ν (M, 3) under τ (M, 3) held over h (M,) [s]."""
    hc = h[:, None]
    k1 = velocity_derivatives(xi, nu, tau)
    k2 = velocity_derivatives(xi, nu + 0.5 * hc * k1, tau)
    k3 = velocity_derivatives(xi, nu + 0.5 * hc * k2, tau)
    k4 = velocity_derivatives(xi, nu + hc * k3, tau)
    return nu + hc / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


_FIRST, _SECOND = np.array([1, 0, 0]), np.array([2, 2, 1])


def _rk4_quadratic(x, tau_m, h, quad, decay):
    """:func:`rk4_velocity` for ν in the (3, N) layout, τ/m given, f = τ/m − decay ν + quad ∘ ·."""

    def f(y):
        return tau_m - decay * y + quad * (y.take(_FIRST, 0) * y.take(_SECOND, 0))

    k1 = f(x)
    k2 = f(x + 0.5 * h * k1)
    k3 = f(x + 0.5 * h * k2)
    k4 = f(x + h * k3)
    return x + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rk4_velocity_jacobians(
    xi: np.ndarray, nu: np.ndarray, tau: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(Φ = ∂ν⁺/∂ν (M, 3, 3), Γ = ∂ν⁺/∂ξ (M, 3, 6)) of :func:`rk4_velocity`, exactly, by the
    chain rule through the four stages (k_i = f(ν_i): dk_i = A_i dν_i + P_i dξ)."""
    hc, hs = h[:, None], h[:, None, None]
    eye = np.eye(3)
    k1 = velocity_derivatives(xi, nu, tau)
    a1, p1 = velocity_jacobians(xi, nu, k1)
    n2 = nu + 0.5 * hc * k1
    k2 = velocity_derivatives(xi, n2, tau)
    a2, p2 = velocity_jacobians(xi, n2, k2)
    n3 = nu + 0.5 * hc * k2
    k3 = velocity_derivatives(xi, n3, tau)
    a3, p3 = velocity_jacobians(xi, n3, k3)
    n4 = nu + hc * k3
    a4, p4 = velocity_jacobians(xi, n4, velocity_derivatives(xi, n4, tau))
    d2n = a2 @ (eye + 0.5 * hs * a1)
    d2x = a2 @ (0.5 * hs * p1) + p2
    d3n = a3 @ (eye + 0.5 * hs * d2n)
    d3x = a3 @ (0.5 * hs * d2x) + p3
    d4n = a4 @ (eye + hs * d3n)
    d4x = a4 @ (hs * d3x) + p4
    phi = eye + hs / 6.0 * (a1 + 2.0 * d2n + 2.0 * d3n + d4n)
    gamma = hs / 6.0 * (p1 + 2.0 * d2x + 2.0 * d3x + d4x)
    return phi, gamma


@dataclass(frozen=True)
class OutputErrorData:
    """The trials of a log as padded batches for :func:`simulate_velocities`."""

    tau: np.ndarray  # (N, T, 3) [N, N, N m] recorded τ = B f, held from sample k to k + 1
    nu: np.ndarray  # (N, T, 3) measured ν [m/s, m/s, rad/s]
    h: np.ndarray  # (N, T − 1) [s] sample intervals, 0 on padding
    mask: np.ndarray  # (N, T) 1 on the residuals of (9a): real samples after the first
    t: np.ndarray  # (N, T) [s] sample times (padding repeats the last)

    @classmethod
    def from_trials(cls, trials: list[Trial], b: np.ndarray) -> OutputErrorData:
        """Stack trials (each ≥ 2 samples) with τ = B f; B (3 × n) of Roboat II eq. (3)."""
        if not trials:
            raise ConfigError("identification", "trials", "at least one trial", "none")
        n_t = max(len(tr.t) for tr in trials)
        shape = (len(trials), n_t)
        tau, nu = np.zeros((*shape, 3)), np.zeros((*shape, 3))
        t, mask = np.zeros(shape), np.zeros(shape)
        for i, tr in enumerate(trials):
            n = len(tr.t)
            if tr.thrust.shape[1] != b.shape[1]:
                raise ConfigError(
                    "identification",
                    f"trials[{i}].thrust",
                    f"{b.shape[1]} thruster columns",
                    tr.thrust.shape[1],
                )
            tau[i, :n] = tr.thrust @ b.T
            nu[i, :n], nu[i, n:] = tr.nu, tr.nu[-1]
            t[i, :n], t[i, n:] = tr.t, tr.t[-1]
            mask[i, 1:n] = 1.0
        return cls(tau=tau, nu=nu, h=np.diff(t, axis=1), mask=mask, t=t)

    @property
    def n_residuals(self) -> int:
        """Number of scalar residuals in (9a): 3 per weighted sample."""
        return int(3 * self.mask.sum())


def simulate_velocities(
    xi: np.ndarray, data: OutputErrorData, sensitivities: bool = False, substeps: int = 1
) -> tuple[np.ndarray, np.ndarray | None]:
    """ν_sim (N, T, 3) from each trial's first measured ν, and S = ∂ν_sim/∂ξ (N, T, 3, 6).

    Three passes: (1) the RK4 simulation, sequential in time, batched over trials; (2) the
    step Jacobians Φ_k, Γ_k at every (trial, step) at once; (3) the forward-sensitivity
    recursion S_{k+1} = Φ_k S_k + Γ_k, S_0 = 0 (the first ν is measured, not simulated)."""
    xi = xi_vector(xi)
    n, n_t = data.mask.shape
    n_k = (n_t - 1) * substeps
    h = np.repeat(data.h / substeps, substeps, axis=1)  # (N, K) per RK4 step
    tau = np.repeat(data.tau[:, :-1], substeps, axis=1)  # (N, K, 3)
    # Pass 1 in the (3, N) layout with eq. (2) as ν̇ = τ/m − (d/m) ν + c ∘ [v r, u r, u v]:
    # the same model as velocity_derivatives in a third of the numpy calls (it is the loop).
    m = xi[:3]
    decay = (xi[3:] / m)[:, None]
    quad = np.array([xi[1] / xi[0], -xi[0] / xi[1], -(xi[1] - xi[0]) / xi[2]])[:, None]
    tau_m = (tau / m).transpose(1, 2, 0)  # (K, 3, N)
    h_t = h.T
    out = np.empty((n_k + 1, 3, n))
    x = out[0] = data.nu[:, 0].T
    for k in range(n_k):
        x = out[k + 1] = _rk4_quadratic(x, tau_m[k], h_t[k], quad, decay)
    states = out.transpose(2, 0, 1)  # (N, K + 1, 3)
    nu_sim = states[:, ::substeps]
    if not sensitivities:
        return nu_sim, None
    phi, gamma = rk4_velocity_jacobians(
        xi, states[:, :-1].reshape(-1, 3), tau.reshape(-1, 3), h.reshape(-1)
    )
    phi, gamma = phi.reshape(n, n_k, 3, 3), gamma.reshape(n, n_k, 3, 6)
    s_all = np.empty((n, n_k + 1, 3, 6))
    s = s_all[:, 0] = np.zeros((n, 3, 6))
    for k in range(n_k):
        s = s_all[:, k + 1] = phi[:, k] @ s + gamma[:, k]
    return nu_sim, s_all[:, ::substeps]


class OutputErrorProblem:
    """Eq. (9a) on one data set: cost, exact gradient and Gauss-Newton Hessian in ξ units."""

    def __init__(self, data: OutputErrorData, weight: np.ndarray, substeps: int = 1):
        weight = np.asarray(weight, dtype=float)
        weight = (
            0.5 * (weight + weight.T) if weight.shape == (3, 3) else weight
        )  # εᵀwε sees only this
        if weight.shape != (3, 3) or np.any(np.linalg.eigvalsh(0.5 * (weight + weight.T)) <= 0):
            raise ConfigError("identification", "weight", "a positive definite 3×3", weight.shape)
        self.data, self.weight, self.substeps = data, weight, substeps

    def residuals(self, xi) -> np.ndarray:
        """ε = ν_measured − ν_simulated (N, T, 3), zero where the mask is."""
        nu_sim, _ = simulate_velocities(xi, self.data, False, self.substeps)
        return (self.data.nu - nu_sim) * self.data.mask[..., None]

    def cost(self, xi) -> float:
        """Σ ε(t)ᵀ w ε(t) of (9a) [dimensionless with the default weight]."""
        e = self.residuals(xi)
        return float(np.einsum("ntj,jk,ntk->", e, self.weight, e))

    def evaluate(self, xi) -> tuple[float, np.ndarray, np.ndarray]:
        """(cost, ∂cost/∂ξ (6,), Σ Sᵀ w S (6, 6)) — the last is half the Gauss-Newton Hessian."""
        nu_sim, s = simulate_velocities(xi, self.data, True, self.substeps)
        e = (self.data.nu - nu_sim) * self.data.mask[..., None]
        we = e @ self.weight.T
        cost = float(np.einsum("ntj,ntj->", e, we))
        grad = -2.0 * np.einsum("ntj,ntjp->p", we, s, optimize=True)
        # Σ Sᵀ w S as YᵀY with Y = Lᵀ S, w = L Lᵀ (one matrix product instead of an einsum).
        y = np.linalg.cholesky(self.weight).T @ (s * self.data.mask[..., None, None])
        y = y.reshape(-1, 6)
        gn = y.T @ y
        return cost, grad, gn

    def covariance(self, xi, window_s: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
        """(Gauss-Newton, robust) covariance of ξ̂ at a minimiser ξ (6 × 6, ξ units²).

        Gauss-Newton: s² H⁻¹ with H = Σ Sᵀ w S and s² = cost / (n_residuals − 6), right when
        the residuals are white with covariance ∝ w⁻¹. Robust: the sandwich H⁻¹ G H⁻¹ with G the
        Newey-West (Bartlett-weighted, lags up to ``window_s``) long-run covariance of the score
        terms g_k = S_kᵀ w ε_k. Noise on the recorded thrust passes through the dynamics and
        makes the residuals coloured over the vessel's time constants (m11/Xu ≈ 4.5 s for Roboat
        II), where the Gauss-Newton σ comes out several times too small. On the 5 × 150 s Roboat
        II set (three seeds) the sandwich σ matched the spread of the estimates; on trials only
        a few windows long it is itself too noisy to trust."""
        nu_sim, s = simulate_velocities(xi, self.data, True, self.substeps)
        e = (self.data.nu - nu_sim) * self.data.mask[..., None]
        sm = s * self.data.mask[..., None, None]
        y = (np.linalg.cholesky(self.weight).T @ sm).reshape(-1, 6)
        h_inv = np.linalg.inv(y.T @ y)
        s2 = float(np.einsum("ntj,jk,ntk->", e, self.weight, e)) / max(self.data.n_residuals - 6, 1)
        g = np.einsum("ntj,jk,ntkp->ntp", e, self.weight, sm)  # (N, T, 6)
        dt = float(np.median(self.data.h[self.data.h > 0]))
        lags = min(int(round(window_s / dt)), g.shape[1] - 1)
        long_run = np.einsum("ntp,ntq->pq", g, g)
        for lag in range(1, lags + 1):
            c = np.einsum("ntp,ntq->pq", g[:, lag:], g[:, :-lag])
            long_run += (1.0 - lag / (lags + 1.0)) * (c + c.T)
        return s2 * h_inv, h_inv @ long_run @ h_inv


def default_weight(velocity_std) -> np.ndarray:
    """w = diag(σ_u⁻², σ_v⁻², σ_r⁻²) [s²/m², s²/m², s²/rad²]: the inverse noise covariance."""
    return np.diag(1.0 / np.asarray(velocity_std, dtype=float) ** 2)
