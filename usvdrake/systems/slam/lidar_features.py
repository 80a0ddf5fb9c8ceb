"""LOAM-style edge and planar features of a multi-ring lidar sweep, on its range image.

Roboat II §V-A (Roboat II) extracts the lidar frame F_t = {F_t^e, F_t^p} as LeGO-LOAM / LIO-SAM do
(Roboat II ref. [25]): project the sweep onto a range image (ring × azimuth column), compute a
roughness value per pixel from its neighbours in the same ring, take the roughest pixels as
edge features and the smoothest as planar features, a few per sector of each ring so that
features are spread around the sensor (Zhang & Singh, "LOAM: Lidar Odometry and Mapping in
Real-time", RSS 2014, §V-A).

Roughness (:func:`roughness`). LOAM eq. (1) is c = |Σ_{j∈S}(X_i − X_j)| / (|S|·|X_i|) over
the |S| = 2N points around i in its scan line. On a range image the points of a ring share
the sensor origin, and LeGO-LOAM / LIO-SAM replace the vectors by ranges. We implement the
range form of LOAM eq. (1), squared (LIO-SAM's ``diffRange²``) and normalised by the range so
that it is dimensionless and does not grow with distance::

    c_i = ( Σ_{j=i−N..i+N, j≠i} (r_j − r_i) / (2N · r_i) )²          [-]

It is ≈ 0 on a plane seen square-on, grows with the plane's curvature in range (incidence),
and is large at corners and at the edges of thin objects. The neighbours are the next valid
returns along the ring (no-return pixels are skipped, as LIO-SAM compacts its range image),
and c is undefined (NaN) where the window would leave the ring.

Unreliable points (:func:`unreliable_mask`, LOAM §V-A and Fig. 4): (a) points on a surface
nearly parallel to the beam — both neighbours differ in range by more than a fraction of r
(Fig. 4a); (b) points on the far side of a depth discontinuity, which may become occluded
when the sensor moves (Fig. 4b) — the N far-side returns next to a jump larger than
``occlusion_gap`` are dropped, as LIO-SAM's ``markOccludedPoints`` does; (c) returns closer than
``min_range`` (the hull and the crew) or beyond ``max_range``.

An unorganised cloud (a PCD/PLY file, a driver without ring numbers) is organised first by
:func:`organise_cloud`: ring = nearest nominal elevation, column = azimuth bin.
"""

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from usvdrake.sensors.messages import PointCloud


@dataclass
class FeatureParams:
    """Parameters of :func:`extract_features` (defaults after LOAM / LIO-SAM, re-scaled to
    the dimensionless roughness above)."""

    neighbours: int = 5  # [-] N: half-window of the roughness, LOAM |S| = 2N = 10
    edge_threshold: float = 2e-4  # [-] c above this may be an edge
    planar_threshold: float = 2e-5  # [-] c below this may be planar
    sectors: int = 6  # [-] sectors per ring (LOAM four, LIO-SAM six)
    max_edges_per_sector: int = 20  # [-] LIO-SAM keeps 20 per sector
    max_planar_per_sector: int | None = None  # [-] None: every smooth return (LIO-SAM)
    min_range: float = 1.0  # [m] nearer returns are the boat itself
    max_range: float = 100.0  # [m]
    occlusion_gap: float = 0.3  # [m] a depth jump larger than this marks occlusion (LIO-SAM)
    max_column_gap: int = 10  # [-] neighbours further apart in columns are not adjacent
    parallel_ratio: float = 0.02  # [-] |r_i±1 − r_i| > this · r_i on both sides: grazing beam


@dataclass
class LidarFeatures:
    """Edge (F^e) and planar (F^p) features of one sweep, in the sensor frame (Roboat II §V-A)."""

    edge_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # [m]
    planar_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # [m]
    edge_pixels: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), int))  # ring, col
    planar_pixels: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), int))
    edge_roughness: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [-] c
    planar_roughness: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [-] c


def compact_range_image(range_image: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The valid pixels of a range image in ring-major, column order: (ring, column, range).

    range_image: (rings × columns) [m], no return = inf, NaN or ≤ 0. Returns int arrays ring,
    column and the ranges r [m], all of length M (the number of returns)."""
    img = np.asarray(range_image, dtype=float)
    ring, col = np.nonzero(np.isfinite(img) & (img > 0.0))
    return ring, col, img[ring, col]


def roughness(ranges: np.ndarray, ring: np.ndarray, neighbours: int = 5) -> np.ndarray:
    """Roughness c_i of each return of a compacted range image (LOAM eq. (1), range form).

    ranges: (M,) [m] returns in ring-major, column order (:func:`compact_range_image`);
    ring: (M,) their ring; neighbours: N, half the window. Returns c (M,) [-],
    ``c_i = (Σ_{0<|j−i|≤N} (r_j − r_i) / (2N r_i))²``, NaN where the window i−N..i+N leaves
    the ring of i."""
    return _roughness_kernel(
        np.ascontiguousarray(ranges, dtype=float), np.ascontiguousarray(ring), int(neighbours)
    )


@njit(cache=True)
def _roughness_kernel(r, ring, n):
    m = len(r)
    c = np.full(m, np.nan)
    if m < 2 * n + 1:
        return c
    s = np.zeros(m + 1)  # running sums: the window sum is a difference of two
    for i in range(m):
        s[i + 1] = s[i] + r[i]
    for i in range(n, m - n):
        if ring[i - n] == ring[i] and ring[i + n] == ring[i]:
            diff = (s[i + n + 1] - s[i - n] - r[i]) - 2 * n * r[i]  # Σ_{j≠i} r_j − 2N r_i
            c[i] = (diff / (2 * n * r[i])) ** 2
    return c


def range_image_roughness(range_image: np.ndarray, neighbours: int = 5) -> np.ndarray:
    """:func:`roughness` as an image (rings × columns) [-], NaN where undefined or no return."""
    ring, col, r = compact_range_image(range_image)
    out = np.full(np.shape(range_image), np.nan)
    out[ring, col] = roughness(r, ring, neighbours)
    return out


def unreliable_mask(
    ranges: np.ndarray, ring: np.ndarray, column: np.ndarray, params: FeatureParams
) -> np.ndarray:
    """Returns that must not become features (LOAM §V-A, Fig. 4), as a bool mask (M,).

    Inputs as for :func:`roughness` plus the columns (M,). Marks (a) beams nearly parallel to
    the surface: |r_{i−1} − r_i| and |r_{i+1} − r_i| both > ``parallel_ratio`` · r_i (Fig. 4a);
    (b) the ``neighbours`` returns on the far side of a depth jump > ``occlusion_gap`` between
    adjacent returns (Fig. 4b; LIO-SAM ``markOccludedPoints``); (c) r outside
    [``min_range``, ``max_range``]."""
    r = np.asarray(ranges, dtype=float)
    ring, column = np.asarray(ring), np.asarray(column)
    m, n = len(r), params.neighbours
    bad = (r < params.min_range) | (r > params.max_range)
    if m < 2:
        return bad
    # Pairs (k, k+1) of returns that are neighbours on the same ring.
    adjacent = (ring[1:] == ring[:-1]) & (column[1:] - column[:-1] <= params.max_column_gap)
    dr = r[1:] - r[:-1]  # r_{k+1} − r_k
    # (b) k is the far side (dr < −gap): k−N+1..k are occluded; k+1 far: k+1..k+N.
    offsets = np.arange(n)
    far_left = np.nonzero(adjacent & (dr < -params.occlusion_gap))[0]
    far_right = np.nonzero(adjacent & (dr > params.occlusion_gap))[0] + 1
    idx_l = (far_left[:, None] - offsets[None, :]).ravel()
    idx_r = (far_right[:, None] + offsets[None, :]).ravel()
    # Only along the same ring as the jump.
    src_l = np.repeat(far_left, n)
    src_r = np.repeat(far_right, n)
    keep_l = (idx_l >= 0) & (ring[np.clip(idx_l, 0, m - 1)] == ring[src_l])
    keep_r = (idx_r < m) & (ring[np.clip(idx_r, 0, m - 1)] == ring[src_r])
    bad[idx_l[keep_l]] = True
    bad[idx_r[keep_r]] = True
    # (a) grazing incidence: both neighbours far in range relative to r_i.
    gap = np.abs(dr) > params.parallel_ratio * r[:-1]  # reused with r_i on each side below
    left_jump = np.zeros(m, bool)
    right_jump = np.zeros(m, bool)
    left_jump[1:] = adjacent & (np.abs(dr) > params.parallel_ratio * r[1:])
    right_jump[:-1] = adjacent & gap
    bad |= left_jump & right_jump
    return bad


def _sector_of(ring: np.ndarray, sectors: int) -> np.ndarray:
    """Sector id of each compacted return: each ring's returns cut into ``sectors`` equal runs
    (LIO-SAM splits the valid returns of a ring, not the azimuth, so that every sector has
    the same number of candidates)."""
    m = len(ring)
    starts = np.flatnonzero(np.r_[True, ring[1:] != ring[:-1]])
    lengths = np.diff(np.r_[starts, m])
    first = np.repeat(starts, lengths)
    length = np.repeat(lengths, lengths)
    pos = np.arange(m) - first
    within = np.minimum(pos * sectors // np.maximum(length, 1), sectors - 1)
    return np.repeat(np.arange(len(starts)), lengths) * sectors + within


def _local_extremum(score: np.ndarray, ring: np.ndarray, n: int) -> np.ndarray:
    """True where ``score`` is the strict maximum of its ±n window on the same ring (ties go
    to the first). LOAM's "mark the neighbours of a picked point", as a mask."""
    return _local_extremum_kernel(
        np.ascontiguousarray(score, dtype=float), np.ascontiguousarray(ring), int(n)
    )


@njit(cache=True)
def _local_extremum_kernel(score, ring, n):
    m = len(score)
    out = np.zeros(m, dtype=np.bool_)
    for i in range(m):
        si = score[i]
        if not np.isfinite(si):
            continue
        best = True
        for j in range(max(0, i - n), i):  # left: strictly above
            if ring[j] == ring[i] and score[j] >= si:
                best = False
                break
        if best:
            for j in range(i + 1, min(m, i + n + 1)):  # right: at least as high
                if ring[j] == ring[i] and score[j] > si:
                    best = False
                    break
        out[i] = best
    return out


def _top_per_sector(candidates: np.ndarray, key: np.ndarray, sector: np.ndarray, k: int | None):
    """Indices of at most k candidates per sector with the largest ``key``."""
    idx = np.flatnonzero(candidates)
    if k is None or len(idx) == 0:
        return idx
    order = np.lexsort((-key[idx], sector[idx]))
    idx, sec = idx[order], sector[idx[order]]
    first = np.flatnonzero(np.r_[True, sec[1:] != sec[:-1]])
    rank = np.arange(len(idx)) - np.repeat(first, np.diff(np.r_[first, len(idx)]))
    return np.sort(idx[rank < k])


def pixel_points(cloud: PointCloud) -> np.ndarray:
    """The sensor-frame point [m] of every pixel as a (rings × columns × 3) array, NaN where
    there is no return. Uses ``cloud.points`` where given (their measured directions), else the
    nominal ring elevation and column azimuth."""
    img = np.asarray(cloud.range_image, dtype=float)
    out = np.full(img.shape + (3,), np.nan)
    if len(cloud.points):
        out[cloud.ring, cloud.column] = cloud.points
        return out
    e = np.asarray(cloud.elevations)[:, None]
    a = np.asarray(cloud.azimuths)[None, :]
    ok = np.isfinite(img) & (img > 0)
    r = np.where(ok, img, np.nan)
    out[..., 0] = r * np.cos(e) * np.cos(a)
    out[..., 1] = r * np.cos(e) * np.sin(a)
    out[..., 2] = r * np.sin(e) * np.ones_like(a)
    return out


def _points_at(cloud: PointCloud, ring: np.ndarray, col: np.ndarray) -> np.ndarray:
    """:func:`pixel_points` at the pixels (ring, col) only (K × 3) [m]: the whole image of
    points is not built."""
    if len(cloud.points):
        row = np.full(np.shape(cloud.range_image), -1, dtype=np.int64)
        row[cloud.ring, cloud.column] = np.arange(len(cloud.points))
        return np.asarray(cloud.points, dtype=float)[row[ring, col]]
    r = np.asarray(cloud.range_image, dtype=float)[ring, col]
    e, a = np.asarray(cloud.elevations)[ring], np.asarray(cloud.azimuths)[col]
    return np.column_stack([r * np.cos(e) * np.cos(a), r * np.cos(e) * np.sin(a), r * np.sin(e)])


def extract_features(cloud: PointCloud, params: FeatureParams | None = None) -> LidarFeatures:
    """Edge and planar features of one sweep (Roboat II §V-A; LOAM §V-A; LIO-SAM featureExtraction).

    cloud: an organised sweep (its ``range_image`` [m], inf = no return; ``points``, ``ring``,
    ``column`` of its returns). Each ring's returns are cut into ``params.sectors`` runs; in
    each, up to ``max_edges_per_sector`` reliable returns that are local maxima of c over ±N
    and have c > ``edge_threshold`` become edges (largest first), and reliable non-edge
    returns with c < ``planar_threshold`` become planar (all of them, or the
    ``max_planar_per_sector`` smoothest local minima). Returns :class:`LidarFeatures`."""
    p = params or FeatureParams()
    ring, col, r = compact_range_image(cloud.range_image)
    c = roughness(r, ring, p.neighbours)
    usable = np.isfinite(c) & ~unreliable_mask(r, ring, col, p)
    sector = _sector_of(ring, p.sectors)
    score = np.where(usable, c, -np.inf)
    edge_cand = usable & (c > p.edge_threshold) & _local_extremum(score, ring, p.neighbours)
    edges = _top_per_sector(edge_cand, c, sector, p.max_edges_per_sector)
    is_edge = np.zeros(len(r), bool)
    is_edge[edges] = True
    flat = usable & ~is_edge & (c < p.planar_threshold)
    if p.max_planar_per_sector is not None:
        flat &= _local_extremum(np.where(flat, -c, -np.inf), ring, p.neighbours)
    planar = _top_per_sector(flat, -np.where(flat, c, np.inf), sector, p.max_planar_per_sector)
    both = np.r_[edges, planar]
    xyz = _points_at(cloud, ring[both], col[both])
    return LidarFeatures(
        edge_points=xyz[: len(edges)],
        planar_points=xyz[len(edges) :],
        edge_pixels=np.column_stack([ring[edges], col[edges]]),
        planar_pixels=np.column_stack([ring[planar], col[planar]]),
        edge_roughness=c[edges],
        planar_roughness=c[planar],
    )


def uniform_elevations(rings: int, lowest: float, highest: float) -> np.ndarray:
    """Nominal ring elevations [rad] of a sensor with equally spaced beams from ``lowest`` to
    ``highest`` [rad] (VLP-16: 16, ±15°; HDL-32E: 32, −30.67° … +10.67°)."""
    return np.linspace(lowest, highest, rings)


def organise_cloud(
    points: np.ndarray,
    elevations: np.ndarray,
    columns: int = 1800,
    time: float = 0.0,
) -> PointCloud:
    """Organise an unorganised cloud into a range image (elevation-ring × azimuth-column bins).

    points: (K × 3) [m] in the sensor frame (rows with r = 0 or non-finite are no returns);
    elevations: (rings,) nominal beam elevations [rad], ascending; columns: azimuth bins over
    [−π, π). A point goes to the ring of the nearest elevation, if within half the spacing of
    the adjacent beams, and to column ⌊(azimuth + π) · columns / 2π⌋; of several points in one
    pixel the nearest is kept. Returns a :class:`PointCloud` whose ``points`` are the kept
    input points (measured, not re-projected) with their ring and column."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    elev = np.asarray(elevations, dtype=float)
    spacing = np.gradient(elev) if len(elev) > 1 else np.array([np.inf])
    # the ring tests in sin(elevation) = z / r, which is monotone in the elevation: no arcsin
    # per point (the mid-points between rings and each ring's ± half spacing, as sines)
    half = np.pi / 2
    sin_mid = np.sin(np.r_[(elev[:-1] + elev[1:]) / 2, half])
    sin_lo = np.sin(np.clip(elev - 0.5 * spacing, -half, half))
    sin_hi = np.sin(np.clip(elev + 0.5 * spacing, -half, half))
    img, keep, ring, col, kept = _organise_kernel(
        pts, np.sin(elev), sin_mid, sin_lo, sin_hi, int(columns)
    )
    return PointCloud(
        time=time,
        elevations=elev,
        azimuths=column_azimuths(columns),
        range_image=img,
        points=kept,
        ring=ring,
        column=col,
        point_time=np.zeros(len(keep)),
    )


@njit(cache=True)
def _organise_kernel(pts, sin_elev, sin_mid, sin_lo, sin_hi, columns):
    """One pass of :func:`organise_cloud`: per pixel the nearest return (the first of equal
    ones). Returns (range image, kept rows of pts in pixel order, their rings, their columns,
    the kept points)."""
    rings = len(sin_elev)
    best = np.full(rings * columns, -1, dtype=np.int64)
    img = np.full((rings, columns), np.inf)
    for i in range(len(pts)):
        x, y, z = pts[i, 0], pts[i, 1], pts[i, 2]
        r = np.sqrt(x * x + y * y + z * z)
        if not (np.isfinite(r) and r > 0.0):
            continue
        e = min(1.0, max(-1.0, z / r))  # sin(elevation)
        if rings > 1:
            k = min(max(np.searchsorted(sin_elev, e), 1), rings - 1)
            ring = k - 1 if e < sin_mid[k - 1] else k  # the nearer of rings k − 1, k
        else:
            ring = 0
        if not (sin_lo[ring] <= e <= sin_hi[ring]):
            continue
        a = np.arctan2(y, x)
        col = int(np.floor((a + np.pi) * columns / (2 * np.pi))) % columns
        if best[ring * columns + col] < 0 or r < img[ring, col]:
            best[ring * columns + col] = i
            img[ring, col] = r
    n = 0
    for p in range(rings * columns):
        if best[p] >= 0:
            n += 1
    keep = np.empty(n, dtype=np.int64)
    ring_out = np.empty(n, dtype=np.int64)
    col_out = np.empty(n, dtype=np.int64)
    kept = np.empty((n, 3))
    n = 0
    for p in range(rings * columns):
        if best[p] >= 0:
            keep[n], ring_out[n], col_out[n] = best[p], p // columns, p % columns
            kept[n, 0], kept[n, 1], kept[n, 2] = pts[best[p], 0], pts[best[p], 1], pts[best[p], 2]
            n += 1
    return img, keep, ring_out, col_out, kept


def azimuth_column(azimuth: np.ndarray, columns: int) -> np.ndarray:
    """Column ⌊(azimuth + π) · columns / 2π⌋ of azimuths [rad] in ``columns`` bins over [−π, π)."""
    return np.floor((np.asarray(azimuth) + np.pi) * columns / (2 * np.pi)).astype(int) % columns


def column_azimuths(columns: int) -> np.ndarray:
    """Centre azimuth [rad] of each of the :func:`azimuth_column` bins."""
    return -np.pi + (np.arange(columns) + 0.5) * 2 * np.pi / columns


def nearest_per_pixel(
    r: np.ndarray, ring: np.ndarray, col: np.ndarray, rings: int, columns: int
) -> tuple[np.ndarray, np.ndarray]:
    """(range image rings × columns [m], inf = none; indices of the kept returns in pixel
    order): of several returns in one pixel the nearest is kept (sort by pixel, then range)."""
    pix = ring * columns + col
    order = np.lexsort((r, pix))
    keep = order[np.r_[True, pix[order][1:] != pix[order][:-1]]] if len(order) else order
    keep = keep[np.argsort(pix[keep], kind="stable")]
    img = np.full((rings, columns), np.inf)
    img[ring[keep], col[keep]] = r[keep]
    return img, keep
