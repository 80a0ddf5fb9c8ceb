"""Point-to-line ICP (PLICP) for 2D laser scans: the numerical core of the scan matcher.

Censi, "An ICP variant using a point-to-line metric", ICRA 2008, as used by Pham et al. §II-A.
Each iteration pairs every current point p_i (transformed by the estimate) with the closest
reference point a_i and the closer of its two neighbours *in scan order* b_i, and minimises
the point-to-line error (Pham et al. eq. 1)

    J(t, θ) = Σ_i w_i (n_iᵀ (R(θ) p_i + t − a_i))²,   n_i ⊥ (b_i − a_i), |n_i| = 1,

exactly, in closed form (:func:`solve_point_to_line`, Pham et al. eqs. 2-3). Because each step is an
exact minimiser over fixed correspondences, the iteration stops as soon as the correspondences
repeat (Censi's finite convergence) or the step falls below a tolerance.

Why scan-order neighbours rather than the two Euclidean nearest neighbours: consecutive
returns of one scan sample one surface between them (unless they straddle a depth jump, which
``max_segment`` rejects), whereas the two nearest neighbours of a point near a corner or a thin
object can lie on different surfaces and give a meaningless line. It also costs one k = 1
tree query instead of k = 2.

Large initial rotation errors are PLICP's known weakness (Censi 2008 §VI reports failures
from ±45° starts). :func:`coarse_rotation` is a cheap safeguard: it scores a grid of rotations
about the initial guess by the truncated mean nearest-neighbour distance of a subsample and
starts PLICP from the best one (``plicp(..., rotation_search=...)``).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.slam import plicp_kernel as kernel

GRID_CELL = 0.25  # nearest-neighbour grid cell [max_distance]: exact for any size, only speed


@dataclass
class PlicpResult:
    """Result of :func:`plicp`: the pose of the current scan's frame in the reference frame."""

    t: np.ndarray  # (2,) [m] translation: p_ref = R(theta) p_cur + t
    theta: float  # [rad]
    iterations: int  # closed-form solves performed (coarse and fine)
    converged: bool  # stopped by the tolerance / repeated correspondences, not max_iterations
    n_valid: int  # correspondences used in the last solve (after trimming)
    residual: float  # [m] RMS point-to-line error of those correspondences
    correspondences: np.ndarray  # (n_valid, 3) int: current index i, reference a_i, b_i

    @property
    def pose(self) -> np.ndarray:
        """(x, y, θ) of the current scan's frame in the reference frame."""
        return np.array([self.t[0], self.t[1], self.theta])


def rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def scan_to_points(scan: LaserScan) -> np.ndarray:
    """Valid returns of ``scan`` as (M × 2) points [m] in the sensor frame, in beam order
    (the order :func:`plicp` relies on for its reference scan)."""
    return scan.points()


def line_normals(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Unit normals (N × 2) of the lines through a_i and b_i (the sign is irrelevant)."""
    d = b - a
    n = np.column_stack([-d[:, 1], d[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _quadratic_form(p, q, n, w):
    """M (4 × 4) and g (4,) of J(x) = xᵀ M x + gᵀ x + const, x = [t_x, t_y, cos θ, sin θ].

    With M_i = [[1, 0, p_x, −p_y], [0, 1, p_y, p_x]] (so that R(θ) p + t = M_i x) and
    C_i = w_i n_i n_iᵀ: M = Σ M_iᵀ C_i M_i, g = −2 Σ M_iᵀ C_i q_i (Censi 2008 §IV)."""
    # n_iᵀ M_i x = [n_x, n_y, n·p, n×p] · x, so M = Σ w k kᵀ with k that row.
    k = np.column_stack(
        [
            n[:, 0],
            n[:, 1],
            n[:, 0] * p[:, 0] + n[:, 1] * p[:, 1],
            n[:, 1] * p[:, 0] - n[:, 0] * p[:, 1],
        ]
    )
    c = np.einsum("ij,ij->i", n, q)
    kw = k * w[:, None]
    return kw.T @ k, -2.0 * (kw.T @ c)


def solve_point_to_line(
    p: np.ndarray, q: np.ndarray, n: np.ndarray, w: np.ndarray | None = None
) -> tuple[np.ndarray, float]:
    """Exact minimiser (t [m], θ [rad]) of Σ w_i (n_iᵀ (R(θ) p_i + t − q_i))² (Pham et al. eq. 1).

    Censi 2008 §IV: with x = [t, cos θ, sin θ] the cost is xᵀ M x + gᵀ x + const subject to
    xᵀ W x = 1, W = diag(0, 0, 1, 1). The Lagrange condition (2M + 2λW) x = −g and the
    constraint give Pham et al. eq. 2, gᵀ (2M + 2λW)⁻ᵀ W (2M + 2λW)⁻¹ g = 1. Writing
    2M = [[A, B], [Bᵀ, D]] (2 × 2 blocks), S = D − Bᵀ A⁻¹ B, S^A = |S| S⁻¹ its adjugate and
    h = g_r − Bᵀ A⁻¹ g_t, the rotation part is x_r = −(S + 2λI)⁻¹ h = −(S^A + 2λI) h / |S + 2λI|,
    so |x_r|² = 1 is the quartic (Pham et al. eq. 3)

        16 λ⁴ + 16 tr S λ³ + (8|S| + 4 tr²S − 4 hᵀh) λ² + (4|S| tr S − 4 hᵀ S^A h) λ
        + |S|² − hᵀ S^A S^A h = 0.

    Pham et al.'s coefficient list is garbled in extraction: it writes hᵀ X h expanded through g
    with non-transposed off-diagonal blocks (−A⁻¹B where −Bᵀ A⁻ᵀ belongs), "1" for the identity, and
    an undefined "T" in e (it is the identity: hᵀ S^A S^A h). We implement the form above, in Pham
    et al.'s convention that A, B, D are blocks of 2M. Every real root gives a stationary point; we
    polish each root's θ by Newton steps on the reduced cost ½ uᵀ S u + hᵀ u, u = (cos θ, sin θ),
    take the one of least cost (the global minimum is among them) and set t = −A⁻¹ (g_t + B x_r).

    p, q, n: (N × 2) current points, reference points on the lines, line normals; w: (N,)
    weights (default 1). Needs at least two non-parallel normals (A invertible).
    """
    p, q, n = (np.asarray(v, float) for v in (p, q, n))
    w = np.ones(len(p)) if w is None else np.asarray(w, float)
    m, g = _quadratic_form(p, q, n, w)
    m2 = 2.0 * m
    a, b, d = m2[:2, :2], m2[:2, 2:], m2[2:, 2:]
    g_t, g_r = g[:2], g[2:]
    a_inv = np.linalg.inv(a)
    s = d - b.T @ a_inv @ b
    h = g_r - b.T @ a_inv @ g_t
    det_s, tr_s = np.linalg.det(s), np.trace(s)
    s_adj = np.array([[s[1, 1], -s[0, 1]], [-s[1, 0], s[0, 0]]])
    sah = s_adj @ h
    coeffs = [
        16.0,
        16.0 * tr_s,
        8.0 * det_s + 4.0 * tr_s**2 - 4.0 * h @ h,
        4.0 * det_s * tr_s - 4.0 * h @ sah,
        det_s**2 - sah @ sah,
    ]
    roots = np.roots(coeffs)
    # Candidates: the real roots. When the fit is exact the minimising λ is a near-double root
    # whose computed value can pick up a small imaginary part and an error of ~√eps, so nearly
    # real roots count too, and each candidate is polished by Newton steps on the reduced cost
    # f(φ) = ½ uᵀ S u + hᵀ u (t eliminated, u = (cos φ, sin φ)); the least f wins.
    scale = max(1.0, float(np.max(np.abs(roots))))
    lam = roots.real[np.abs(roots.imag) <= 1e-6 * scale]
    if lam.size == 0:  # cannot happen in exact arithmetic (the minimum has a real λ)
        lam = roots.real
    # x_r(λ) = −(S^A + 2λI) h / |S + 2λI| for every candidate at once; its direction is θ.
    xr = -(sah[None, :] + 2.0 * lam[:, None] * h[None, :])
    with np.errstate(divide="ignore", invalid="ignore"):  # non-finite candidates dropped below
        xr /= (lam**2 * 4.0 + 2.0 * tr_s * lam + det_s)[:, None]
    ok = np.all(np.isfinite(xr), axis=1) & np.any(xr != 0.0, axis=1)
    phi = np.arctan2(xr[ok, 1], xr[ok, 0]) if ok.any() else np.zeros(1)
    u = np.stack([np.cos(phi), np.sin(phi)])
    cost = 0.5 * np.einsum("ik,ij,jk->k", u, s, u) + h @ u
    best = float(phi[np.argmin(cost)])
    s00, s01, s11, h0, h1 = s[0, 0], 0.5 * (s[0, 1] + s[1, 0]), s[1, 1], h[0], h[1]
    for _ in range(8):
        c, sn = np.cos(best), np.sin(best)
        # f'(φ) and f''(φ) of f = ½ uᵀ S u + hᵀ u, u = (c, sn), u' = (−sn, c).
        f1 = (s11 - s00) * c * sn + s01 * (c * c - sn * sn) - h0 * sn + h1 * c
        f2 = (s11 - s00) * (c * c - sn * sn) - 4.0 * s01 * c * sn - h0 * c - h1 * sn
        if not f2 > 0.0:
            break
        best -= f1 / f2
        if abs(f1) <= 1e-15 * f2:
            break
    xr = np.array([np.cos(best), np.sin(best)])
    return -a_inv @ (g_t + b @ xr), float(np.arctan2(xr[1], xr[0]))


def find_correspondences(
    tree: cKDTree,
    reference: np.ndarray,
    moved: np.ndarray,
    max_distance: float,
    max_segment: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each transformed current point: the closest reference point a (index j1, by the
    tree) and the closer of its scan-order neighbours j1 ± 1 (j2). Returns (i, j1, j2) of the
    pairs with |p − a| ≤ max_distance [m] and |a − b| ≤ max_segment [m]."""
    dist, j1 = tree.query(moved, k=1, distance_upper_bound=max_distance)
    ok = np.isfinite(dist)
    i = np.nonzero(ok)[0]
    j1 = j1[ok]
    n_ref = len(reference)
    lo, hi = np.maximum(j1 - 1, 0), np.minimum(j1 + 1, n_ref - 1)
    mi = moved[i]
    e_lo, e_hi = reference[lo] - mi, reference[hi] - mi
    d_lo = np.einsum("ij,ij->i", e_lo, e_lo)
    d_hi = np.einsum("ij,ij->i", e_hi, e_hi)
    # At the ends of the scan one neighbour is j1 itself: never pick it.
    d_lo[lo == j1] = np.inf
    d_hi[hi == j1] = np.inf
    j2 = np.where(d_lo <= d_hi, lo, hi)
    e = reference[j2] - reference[j1]
    seg2 = np.einsum("ij,ij->i", e, e)
    ok = (j2 != j1) & (seg2 <= max_segment**2) & (seg2 > 0.0)
    return i[ok], j1[ok], j2[ok]


def coarse_rotation(
    tree: cKDTree,
    current: np.ndarray,
    t: np.ndarray,
    theta: float,
    half_width: float = np.deg2rad(60.0),
    step: float = np.deg2rad(2.0),
    samples: int = 120,
    cap: float = 0.5,
) -> float:
    """Best rotation [rad] on the grid θ + [−half_width, half_width] (step [rad]) about the
    initial guess, keeping t [m]: the one with the least mean of min(nearest-neighbour
    distance, cap [m]) over ``samples`` evenly spaced current points. One batched tree query."""
    sub = current[np.linspace(0, len(current) - 1, min(samples, len(current))).astype(int)]
    grid = theta + np.arange(-half_width, half_width + 0.5 * step, step)
    c, s = np.cos(grid), np.sin(grid)
    x = c[:, None] * sub[:, 0] - s[:, None] * sub[:, 1] + t[0]
    y = s[:, None] * sub[:, 0] + c[:, None] * sub[:, 1] + t[1]
    dist, _ = tree.query(np.column_stack([x.ravel(), y.ravel()]), k=1, distance_upper_bound=cap)
    score = np.minimum(dist, cap).reshape(len(grid), -1).mean(axis=1)
    return float(grid[np.argmin(score)])


def plicp(
    reference: np.ndarray,
    current: np.ndarray,
    initial: tuple[float, float, float] = (0.0, 0.0, 0.0),
    max_iterations: int = 50,
    max_distance: float = 1.0,
    max_segment: float = 1.0,
    trim: float = 0.9,
    tolerance_t: float = 1e-6,
    tolerance_theta: float = 1e-7,
    rotation_search: bool = False,
    coarse_stride: int = 4,
    coarse_tolerance: float = 1e-3,
    tree: cKDTree | None = None,
) -> PlicpResult:
    """Match ``current`` (M × 2 points [m], its sensor frame) against ``reference`` (N × 2
    points [m], ordered by beam angle) from ``initial`` = (t_x [m], t_y [m], θ [rad]).

    Each iteration transforms the current points by the estimate, finds correspondences
    (:func:`find_correspondences`, at most ``max_distance`` [m] away, segments at most
    ``max_segment`` [m] long), keeps the ``trim`` fraction with the least point-to-line error
    (trimmed ICP) and solves Pham et al. eq. 1 exactly with :func:`solve_point_to_line`. It stops
    when the correspondences repeat (the solve would return the same pose) or the step is below
    ``tolerance_t`` [m] and ``tolerance_theta`` [rad]. ``rotation_search`` first replaces the
    initial θ by :func:`coarse_rotation`. ``tree``: a prebuilt ``cKDTree(reference)``,
    used only by the rotation search.

    Coarse to fine (for speed; the answer is the full-resolution one): the first iterations use
    every ``coarse_stride``-th current point until a step is below ``coarse_tolerance`` [m, rad];
    the rest use all of them. The correspondence search dominates the cost, so this roughly
    halves it on 1081-beam scans.

    The loop runs compiled (:mod:`usvdrake.systems.slam.plicp_kernel`, with its own exact
    nearest-neighbour grid of the reference); :func:`plicp_reference` is the same algorithm in
    numpy, kept as the tests' reference, and runs the match instead when a solve is
    ill-conditioned (a featureless corridor), where only numpy's own rounding gives today's answer.
    """
    reference = _points(reference)
    current = _points(current)
    t = np.array(initial[:2], float)
    theta = float(initial[2])
    if rotation_search:
        tree = cKDTree(reference) if tree is None else tree
        theta = coarse_rotation(tree, current, t, theta)
    params = np.array(
        [max_distance, max_segment, trim, tolerance_t, tolerance_theta, coarse_tolerance], float
    )
    pose, iterations, converged, i, j1, j2, fallback = kernel.run(
        reference,
        current,
        GRID_CELL * max_distance,
        np.array([t[0], t[1], theta]),
        params,
        max_iterations,
        coarse_stride,
    )
    if fallback:  # an ill-conditioned solve: numpy's rounding decides it, as it always did
        return plicp_reference(
            reference,
            current,
            initial,
            max_iterations,
            max_distance,
            max_segment,
            trim,
            tolerance_t,
            tolerance_theta,
            rotation_search,
            coarse_stride,
            coarse_tolerance,
            tree,
        )
    t, theta, sel, residual = pose[:2], float(pose[2]), np.zeros((0, 3), int), np.inf
    if len(i):
        # the last solve once more in numpy: bit for bit the reference's pose (the kernel's is
        # ~1e-13 off, which a pose graph's tolerance-based stopping grows to ~1e-6 in a mission)
        n = line_normals(reference[j1], reference[j2])
        t, theta = solve_point_to_line(current[i], reference[j1], n)
        sel, residual = _selection(reference, current, t, theta, i, j1, j2, n)
    return PlicpResult(
        t=t,
        theta=theta,
        iterations=int(iterations),
        converged=bool(converged),
        n_valid=len(sel),
        residual=residual,
        correspondences=sel,
    )


def _points(points) -> np.ndarray:
    """(N × 2) float64 C-contiguous, as the kernel takes them."""
    return np.ascontiguousarray(np.asarray(points, float).reshape(-1, 2))


def plicp_reference(
    reference: np.ndarray,
    current: np.ndarray,
    initial: tuple[float, float, float] = (0.0, 0.0, 0.0),
    max_iterations: int = 50,
    max_distance: float = 1.0,
    max_segment: float = 1.0,
    trim: float = 0.9,
    tolerance_t: float = 1e-6,
    tolerance_theta: float = 1e-7,
    rotation_search: bool = False,
    coarse_stride: int = 4,
    coarse_tolerance: float = 1e-3,
    tree: cKDTree | None = None,
) -> PlicpResult:
    """:func:`plicp` in numpy (cKDTree, argpartition, np.roots): the reference its compiled
    kernel is tested against."""
    reference = np.asarray(reference, float)
    current = np.asarray(current, float)
    tree = cKDTree(reference) if tree is None else tree
    t = np.array(initial[:2], float)
    theta = float(initial[2])
    if rotation_search:
        theta = coarse_rotation(tree, current, t, theta)
    prev_key = None
    converged = False
    iterations = 0
    sel = np.zeros((0, 3), int)
    sel_n = None
    residual = np.inf
    active = np.arange(0, len(current), max(1, coarse_stride))
    fine = len(active) == len(current)
    for _ in range(max_iterations):
        moved = current[active] @ rot(theta).T + t
        i, j1, j2, n = _trimmed_pairs(tree, reference, moved, max_distance, max_segment, trim)
        if len(i) < 3:
            break
        i = active[i]
        key = np.concatenate([i, j1, j2])
        if prev_key is not None and key.shape == prev_key.shape and np.array_equal(key, prev_key):
            if fine:
                converged = True
                break
            active, fine, prev_key = np.arange(len(current)), True, None
            continue
        prev_key = key
        try:
            t_new, theta_new = solve_point_to_line(current[i], reference[j1], n)
        except np.linalg.LinAlgError:
            break
        iterations += 1
        step_t = np.linalg.norm(t_new - t)
        step_theta = abs(np.mod(theta_new - theta + np.pi, 2 * np.pi) - np.pi)
        t, theta = t_new, theta_new
        sel_n = (i, j1, j2, n)
        if not fine:
            if step_t < coarse_tolerance and step_theta < coarse_tolerance:
                active, fine, prev_key = np.arange(len(current)), True, None
        elif step_t < tolerance_t and step_theta < tolerance_theta:
            converged = True
            break
    if sel_n is not None:
        sel, residual = _selection(reference, current, t, theta, *sel_n)
    return PlicpResult(
        t=t,
        theta=theta,
        iterations=iterations,
        converged=converged,
        n_valid=len(sel),
        residual=residual,
        correspondences=sel,
    )


def _trimmed_pairs(tree, reference, moved, max_distance, max_segment, trim):
    """PLICP's correspondences of the ``moved`` points (:func:`find_correspondences`), the
    ``trim`` fraction with the least point-to-line error kept (in point order): (i, j1, j2,
    line normals)."""
    i, j1, j2 = find_correspondences(tree, reference, moved, max_distance, max_segment)
    n = line_normals(reference[j1], reference[j2])
    err = np.abs(np.einsum("ij,ij->i", n, moved[i] - reference[j1]))
    keep = max(3, int(np.ceil(trim * len(i))))
    if keep < len(i):
        idx = np.argpartition(err, keep - 1)[:keep]
        idx.sort()
        i, j1, j2, n = i[idx], j1[idx], j2[idx], n[idx]
    return i, j1, j2, n


def _selection(reference, current, t, theta, i, j1, j2, n) -> tuple[np.ndarray, float]:
    """(correspondences (m × 3: i, j1, j2), RMS point-to-line error [m]) of the pairs at the
    pose (t, θ)."""
    moved_i = current[i] @ rot(theta).T + t
    residual = float(np.sqrt(np.mean(np.einsum("ij,ij->i", n, moved_i - reference[j1]) ** 2)))
    return np.column_stack([i, j1, j2]), residual


def plicp_at(
    reference: np.ndarray,
    current: np.ndarray,
    pose,
    max_distance: float = 1.0,
    max_segment: float = 1.0,
    trim: float = 0.9,
    tree: cKDTree | None = None,
) -> PlicpResult:
    """The :class:`PlicpResult` of ``current`` held at ``pose`` = (t_x [m], t_y [m], θ [rad])
    against ``reference``: the trimmed correspondences PLICP would pair there and their RMS
    point-to-line error, no solve (``iterations`` 0, ``converged``). For a pose found by other
    means (a likelihood-field refinement) that must pass PLICP's checks and feed Censi's
    covariance like a PLICP match. ``tree`` is accepted for the callers' convenience and
    unused (the kernel indexes the reference itself)."""
    reference = _points(reference)
    current = _points(current)
    t, theta = np.array(pose[:2], float), float(pose[2])
    i, j1, j2 = kernel.held(
        reference,
        current,
        GRID_CELL * max_distance,
        np.array([t[0], t[1], theta]),
        max_distance,
        max_segment,
        trim,
    )
    sel, residual = np.zeros((0, 3), int), np.inf
    if len(i) >= 3:  # the residual in numpy, bit for bit the reference's (as in plicp)
        n = line_normals(reference[j1], reference[j2])
        sel, residual = _selection(reference, current, t, theta, i, j1, j2, n)
    return PlicpResult(
        t=t,
        theta=theta,
        iterations=0,
        converged=True,
        n_valid=len(sel),
        residual=residual,
        correspondences=sel,
    )


def plicp_at_reference(
    reference: np.ndarray,
    current: np.ndarray,
    pose,
    max_distance: float = 1.0,
    max_segment: float = 1.0,
    trim: float = 0.9,
    tree: cKDTree | None = None,
) -> PlicpResult:
    """:func:`plicp_at` in numpy: the reference its compiled kernel is tested against."""
    reference = np.asarray(reference, float)
    current = np.asarray(current, float)
    tree = cKDTree(reference) if tree is None else tree
    t, theta = np.array(pose[:2], float), float(pose[2])
    moved = current @ rot(theta).T + t
    i, j1, j2, n = _trimmed_pairs(tree, reference, moved, max_distance, max_segment, trim)
    sel, residual = np.zeros((0, 3), int), np.inf
    if len(i) >= 3:
        sel, residual = _selection(reference, current, t, theta, i, j1, j2, n)
    return PlicpResult(
        t=t,
        theta=theta,
        iterations=0,
        converged=True,
        n_valid=len(sel),
        residual=residual,
        correspondences=sel,
    )
