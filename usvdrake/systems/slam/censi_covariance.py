"""Closed-form covariance of a converged PLICP match (Pham et al. §II-B, eqs. 4-10).

Censi, "An accurate closed-form estimate of ICP's covariance", ICRA 2007: if x̂ minimises
J(x, z) for measurements z, then to first order

    cov(x̂) ≈ (∂²J/∂x²)⁻¹ (∂²J/∂x∂z) cov(z) (∂²J/∂x∂z)ᵀ (∂²J/∂x²)⁻¹.

Pham et al. eq. 4 as extracted ends in (∂²J/∂z²)⁻¹; that is garbled (the dimensions do not even
match): both outer factors are the inverse Hessian in x, as in Censi 2007 eq. 5.

Here x = [t_x, t_y, θ] and J is the point-to-line cost at the match's final correspondences
(Pham et al. eq. 5), J = Σ_i r_i², r_i = n_iᵀ (R(θ) p_i + t − a_i), with every point written in
polar form p = ρ u (u the known beam direction): p_i = ρ_i u_i from the current scan, a_i = ρ_a u_a
and b_i = ρ_b u_b its two reference points, n_i ⊥ (b_i − a_i). The measurements z are the
*ranges*, cov(z) = σ² I (σ the range noise).

Differences from Pham et al. eqs. 6-10, and why:

* z holds each scan's ranges once (all current ranges, then all reference ranges) and the
  contributions of every correspondence that uses a range are summed into its column. Pham et al.
  eq. 6 stacks (ρ_i, ρ_a, ρ_b) per correspondence, which counts a reference range used by
  several current points as independent measurements and underestimates the covariance.
* ∂²J/∂x∂z is analytic (Pham et al. eq. 9 takes ∂C_i/∂ρ by a forward difference with ε = 0.001).
  With d = b − a, τ = d/|d|: ∂n/∂d = −τ nᵀ/|d|, so ∂n/∂ρ_a = τ (n·u_a)/|d| and
  ∂n/∂ρ_b = −τ (n·u_b)/|d|. Then, with v = R p + t − a (Pham et al.'s v₂), R' = dR/dθ:

      ∂r/∂t = n,  ∂r/∂θ = nᵀ R' p,
      ∂r/∂ρ_i = nᵀ R u_i,  ∂r/∂ρ_a = (∂n/∂ρ_a)ᵀ v − nᵀ u_a,  ∂r/∂ρ_b = (∂n/∂ρ_b)ᵀ v,
      ∂²r/∂t∂ρ = ∂n/∂ρ,  ∂²r/∂θ∂ρ_i = nᵀ R' u_i,  ∂²r/∂θ∂ρ_{a,b} = (∂n/∂ρ_{a,b})ᵀ R' p,
      ∂²J/∂x∂z = Σ 2 (∂r/∂x)(∂r/∂z)ᵀ + 2 r ∂²r/∂x∂z,
      ∂²J/∂x² = Σ 2 (∂r/∂x)(∂r/∂x)ᵀ + 2 r ∂²r/∂x²,  ∂²r/∂θ² = −nᵀ R p   (Pham et al. eq. 7).

The correspondences are held fixed, as in Censi 2007. Measured (tests/test_plicp.py): against
Monte Carlo with fixed correspondences, σ = 1 mm, the estimate agrees to ~15 % (Frobenius).
Against full re-matching trimmed PLICP (correspondences re-found and trimmed per trial) it is
~5× larger in standard deviation, at every σ from 1 mm to 1 cm: the trimming discards the
pairs whose noisy normals hurt most, which the fixed-correspondence model cannot know. Read it
as a conservative bound for :func:`usvdrake.systems.slam.plicp.plicp`.
"""

import numpy as np

from usvdrake.systems.slam.plicp import PlicpResult, rot


def plicp_hessians(
    reference: np.ndarray,
    current: np.ndarray,
    t: np.ndarray,
    theta: float,
    correspondences: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """∂²J/∂x² (3 × 3) and ∂²J/∂x∂z (3 × (M + N)) of the point-to-line cost at (t [m], θ [rad]).

    reference (N × 2), current (M × 2): scan points [m] in their own sensor frames (sensor at
    the origin); correspondences (K × 3): current index i, reference indices a, b. Column k of
    ∂²J/∂x∂z is range k of the current scan for k < M, range k − M of the reference scan after.
    """
    reference = np.asarray(reference, float)
    current = np.asarray(current, float)
    i, ja, jb = (correspondences[:, k] for k in range(3))
    m_cur = len(current)
    p, a, b = current[i], reference[ja], reference[jb]
    u_p = p / np.linalg.norm(p, axis=1, keepdims=True)
    u_a = a / np.linalg.norm(a, axis=1, keepdims=True)
    u_b = b / np.linalg.norm(b, axis=1, keepdims=True)
    d = b - a
    length = np.linalg.norm(d, axis=1, keepdims=True)
    tau = d / length
    n = np.column_stack([-tau[:, 1], tau[:, 0]])

    r_mat = rot(theta)
    dr_mat = rot(theta + np.pi / 2)  # R'(θ)
    rp = p @ r_mat.T
    drp = p @ dr_mat.T
    v = rp + t - a
    r = np.einsum("ij,ij->i", n, v)

    def dot(x, y):
        return np.einsum("ij,ij->i", x, y)

    # First derivatives of r in x (K × 3).
    rx = np.column_stack([n, dot(n, drp)])
    # Derivatives of the normal in ρ_a, ρ_b (K × 2 each).
    dn_a = tau * (dot(n, u_a) / length[:, 0])[:, None]
    dn_b = -tau * (dot(n, u_b) / length[:, 0])[:, None]
    # ∂r/∂z for z = ρ_i, ρ_a, ρ_b (K each).
    rz_i = dot(n, u_p @ r_mat.T)
    rz_a = dot(dn_a, v) - dot(n, u_a)
    rz_b = dot(dn_b, v)
    # ∂²r/∂x∂z (K × 3 each).
    rxz_i = np.column_stack([np.zeros((len(i), 2)), dot(n, u_p @ dr_mat.T)])
    rxz_a = np.column_stack([dn_a, dot(dn_a, drp)])
    rxz_b = np.column_stack([dn_b, dot(dn_b, drp)])

    hess = 2.0 * rx.T @ rx
    hess[2, 2] += 2.0 * np.sum(r * -dot(n, rp))

    jxz = np.zeros((3, m_cur + len(reference)))
    for col, rz, rxz in ((i, rz_i, rxz_i), (m_cur + ja, rz_a, rxz_a), (m_cur + jb, rz_b, rxz_b)):
        contrib = 2.0 * (rx * rz[:, None] + r[:, None] * rxz)  # (K × 3)
        np.add.at(jxz.T, col, contrib)
    return hess, jxz


def plicp_covariance(
    reference: np.ndarray, current: np.ndarray, result: PlicpResult, sigma: float
) -> np.ndarray:
    """Covariance (3 × 3, [m², m·rad, rad²]) of ``result`` = (t_x, t_y, θ) from
    :func:`usvdrake.systems.slam.plicp.plicp` when every range has independent noise of
    standard deviation ``sigma`` [m] (Censi 2007 eq. 5 / Pham et al. eq. 4, see the module
    docstring)."""
    hess, jxz = plicp_hessians(reference, current, result.t, result.theta, result.correspondences)
    h_inv = np.linalg.inv(hess)
    cov = sigma**2 * h_inv @ (jxz @ jxz.T) @ h_inv
    return 0.5 * (cov + cov.T)
