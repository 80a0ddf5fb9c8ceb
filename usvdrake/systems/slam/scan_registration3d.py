"""Scan-to-map registration of LOAM features: the lidar odometry factor of Roboat II §V-A.

A keyframe's features F_{t+1} = {F^e, F^p} (sensor frame, :mod:`lidar_features`) are
registered against the voxel maps M_t = {M^e, M^p} of the previous n keyframes (Roboat II §V-A,
n = 25) by minimising point-to-line and point-to-plane distances (LOAM §VI, eqs. (2)-(3),
in the mapping form of LOAM §VI-B / LIO-SAM ``scan2MapOptimization``):

* edge point p: its 5 nearest map edge points must lie on a line — the largest eigenvalue of
  their covariance at least ``line_ratio`` times the second (LOAM §VI-B). With centroid m and
  direction u, the residual is the 2-vector (aᵀ(q − m), bᵀ(q − m)) where a, b ⊥ u are the
  other two eigenvectors and q = T p: its norm is LOAM eq. (2)'s point-to-line distance.
* planar point p: its 5 nearest map planar points must fit a plane (every point within
  ``plane_threshold`` of it); with unit normal n (smallest eigenvector) the residual is
  nᵀ(q − m), LOAM eq. (3)'s point-to-plane distance. Our addition: the 5 points must also
  spread in two directions (sqrt(λ2/λ3) ≥ ``plane_spread``, eigenvalues ascending). In a map
  built from one or few sparse sweeps the 5 nearest points often lie along one ring; with
  range noise their "normal" is arbitrary about the ring and pulls the scan toward the ring
  pattern (on the real HDL-32E pair of the tests it moved roll by 0.3° with the map voxel size;
  with the guard the estimate is stable to ±0.03°). For raw, noise-free maps set it to 0.

The map is a :class:`~usvdrake.systems.slam.voxel_map.VoxelMap` (an incremental voxel hash
with k-NN search). The neighbourhood fits (centroid, scatter, its 3 × 3 eigen-problem in closed
form after Smith 1961, the line / plane tests) and the LM steps run in numba kernels.

Both are rows ``r_k = n_kᵀ(R p_k + t − m_k)``. The pose is perturbed on the right,
``T ← T · (Exp(ω), v)``, i.e. R ← R Exp(ω), t ← t + R v, ξ = (ω, v) ∈ R⁶ in the sensor
(body) frame — gtsam's Pose3 tangent ordering, so the information matrix can go straight into
a BetweenFactor. The Jacobian of a row is ``∂r/∂ξ = [(p × Rᵀn)ᵀ, (Rᵀn)ᵀ]``.

The solver is Levenberg-Marquardt with iteratively re-weighted Huber weights (w = 1 for d ≤ δ,
δ/d beyond, d the point's distance) over correspondences searched again at every outer
iteration, as LOAM does (a point that moved less than its neighbours' certified tolerance keeps
them: :meth:`VoxelMap.knn_update`). Degeneracy follows Zhang 2016: eigen-decompose H = JᵀWJ;
directions with eigenvalue below ``degeneracy_threshold`` are left out of every update (their
"solution remapping"), and the smallest eigenvalue is reported.

Coarse to fine: ``max_correspondence_distances`` lists the association radius of each stage
(largest first); each stage iterates to convergence before the next, tighter one starts.

The rigid-motion helpers here (:func:`so3_exp`, :func:`transform_points`, :func:`deskew`) are
shared with the lidar-inertial front end and the 2D graph SLAM's scan de-skewing.
"""

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from usvdrake.systems.slam.lidar_features import LidarFeatures
from usvdrake.systems.slam.voxel_map import VoxelMap, moved_rows, voxel_filter


@dataclass
class RegistrationParams:
    """Parameters of :func:`register_scan` (defaults after LOAM / LIO-SAM mapping)."""

    k_neighbours: int = 5  # [-] map points per correspondence (LOAM: 5)
    # [m] radius per stage (a list, not a tuple: Drake's typed YAML reads lists)
    max_correspondence_distances: list[float] = field(default_factory=lambda: [1.0])
    line_ratio: float = 3.0  # [-] λ1 ≥ this · λ2 for a line (LOAM: 3)
    plane_threshold: float = 0.2  # [m] max distance of the 5 points from their plane
    plane_spread: float = 0.3  # [-] min sqrt(λ2/λ3) of the plane's 5 points: not on one line
    huber_delta: float = 0.1  # [m] distances beyond this are down-weighted
    max_iterations: int = 30  # [-] outer iterations (re-association) per stage
    inner_steps: int = 3  # [-] LM steps on fixed correspondences per outer iteration
    rotation_tolerance: float = (
        2e-4  # [rad] converged when an outer iteration turns less (LOAM 8.7e-4)
    )
    translation_tolerance: float = 2e-4  # [m] ... and moves less (LOAM: 5e-4)
    degeneracy_threshold: float = 10.0  # [m⁻²·m²] eigenvalue of JᵀWJ below which a direction
    #                                     is degenerate (≈ fewer than this many unit constraints)
    source_edge_voxel: float = 0.0  # [m] voxel filter of the source edges (0: none)
    source_planar_voxel: float = 0.0  # [m] voxel filter of the source planar points
    initial_damping: float = 1e-4  # [-] LM λ, relative to diag(H)
    cycle_length: int = 3  # [-] also converged on returning to a pose this many iterations back
    # [m] a point's k-NN search also looks this far beyond the radius, to know how far the point
    # may move before its neighbours can change (it is searched again only then; the answer is
    # that of a full search). Larger: fewer re-searches, each a little dearer
    reuse_margin: float = 0.1


@dataclass
class RegistrationResult:
    """Result of :func:`register_scan`."""

    T: np.ndarray  # (4 × 4) T_map_source: q = R p + t maps source points into the map frame
    iterations: int  # [-] outer iterations (associations) over all stages
    converged: bool  # [-] the last stage met the tolerances before max_iterations
    information: np.ndarray  # (6 × 6) JᵀWJ / σ² in ξ = (ω [rad], v [m]), body frame
    covariance: np.ndarray  # (6 × 6) σ² (JᵀWJ)⁻¹ (pseudo-inverse on degenerate directions)
    min_eigenvalue: float  # [-] smallest eigenvalue of JᵀWJ (Zhang 2016 degeneracy measure)
    degenerate: bool  # [-] some eigenvalue below params.degeneracy_threshold
    n_edge: int  # [-] edge correspondences in the last iteration
    n_planar: int  # [-] planar correspondences in the last iteration
    rms: float  # [m] RMS point distance of those correspondences
    sigma: float  # [m] robust residual scale σ used for the information


def voxel_downsample(points: np.ndarray, voxel: float) -> np.ndarray:
    """Centroid of the points in each occupied cubic voxel of side ``voxel`` [m] (PCL
    VoxelGrid). points: (N × 3) [m]; voxel ≤ 0 returns the points unchanged."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    if voxel <= 0 or len(pts) == 0:
        return pts
    key = np.floor(pts / voxel).astype(np.int64)
    key -= key.min(axis=0)
    span = key.max(axis=0) + 1
    # One int64 per voxel (sorting 1-D keys is ~10x faster than np.unique(axis=0)).
    flat = (key[:, 0] * span[1] + key[:, 1]) * span[2] + key[:, 2]
    order = np.argsort(flat)  # introsort: 2x faster than stable, and deterministic too
    flat = flat[order]
    start = np.flatnonzero(np.r_[True, flat[1:] != flat[:-1]])
    counts = np.diff(np.r_[start, len(flat)])
    sums = np.add.reduceat(pts[order], start, axis=0)
    return sums / counts[:, None]


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """q = R p + t for each row p of points (N × 3) [m]."""
    return np.asarray(points) @ T[:3, :3].T + T[:3, 3]


def build_feature_map(
    edge_clouds: Sequence[np.ndarray],
    planar_clouds: Sequence[np.ndarray],
    poses: Sequence[np.ndarray] | None = None,
    edge_voxel: float = 0.2,
    planar_voxel: float = 0.4,
) -> VoxelMap:
    """Merge keyframe features into the voxel maps M^e = ∪ 'F^e, M^p = ∪ 'F^p (Roboat II §V-A).

    edge_clouds, planar_clouds: per keyframe, (N × 3) [m] in its sensor frame; poses: per
    keyframe T_map_keyframe (4 × 4), identity if None; edge_voxel, planar_voxel: voxel sides
    [m] of the merged maps (LIO-SAM 0.2 / 0.4; ≤ 0: every point). A map that changes a few
    keyframes at a time is better edited in place (:class:`VoxelMap`)."""
    if poses is None:
        poses = [np.eye(4)] * len(edge_clouds)
    fmap = VoxelMap(edge_voxel, planar_voxel)
    for i, (T, e, p) in enumerate(zip(poses, edge_clouds, planar_clouds, strict=True)):
        fmap.add(i, transform_points(T, e), transform_points(T, p))
    return fmap


@njit(cache=True)
def so3_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix Exp(ω) (Rodrigues' formula), ω (3,) [rad] (numba: also in kernels)."""
    th = np.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(th) / th * K + (1 - np.cos(th)) / th**2 * K @ K


def deskew(points: np.ndarray, age: np.ndarray, omega: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Points measured ``age`` [s] before the sweep's end, each in the sensor frame of its own
    firing time, expressed in the sensor frame at the end; constant body twist (ω [rad/s],
    v [m/s], sensor frame). With T(t) = T_end Exp((t − t_end) ξ) the point moves by
    T_end⁻¹ T(t_i) = Exp(−age_i ξ): p_end = Exp(−age_i ω) p_i − age_i v (first order in the
    translation; over a 0.1 s sweep the neglected term is ≤ ½ |ω| |v| age² ≈ 0.1 mm)."""
    return _deskew_kernel(
        np.ascontiguousarray(points, dtype=float).reshape(-1, 3),
        np.ascontiguousarray(age, dtype=float).ravel(),
        np.asarray(omega, dtype=float).ravel(),
        np.asarray(v, dtype=float).ravel(),
    )


@njit(cache=True)
def _deskew_kernel(pts, age, omega, v):
    """:func:`deskew` per point: Rodrigues' rotation by −age·ω, then −age·v."""
    out = np.empty_like(pts)
    wn = np.sqrt(omega[0] ** 2 + omega[1] ** 2 + omega[2] ** 2)
    # the axis is −ω/|ω| for every point with age > 0 (+ω/|ω| for age < 0): only the angle varies
    kx, ky, kz = (-omega[0] / wn, -omega[1] / wn, -omega[2] / wn) if wn > 0 else (0.0, 0.0, 0.0)
    for i in range(len(pts)):
        px, py, pz = pts[i, 0], pts[i, 1], pts[i, 2]
        a = age[i]
        th = abs(a) * wn
        if th < 1e-12:
            out[i, 0], out[i, 1], out[i, 2] = px - a * v[0], py - a * v[1], pz - a * v[2]
            continue
        sgn = 1.0 if a > 0 else -1.0
        ax, ay, az = sgn * kx, sgn * ky, sgn * kz
        c, s = np.cos(th), np.sin(th)
        dot = (ax * px + ay * py + az * pz) * (1.0 - c)
        out[i, 0] = px * c + (ay * pz - az * py) * s + ax * dot - a * v[0]
        out[i, 1] = py * c + (az * px - ax * pz) * s + ay * dot - a * v[1]
        out[i, 2] = pz * c + (ax * py - ay * px) * s + az * dot - a * v[2]
    return out


def retract(T: np.ndarray, xi: np.ndarray) -> np.ndarray:
    """T · (Exp(ω), v): R ← R Exp(ω), t ← t + R v, with ξ = (ω [rad], v [m])."""
    out = T.copy()
    out[:3, :3] = T[:3, :3] @ so3_exp(xi[:3])
    out[:3, 3] = T[:3, 3] + T[:3, :3] @ xi[3:]
    return out


@dataclass
class _Rows:
    """Correspondences: residuals r = n_jᵀ(R p + t − m), j = 1, 2 (planes: n2 = 0)."""

    p: np.ndarray  # (K × 3) source points [m], sensor frame
    n1: np.ndarray  # (K × 3) unit normals, map frame
    n2: np.ndarray  # (K × 3) second normals of edges (⊥ n1 and the line), zero for planes
    m: np.ndarray  # (K × 3) anchor points [m], map frame
    n_edge: int
    n_planar: int

    @property
    def n_groups(self) -> int:
        return self.n_edge + self.n_planar

    @property
    def n_rows(self) -> int:  # residual rows: 2 per edge, 1 per plane
        return 2 * self.n_edge + self.n_planar


@njit(cache=True, inline="always")
def _sym3_eigvals(a, b, c, d, e, f):
    """Eigenvalues (ascending) of the symmetric 3 × 3 matrix [[a d f] [d b e] [f e c]] by the
    trigonometric solution of its characteristic cubic (Smith, "Eigenvalues of a symmetric
    3 × 3 matrix", CACM 4(4), 1961)."""
    q = (a + b + c) / 3.0
    p = np.sqrt(((a - q) ** 2 + (b - q) ** 2 + (c - q) ** 2 + 2.0 * (d * d + e * e + f * f)) / 6.0)
    if p <= 0.0:
        return q, q, q
    A, B, C, D, E, F = (a - q) / p, (b - q) / p, (c - q) / p, d / p, e / p, f / p
    det = A * (B * C - E * E) - D * (D * C - E * F) + F * (D * E - B * F)
    phi = np.arccos(min(1.0, max(-1.0, det / 2.0))) / 3.0
    hi = q + 2.0 * p * np.cos(phi)
    lo = q + 2.0 * p * np.cos(phi + 2.0 * np.pi / 3.0)
    return lo, 3.0 * q - hi - lo, hi


@njit(cache=True, inline="always")
def _sym3_eigvec(C, lam, out):
    """Unit eigenvector of symmetric C (3 × 3) for the simple eigenvalue lam into out (3,): the
    largest cross product of two rows of C − λI (a column of its adjugate). Where λ is not
    simple the direction is arbitrary within its eigenspace, as for any solver."""
    best = -1.0
    for i, j in ((0, 1), (0, 2), (1, 2)):
        ri0, ri1, ri2 = C[i, 0], C[i, 1], C[i, 2]
        rj0, rj1, rj2 = C[j, 0], C[j, 1], C[j, 2]
        if i == 0:
            ri0 -= lam
        elif i == 1:
            ri1 -= lam
        if j == 1:
            rj1 -= lam
        else:
            rj2 -= lam
        x = ri1 * rj2 - ri2 * rj1
        y = ri2 * rj0 - ri0 * rj2
        z = ri0 * rj1 - ri1 * rj0
        n2 = x * x + y * y + z * z
        if n2 > best:
            best = n2
            out[0], out[1], out[2] = x, y, z
    if best > 0.0:
        n = np.sqrt(best)
        out[0], out[1], out[2] = out[0] / n, out[1] / n, out[2] / n
    else:
        out[0], out[1], out[2] = 0.0, 0.0, 1.0


@njit(cache=True)
def _fit_kernel(pts, idx, ok, rows, line, ratio, spread2, threshold, keep, cen, n1, n2):
    """Per query row m in ``rows`` with all k neighbours ``pts[idx[m]]`` found (``ok[m]``):
    the centroid and scatter C = Σ (p − c)(p − c)ᵀ / k with its eigen-decomposition, then

    * line (edges, LOAM §VI-B): λ3 > ratio · λ2 → two unit normals ⊥ the line direction;
    * plane: λ2 ≥ spread2 · λ3 (not on one ring) and every neighbour within ``threshold`` of
      the plane through c with normal the λ1 eigenvector → that normal.

    Writes rows m of keep (M,), centroid (M × 3), n1 (M × 3), n2 (M × 3; lines only)."""
    k = idx.shape[1]
    C = np.zeros((3, 3))
    v = np.zeros(3)
    for m in rows:
        keep[m] = False
        if not ok[m]:
            continue
        cx = cy = cz = 0.0
        for j in range(k):
            q = idx[m, j]
            cx += pts[q, 0]
            cy += pts[q, 1]
            cz += pts[q, 2]
        cx, cy, cz = cx / k, cy / k, cz / k
        C[:, :] = 0.0
        for j in range(k):
            q = idx[m, j]
            dx, dy, dz = pts[q, 0] - cx, pts[q, 1] - cy, pts[q, 2] - cz
            C[0, 0] += dx * dx
            C[1, 1] += dy * dy
            C[2, 2] += dz * dz
            C[0, 1] += dx * dy
            C[1, 2] += dy * dz
            C[0, 2] += dx * dz
        C /= k
        C[1, 0], C[2, 1], C[2, 0] = C[0, 1], C[1, 2], C[0, 2]
        l1, l2, l3 = _sym3_eigvals(C[0, 0], C[1, 1], C[2, 2], C[0, 1], C[1, 2], C[0, 2])
        if line:
            if not l3 > ratio * l2:
                continue
            _sym3_eigvec(C, l3, v)
            # complete the direction u to an orthonormal basis (u, a, b)
            ax = 0
            if abs(v[1]) < abs(v[ax]):
                ax = 1
            if abs(v[2]) < abs(v[ax]):
                ax = 2
            e = np.zeros(3)
            e[ax] = 1.0
            a0, a1, a2 = (
                v[1] * e[2] - v[2] * e[1],
                v[2] * e[0] - v[0] * e[2],
                v[0] * e[1] - v[1] * e[0],
            )
            na = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
            a0, a1, a2 = a0 / na, a1 / na, a2 / na
            n1[m, 0], n1[m, 1], n1[m, 2] = a0, a1, a2
            n2[m, 0] = v[1] * a2 - v[2] * a1
            n2[m, 1] = v[2] * a0 - v[0] * a2
            n2[m, 2] = v[0] * a1 - v[1] * a0
        else:
            if not l2 >= spread2 * l3:
                continue
            _sym3_eigvec(C, l1, v)
            flat = True
            for j in range(k):
                q = idx[m, j]
                dist = (pts[q, 0] - cx) * v[0] + (pts[q, 1] - cy) * v[1] + (pts[q, 2] - cz) * v[2]
                if abs(dist) > threshold:
                    flat = False
                    break
            if not flat:
                continue
            n1[m, 0], n1[m, 1], n1[m, 2] = v[0], v[1], v[2]
        keep[m] = True
        cen[m, 0], cen[m, 1], cen[m, 2] = cx, cy, cz


class _Neighbourhoods:
    """One feature type's k-NN answers and fits over a stage's iterations: a point that moved
    less than its answer's tolerance (:meth:`VoxelMap.knn_update`) keeps them, exactly."""

    def __init__(self, m: int, k: int):
        self.anchor = np.zeros((m, 3))
        self.tau = np.full(m, -1.0)  # < 0: never searched
        self.idx = np.zeros((m, k), dtype=np.int64)
        self.ok = np.zeros(m, dtype=np.bool_)
        self.keep = np.zeros(m, dtype=np.bool_)
        self.cen = np.zeros((m, 3))
        self.n1 = np.zeros((m, 3))
        self.n2 = np.zeros((m, 3))


def fit_neighbourhoods(
    fmap: VoxelMap,
    q: np.ndarray,
    k: int,
    radius: float,
    line: bool,
    params: "RegistrationParams",
    state: _Neighbourhoods | None = None,
):
    """The query points q (M × 3) whose k nearest map points (edges if ``line``, else planes)
    all lie within ``radius`` and fit a line (``line``) or a plane (module doc): (rows (K,),
    centroids (K × 3), normals (K × 3), second normals (K × 3, lines only)). state: kept over
    the iterations of one stage on an unchanged map, to re-search only the points that moved
    (``params.reuse_margin``)."""
    if len(q) == 0:
        z = np.zeros((0, 3))
        return np.zeros(0, int), z, z, z
    q = np.ascontiguousarray(q, dtype=float)
    st = state if state is not None else _Neighbourhoods(len(q), k)
    rows = moved_rows(q, st.anchor, st.tau)
    fmap.knn_update(line, q, rows, k, radius, params.reuse_margin, st.idx, st.ok, st.tau)
    _fit_kernel(
        fmap.table(line), st.idx, st.ok, rows, line,
        float(params.line_ratio), float(params.plane_spread) ** 2, float(params.plane_threshold),
        st.keep, st.cen, st.n1, st.n2,
    )  # fmt: skip
    out = np.flatnonzero(st.keep)
    return out, st.cen[out], st.n1[out], st.n2[out]


def _associate(
    fmap: VoxelMap, edges: np.ndarray, planes: np.ndarray, T: np.ndarray, params, radius, states
) -> _Rows:
    k = params.k_neighbours
    # Edges: line-like neighbourhoods; residual rows along two directions ⊥ the line.
    i_e, c_e, a_e, b_e = fit_neighbourhoods(
        fmap, transform_points(T, edges), k, radius, True, params, states[0]
    )
    # Planes: spread in two directions, every neighbour within plane_threshold of the plane.
    i_p, c_p, n_p, _ = fit_neighbourhoods(
        fmap, transform_points(T, planes), k, radius, False, params, states[1]
    )
    return _Rows(
        p=np.concatenate([edges[i_e], planes[i_p]]),
        n1=np.concatenate([a_e, n_p]),
        n2=np.concatenate([b_e, np.zeros_like(n_p)]),
        m=np.concatenate([c_e, c_p]),
        n_edge=len(i_e),
        n_planar=len(i_p),
    )


@njit(cache=True)
def _gn_kernel(p, n1, n2, m, T, delta, with_h):
    """Huber cost Σ ρ(d) of the correspondences at pose T and, if ``with_h``, the IRLS normal
    equations H = Σ w JᵀJ, g = Σ w Jᵀr (w = ρ'(d)/d per correspondence, shared by its rows),
    J = [(p × Rᵀn)ᵀ, (Rᵀn)ᵀ] per row (module doc). Returns (H (6 × 6), g (6,), cost)."""
    H = np.zeros((6, 6))
    g = np.zeros(6)
    J = np.zeros(6)
    cost = 0.0
    R = T[:3, :3]
    for i in range(len(p)):
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        qx = R[0, 0] * px + R[0, 1] * py + R[0, 2] * pz + T[0, 3] - m[i, 0]
        qy = R[1, 0] * px + R[1, 1] * py + R[1, 2] * pz + T[1, 3] - m[i, 1]
        qz = R[2, 0] * px + R[2, 1] * py + R[2, 2] * pz + T[2, 3] - m[i, 2]
        r1 = n1[i, 0] * qx + n1[i, 1] * qy + n1[i, 2] * qz
        r2 = n2[i, 0] * qx + n2[i, 1] * qy + n2[i, 2] * qz
        d = np.sqrt(r1 * r1 + r2 * r2)
        if d <= delta:
            cost += 0.5 * d * d
            w = 1.0
        else:
            cost += delta * (d - 0.5 * delta)
            w = delta / d
        if not with_h:
            continue
        for row in range(2):
            if row == 0:
                nx, ny, nz, r = n1[i, 0], n1[i, 1], n1[i, 2], r1
            else:
                nx, ny, nz, r = n2[i, 0], n2[i, 1], n2[i, 2], r2
                if nx == 0.0 and ny == 0.0 and nz == 0.0:
                    continue  # a plane: one row
            bx = R[0, 0] * nx + R[1, 0] * ny + R[2, 0] * nz  # Rᵀn
            by = R[0, 1] * nx + R[1, 1] * ny + R[2, 1] * nz
            bz = R[0, 2] * nx + R[1, 2] * ny + R[2, 2] * nz
            J[0], J[1], J[2] = py * bz - pz * by, pz * bx - px * bz, px * by - py * bx
            J[3], J[4], J[5] = bx, by, bz
            for a in range(6):
                wa = w * J[a]
                g[a] += wa * r
                for b in range(a, 6):
                    H[a, b] += wa * J[b]
    for a in range(6):
        for b in range(a):
            H[a, b] = H[b, a]
    return H, g, cost


def _row_statistics(rows: _Rows, T: np.ndarray, delta: float):
    """(Σ w r² over the rows, distances d per correspondence) at T."""
    q = transform_points(T, rows.p) - rows.m
    r1 = np.einsum("ki,ki->k", rows.n1, q)
    r2 = np.einsum("ki,ki->k", rows.n2, q)
    d = np.sqrt(r1 * r1 + r2 * r2)
    w = np.where(d <= delta, 1.0, delta / np.maximum(d, 1e-300))  # Huber IRLS weight
    return float(np.sum(w * d * d)), d


def _degenerate_projector(H: np.ndarray, threshold: float):
    """Projector onto the eigenvectors of H with eigenvalue ≥ threshold (Zhang 2016 §V)."""
    evals, evecs = np.linalg.eigh(H)
    good = evecs[:, evals >= threshold]
    return good @ good.T, float(evals[0]), bool(np.any(evals < threshold))


def _settled(T: np.ndarray, previous: list[np.ndarray], prm: RegistrationParams) -> bool:
    """Converged: T is within the tolerances of one of the ``previous`` outer iterations' poses
    — the last one (the iteration moved less than the tolerance, LOAM's test), or an earlier
    one: re-association can cycle between two or three correspondence sets a millimetre apart
    (seen on canal_survey: 10 % of matches ran all 30 iterations alternating ~1 mm / 0.007°),
    and iterating further only revisits them."""
    for P in previous:
        R_step = P[:3, :3].T @ T[:3, :3]  # P⁻¹ T of rigid motions, without a general inverse
        w_step = np.arccos(np.clip((np.trace(R_step) - 1) / 2, -1.0, 1.0))
        if w_step < prm.rotation_tolerance and np.linalg.norm(T[:3, 3] - P[:3, 3]) < (
            prm.translation_tolerance
        ):
            return True
    return False


def _lm_steps(rows: _Rows, T: np.ndarray, prm: RegistrationParams) -> np.ndarray:
    """``inner_steps`` Levenberg-Marquardt steps on fixed correspondences (module doc)."""
    return _lm_kernel(
        rows.p, rows.n1, rows.n2, rows.m, np.ascontiguousarray(T, dtype=float),
        float(prm.huber_delta), int(prm.inner_steps), float(prm.initial_damping),
        float(prm.degeneracy_threshold),
    )  # fmt: skip


@njit(cache=True)
def _lm_kernel(p, n1, n2, m, T, delta, inner_steps, damping, threshold):
    """:func:`_lm_steps` in one call: λ-damped steps ξ = −P (H + λ diag H)⁻¹ g, P the projector
    off H's degenerate directions (Zhang 2016), accepted when the Huber cost does not grow
    (then λ /= 3, else λ *= 4), T ← T · (Exp(ω), v)."""
    lam = damping
    H, g, cost = _gn_kernel(p, n1, n2, m, T, delta, True)
    evals, evecs = np.linalg.eigh(H)
    P = np.zeros((6, 6))
    for j in range(6):
        if evals[j] >= threshold:
            P += np.outer(evecs[:, j], evecs[:, j])
    for _ in range(inner_steps):
        accepted = False
        while not accepted and lam < 1e8:
            A = H + lam * np.diag(np.diag(H))
            try:
                xi = -P @ np.linalg.solve(A, g)
            except Exception:  # numba catches no narrower class (a singular A)
                xi = -P @ np.linalg.lstsq(A, g)[0]
            R = np.ascontiguousarray(T[:3, :3])
            T_new = T.copy()
            T_new[:3, :3] = R @ so3_exp(np.ascontiguousarray(xi[:3]))
            T_new[:3, 3] = T[:3, 3] + R @ np.ascontiguousarray(xi[3:])
            if _gn_kernel(p, n1, n2, m, T_new, delta, False)[2] <= cost:
                T, accepted = T_new, True
                lam = max(lam / 3.0, 1e-12)
            else:
                lam *= 4.0
        if not accepted:
            break
        H, g, cost = _gn_kernel(p, n1, n2, m, T, delta, True)
    return T


def register_scan(
    source: LidarFeatures,
    feature_map: VoxelMap,
    T_init: np.ndarray | None = None,
    params: RegistrationParams | None = None,
) -> RegistrationResult:
    """Register one scan's features to the feature map (LOAM §VI-B; Roboat II §V-A).

    source: features of the new keyframe in its sensor frame; feature_map: M_t;
    T_init: initial T_map_source (4 × 4), identity if None (Roboat II: the IMU's prediction).
    Returns the refined T_map_source, iteration count, information / covariance in
    ξ = (ω, v) (body frame, right perturbation) and the degeneracy indicator."""
    prm = params or RegistrationParams()
    T = np.eye(4) if T_init is None else np.array(T_init, dtype=float)
    edges = voxel_filter(source.edge_points, prm.source_edge_voxel)
    planes = voxel_filter(source.planar_points, prm.source_planar_voxel)
    iterations, converged = 0, False
    rows = None
    for radius in prm.max_correspondence_distances:
        converged = False
        history: list[np.ndarray] = []  # poses at the start of each outer iteration
        k = prm.k_neighbours
        states = (_Neighbourhoods(len(edges), k), _Neighbourhoods(len(planes), k))
        for _ in range(prm.max_iterations):
            iterations += 1
            rows = _associate(feature_map, edges, planes, T, prm, radius, states)
            if rows.n_groups < 6:
                break
            history.append(T)
            T = _lm_steps(rows, T, prm)
            if _settled(T, history[-prm.cycle_length :], prm):
                converged = True
                break
    if rows is None or rows.n_groups < 6:
        nan6 = np.full((6, 6), np.nan)
        return RegistrationResult(T, iterations, False, np.zeros((6, 6)), nan6, 0.0, True, 0, 0,
                                  np.nan, np.nan)  # fmt: skip
    H, _, _ = _gn_kernel(rows.p, rows.n1, rows.n2, rows.m, T, float(prm.huber_delta), True)
    _, min_eig, degenerate = _degenerate_projector(H, prm.degeneracy_threshold)
    dof = max(rows.n_rows - 6, 1)
    wr2, d = _row_statistics(rows, T, prm.huber_delta)
    sigma2 = wr2 / dof
    cov = sigma2 * np.linalg.pinv(H)
    return RegistrationResult(
        T=T,
        iterations=iterations,
        converged=converged,
        information=H / sigma2,
        covariance=cov,
        min_eigenvalue=min_eig,
        degenerate=degenerate,
        n_edge=rows.n_edge,
        n_planar=rows.n_planar,
        rms=float(np.sqrt(np.mean(d * d))),
        sigma=float(np.sqrt(sigma2)),
    )
