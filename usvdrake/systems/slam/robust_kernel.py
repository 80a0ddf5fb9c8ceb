"""Barron's general robust kernel, its IRLS weight, a small IRLS solver and a gtsam adapter.

The sliding-window pose graph of Pham et al. (2022, "Online Robust Sliding-Windowed LiDAR SLAM in
Natural Environments", §III eqs. 11-14) robustifies every constraint residual
``r = sqrt(eᵀ Ω e)`` (eq. 12) with Barron's kernel (eq. 14; Barron, "A General and Adaptive
Robust Loss Function", CVPR 2019, eq. 1)::

    ρ(x, α, c) = |α−2|/α · (((x/c)² / |α−2| + 1)^(α/2) − 1)

and solves the robust problem by iteratively reweighted least squares (eqs. 11, 13) with the
IRLS weight ``w(x) = ρ'(x) / x`` (Barron eq. 2 differentiated; the paper's eq. 13 is garbled
in our copy, this is the standard IRLS weight it stands for)::

    w(x, α, c) = 1/c² · ((x/c)² / |α−2| + 1)^(α/2 − 1)

The shape α selects the kernel (Barron §1): α = 2 L2 ``½(x/c)²``; α = 1 pseudo-Huber /
Charbonnier ``sqrt((x/c)² + 1) − 1``; α = 0 Cauchy / Lorentzian ``log(½(x/c)² + 1)``;
α = −2 Geman-McClure ``2(x/c)² / ((x/c)² + 4)``; α = −∞ Welsch ``1 − exp(−½(x/c)²)``.
α = 2, 0 and −∞ are removable singularities of the formula and are evaluated by their limits;
near them the formula is evaluated with ``log1p`` / ``expm1`` so that ρ is continuous in α.
x and c share units (e.g. metres, or whitened units for a graph residual); ρ is dimensionless
and w has units 1/c².
"""

from collections.abc import Callable
from dataclasses import dataclass

import gtsam
import numpy as np

# |α − 2| below this is treated as α = 2 exactly: the closed form's error there is
# O(ε log(1/ε)) relative, far below double precision's useful digits.
_EPS = float(np.finfo(float).eps)


def _check(alpha: float, c: float) -> tuple[float, float]:
    alpha, c = float(alpha), float(c)
    if np.isnan(alpha) or alpha == np.inf:
        raise ValueError(f"alpha must be in [-inf, inf), got {alpha}")
    if not c > 0.0:
        raise ValueError(f"scale c must be positive, got {c}")
    return alpha, c


def barron_loss(x, alpha: float, c: float = 1.0) -> np.ndarray:
    """Barron's general robust loss ρ(x, α, c) (Barron 2019 eq. 1; Pham et al. eq. 14).

    x: residuals [units of c], any shape; alpha: shape α ∈ [−∞, 2] (α > 2 also evaluates the
    formula); c: scale [units of x] > 0, the width of the quadratic bowl near x = 0.
    Returns ρ, dimensionless, same shape as x; ρ(x) ≈ ½(x/c)² for |x| ≪ c for every α.
    """
    alpha, c = _check(alpha, c)
    z = np.square(np.asarray(x, dtype=float) / c)
    if abs(alpha - 2.0) < _EPS:
        return 0.5 * z
    if alpha == 0.0 or abs(alpha) < 1e-300:  # subnormal α would lose digits in α/2 · log1p
        return np.log1p(0.5 * z)
    if alpha == -np.inf:
        return -np.expm1(-0.5 * z)
    b = abs(alpha - 2.0)
    # (z/b + 1)^(α/2) − 1 = expm1(α/2 · log1p(z/b)): exact as α → 0 and for small z.
    return b / alpha * np.expm1(0.5 * alpha * np.log1p(z / b))


def barron_weight(x, alpha: float, c: float = 1.0) -> np.ndarray:
    """IRLS weight w(x) = ρ'(x, α, c) / x of Barron's loss (Pham et al. eq. 13) [1/c²].

    ``w = 1/c² · ((x/c)²/|α−2| + 1)^(α/2 − 1)``: 1/c² at x = 0 for every α; α = 2 gives the
    constant 1/c² (plain least squares), α = −∞ the Welsch weight ``exp(−½(x/c)²)/c²``.
    Same shapes and units as :func:`barron_loss`.
    """
    alpha, c = _check(alpha, c)
    z = np.square(np.asarray(x, dtype=float) / c)
    if abs(alpha - 2.0) < _EPS:
        return np.full_like(z, 1.0 / c**2)
    if alpha == -np.inf:
        return np.exp(-0.5 * z) / c**2
    b = abs(alpha - 2.0)
    return np.exp((0.5 * alpha - 1.0) * np.log1p(z / b)) / c**2


@dataclass
class IrlsResult:
    x: np.ndarray  # the estimate
    weights: np.ndarray  # [1/c²] final IRLS weight of each residual
    iterations: int  # iterations run


def irls(
    residual_fn: Callable[[np.ndarray], np.ndarray],
    jacobian_fn: Callable[[np.ndarray], np.ndarray],
    x0,
    alpha: float,
    c: float = 1.0,
    iterations: int = 50,
    tol: float = 1e-12,
) -> IrlsResult:
    """Minimise Σᵢ ρ(rᵢ(x), α, c) by iteratively reweighted Gauss-Newton (Pham et al. eq. 11).

    Each iteration freezes the weights wᵢ = w(rᵢ(x), α, c) (eq. 13, :func:`barron_weight`) and
    takes the Gauss-Newton step of Σᵢ wᵢ rᵢ(x)² : ``(Jᵀ W J) δ = −Jᵀ W r``. For a linear model
    one step is the weighted least-squares solution. Stops when ‖δ‖ ≤ tol (1 + ‖x‖).

    residual_fn: x ↦ r (m,); jacobian_fn: x ↦ ∂r/∂x (m × n); x0: start (n,) — for α < 1 the
    loss is non-convex, so start from a sensible guess (e.g. the least-squares solution).
    """
    x = np.array(x0, dtype=float)
    done = 0
    while done < iterations:
        done += 1
        r, J = np.asarray(residual_fn(x), float), np.asarray(jacobian_fn(x), float)
        w = barron_weight(r, alpha, c)
        # Scale rows by sqrt(w) and solve by lstsq rather than forming JᵀWJ (better conditioned).
        sw = np.sqrt(w)
        step = np.linalg.lstsq(sw[:, None] * J, -sw * r, rcond=None)[0]
        x = x + step
        if np.linalg.norm(step) <= tol * (1.0 + np.linalg.norm(x)):
            break
    return IrlsResult(x=x, weights=barron_weight(residual_fn(x), alpha, c), iterations=done)


def gtsam_barron(alpha: float, c: float = 1.0):
    """Barron's kernel as a ``gtsam.noiseModel.mEstimator.Custom`` for ``Robust.Create``.

    Scaled by c² to gtsam's convention (its Null estimator: loss ½e², weight 1), i.e.
    ``loss(e) = c² ρ(e, α, c)`` and ``weight(e) = c² w(e, α, c)``, where e is the whitened
    residual ``sqrt(eᵀΩe)`` of eq. 12 (Block reweighting: one weight per factor). With this
    scaling gtsam's own kernels are special cases: Cauchy(k) = (α = 0, c = k/√2),
    GemanMcClure(k) = (α = −2, c = k/2), Welsch(k) = (α = −∞, c = k/√2).

    Use: ``gtsam.noiseModel.Robust.Create(gtsam_barron(0.0, 1.0), base_noise)``.
    """
    alpha, c = _check(alpha, c)
    c2 = c * c

    def weight(e: float) -> float:
        return float(c2 * barron_weight(e, alpha, c))

    def loss(e: float) -> float:
        return float(c2 * barron_loss(e, alpha, c))

    m = gtsam.noiseModel.mEstimator
    return m.Custom(weight, loss, m.Base.ReweightScheme.Block, f"Barron(alpha={alpha}, c={c})")
