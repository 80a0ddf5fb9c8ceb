"""Correlative scan matching (Olson, "Real-time correlative scan matching", ICRA 2009): the
global search that seeds PLICP when the motion is too large for its basin, and that finds loop
closures.

The reference points are rasterised into a likelihood field: each cell holds
exp(−d² / 2σ²), d the distance from its centre to the nearest reference point
(``scipy.ndimage.distance_transform_edt``). A candidate pose (t_x, t_y, θ) of the current
points scores the mean field value under them (Olson's eq. 4 with the lookup table of his
§III-B; 1 on the surfaces, 0 far away), so the best pose of a search window is the maximum of a
3D grid of candidates.

That grid is searched exactly by Olson's two-level method (§IV-B): a coarse table whose cell
holds the maximum of the fine cells it covers bounds the score of every fine translation inside
a coarse one. All coarse candidates are scored (a numba kernel over rotations × translations ×
points, rotations on parallel threads), and the fine translations are evaluated coarse cell by
coarse cell in decreasing bound order until the bound falls below the best fine score found:
the result equals the exhaustive fine search, at the cost of the coarse one and a few fine
cells. The fine answer is as accurate as the grid (``resolution`` in translation,
``angular_step`` in rotation); PLICP refines it.
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from scipy.ndimage import distance_transform_edt

from usvdrake.systems.slam.plicp import rot


def distance_field(points: np.ndarray, resolution: float, margin: float):
    """(field, origin): distance [m] from each cell centre to the nearest point; rows are y,
    columns x, cell (r, c) covers origin + (c, r)·resolution onwards."""
    lo = points.min(axis=0) - margin
    hi = points.max(axis=0) + margin
    shape = np.ceil((hi - lo) / resolution).astype(int) + 1
    empty = np.ones(shape[::-1], bool)  # True where no point
    cells = np.floor((points - lo) / resolution).astype(int)
    empty[cells[:, 1], cells[:, 0]] = False
    return distance_transform_edt(empty) * resolution, lo


def _window_max(field: np.ndarray, k: int) -> np.ndarray:
    """out[r, c] = max of field[r : r + k, c : c + k] (cells beyond the edge count as 0)."""
    out = field.copy()
    for axis in (0, 1):
        src = out.copy()
        for m in range(1, k):
            if axis == 0:
                np.maximum(out[:-m], src[m:], out=out[:-m])
            else:
                np.maximum(out[:, :-m], src[:, m:], out=out[:, :-m])
    return out


@dataclass
class LikelihoodField:
    """Olson's lookup table of a reference point set: ``fine`` (cell ``resolution`` [m]) and
    ``coarse`` = the max over each ``k`` × ``k`` block of fine cells starting at that cell."""

    fine: np.ndarray
    coarse: np.ndarray
    origin: np.ndarray  # [m] corner of cell (0, 0)
    resolution: float
    k: int

    @classmethod
    def build(
        cls,
        reference: np.ndarray,
        resolution: float = 0.05,
        sigma: float = 0.1,
        margin: float = 2.0,
        k: int = 4,
    ) -> "LikelihoodField":
        """The field of ``reference`` (N × 2 points [m]), σ [m] the width of each point's
        bump (about the sensor noise plus the grid's quantisation), ``margin`` [m] of
        empty space kept around the points, ``k`` fine cells per coarse cell side."""
        if len(reference) == 0:
            raise ValueError("LikelihoodField: no reference points")
        d, lo = distance_field(np.asarray(reference, float), resolution, margin)
        fine = np.exp(-0.5 * (d / sigma) ** 2)
        return cls(fine, _window_max(fine, k), lo, resolution, k)

    def score(self, points: np.ndarray, pose) -> float:
        """Mean field value [0, 1] under ``points`` (sensor frame) placed at ``pose`` (x, y, θ)."""
        placed = points @ rot(pose[2]).T + np.asarray(pose[:2], float)
        gx, gy = np.floor((placed - self.origin) / self.resolution).astype(int).T
        rows, cols = self.fine.shape
        ok = (gx >= 0) & (gx < cols) & (gy >= 0) & (gy < rows)
        return float(self.fine[gy[ok], gx[ok]].sum() / max(len(points), 1))


def lateral_motion(start, end) -> float:
    """[m] sideways part of the step from pose ``start`` to pose ``end`` (x, y, θ): the
    translation's component normal to the mean heading (θ_start + θ_end)/2. A vehicle that
    cannot move sideways (wheels; a hull, nearly) drives a circular arc between two scans,
    whose chord lies along that mean heading: 0 for driving, turning on the spot and any arc
    between them alike. (Ours: the corridor aliasing of issue 6's building logs matched turns
    on the spot as sideways jumps of up to 1 m.)"""
    phi = 0.5 * (start[2] + end[2])
    return float(-np.sin(phi) * (end[0] - start[0]) + np.cos(phi) * (end[1] - start[1]))


def _evenly(current, max_points: int, caller: str) -> np.ndarray:
    """At most ``max_points`` of the current points (M × 2), every k-th; a ValueError naming
    ``caller`` if there are none."""
    pts = np.asarray(current, float)
    if len(pts) == 0:
        raise ValueError(f"{caller}: no current points")
    return pts[:: max(1, -(-len(pts) // max_points))]


class CorrelativeMatch(NamedTuple):
    pose: np.ndarray  # (x [m], y [m], θ [rad]) of the current points in the field's frame
    score: float  # mean likelihood of the points there, in [0, 1]
    runner_up: float  # best score at least ``distinct`` away (NaN when not asked for)
    runner_up_pose: np.ndarray | None = None  # (x, y, θ) of that runner-up (None: not asked)


@njit(cache=True, parallel=True)
def _score_grid(table, cell0x, cell0y, px, py, thetas, nx, ny, stride):
    """scores[θ, i, j] = Σ_points table[cell of (R(θ) p) + cell0 + (i, j)·stride] for points
    given in cells (px, py: coordinates [cells] relative to the table's origin). Rotations
    run in parallel (numba threads; each writes its own slice, so the result does not depend
    on the thread count): on 2 cores a ±92° tracking search on Freiburg 079 scans took 16 ms
    instead of 40 ms serially."""
    rows, cols = table.shape
    out = np.zeros((len(thetas), nx, ny))
    for a in prange(len(thetas)):
        c, s = np.cos(thetas[a]), np.sin(thetas[a])
        for p in range(len(px)):
            bx = int(np.floor(c * px[p] - s * py[p] + cell0x))
            by = int(np.floor(s * px[p] + c * py[p] + cell0y))
            for i in range(nx):
                gx = bx + i * stride
                if gx < 0 or gx >= cols:
                    continue
                for j in range(ny):
                    gy = by + j * stride
                    if gy >= 0 and gy < rows:
                        out[a, i, j] += table[gy, gx]
    return out


@njit(cache=True)
def _least_lateral_sq(ns, nc, lx, ly, res, k, nfx, ncx):
    """out[a, ci, cj] = least (ns[a] x + nc[a] y)² over the coarse cell's translations x ∈ lx +
    [ci·k, min(ci·k + k − 1, nfx − 1)]·res (y likewise): the sideways offset is linear in
    them, so its extremes lie on the cell's corners (0 when they straddle 0)."""
    out = np.zeros((len(ns), ncx, ncx))
    for a in range(len(ns)):
        for ci in range(ncx):
            x0 = lx + ci * k * res
            x1 = lx + min(ci * k + k - 1, nfx - 1) * res
            for cj in range(ncx):
                y0 = ly + cj * k * res
                y1 = ly + min(cj * k + k - 1, nfx - 1) * res
                c00 = ns[a] * x0 + nc[a] * y0
                c01 = ns[a] * x0 + nc[a] * y1
                c10 = ns[a] * x1 + nc[a] * y0
                c11 = ns[a] * x1 + nc[a] * y1
                lo = min(min(c00, c01), min(c10, c11))
                hi = max(max(c00, c01), max(c10, c11))
                if lo > 0.0:
                    out[a, ci, cj] = lo * lo
                elif hi < 0.0:
                    out[a, ci, cj] = hi * hi
    return out


@njit(cache=True)
def _refine(
    fine,
    cell0x,
    cell0y,
    px,
    py,
    thetas,
    lat,
    order,
    ci,
    cj,
    ca,
    bounds,
    k,
    nfx,
    nfy,
    ex_i,
    ex_j,
    ex_r,
):
    """Branch and bound over the coarse cells in ``order`` (decreasing bound): the best fine
    (θ index, i, j) and its score; stops once a bound cannot beat the best. Translations within
    ``ex_r`` cells of (ex_i, ex_j) are excluded (ex_r < 0: none). ``lat`` = ([weight, lx, ly,
    res], ns, nc), ns and nc per rotation: a fine cell's score loses weight · (ns[a] (lx +
    i·res) + nc[a] (ly + j·res))², the arc prior of :func:`lateral_motion` (weight 0: none)."""
    rows, cols = fine.shape
    w, lx, ly, ns, nc, res = lat[0][0], lat[0][1], lat[0][2], lat[1], lat[2], lat[0][3]
    best, bi, bj, ba = -1.0, 0, 0, 0
    for n in range(len(order)):
        o = order[n]
        if bounds[o] <= best:
            break
        a = ca[o]
        c, s = np.cos(thetas[a]), np.sin(thetas[a])
        i0, j0 = ci[o] * k, cj[o] * k
        for di in range(k):
            i = i0 + di
            if i >= nfx:
                break
            for dj in range(k):
                j = j0 + dj
                if j >= nfy:
                    break
                if (i - ex_i) ** 2 + (j - ex_j) ** 2 <= ex_r * ex_r:
                    continue
                total = 0.0
                for p in range(len(px)):
                    gx = int(np.floor(c * px[p] - s * py[p] + cell0x)) + i
                    gy = int(np.floor(s * px[p] + c * py[p] + cell0y)) + j
                    if gx >= 0 and gx < cols and gy >= 0 and gy < rows:
                        total += fine[gy, gx]
                if w > 0.0:
                    d = ns[a] * (lx + i * res) + nc[a] * (ly + j * res)
                    total -= w * d * d
                if total > best:
                    best, bi, bj, ba = total, i, j, a
    return best, ba, bi, bj


def correlative_match(
    field: LikelihoodField,
    current: np.ndarray,
    guess=(0.0, 0.0, 0.0),
    linear_window: float = 1.2,
    angular_window: float = np.deg2rad(40.0),
    angular_step: float | None = None,
    max_points: int = 400,
    distinct: float = 0.0,
    prior_from=None,
    lateral_weight: float = 0.0,
) -> CorrelativeMatch:
    """The best pose (x, y, θ) of ``current`` (M × 2 points [m], sensor frame) in ``field``'s
    frame among translations within ± ``linear_window`` [m] of ``guess`` on the field's grid
    and rotations within ± ``angular_window`` [rad] every ``angular_step`` [rad] (default: the
    angle that moves the farthest used point by one cell, Olson §III-A), with its score, the
    mean likelihood [0, 1] of the points there. Exact on that grid (branch and bound).

    Olson's eq. 1 multiplies in a motion prior. A constant-velocity one, of any weight we
    tried, made tracking worse on the subsampled CARMEN logs, whose steps alternate between
    turning on the spot and driving (the caller weighs the search against its own
    constant-velocity match instead); the kinematic one below, which only forbids sliding
    sideways, made it better (issue 6's logs: see ``offline.LOG_CONFIG``).

    With ``distinct`` > 0 [m] it also finds the runner-up: the best score of the window's
    translations at least that far from the best pose (any rotation), the same branch
    and bound with that disc excluded. A runner-up close to the score means the scene repeats
    (a corridor, a row of doors) and the best pose is not to be trusted as a loop closure.

    With ``prior_from`` (the pose (x, y, θ) the sensor had at the previous scan, in the field's
    frame) and ``lateral_weight`` > 0, a candidate's score is lowered by lateral_weight ·
    :func:`lateral_motion`² [1/m²] (the coarse bounds by its least value over their cell, so
    the search stays exact): of two poses a corridor fits alike, the one reached without
    sliding sideways wins. The returned ``score`` is the likelihood alone."""
    pts = _evenly(current, max_points, "correlative_match")
    res, k = field.resolution, field.k
    if angular_step is None:
        reach = float(np.max(np.hypot(pts[:, 0], pts[:, 1])))
        angular_step = min(np.deg2rad(2.0), res / max(reach, res))
    n_a = int(np.floor(angular_window / angular_step))
    thetas = guess[2] + angular_step * np.arange(-n_a, n_a + 1)
    n_f = int(np.floor(linear_window / res))
    nfx = nfy = 2 * n_f + 1
    # candidate (i, j) translates by guess − window + (i, j)·res; points in cells from the origin
    x0 = guess[0] - n_f * res - field.origin[0]
    y0 = guess[1] - n_f * res - field.origin[1]
    px, py = pts[:, 0] / res, pts[:, 1] / res
    ncx = -(-nfx // k)
    bounds = _score_grid(field.coarse, x0 / res, y0 / res, px, py, thetas, ncx, ncx, k)
    weight = lateral_weight * len(pts) if prior_from is not None else 0.0
    # (x, y) of fine cell (i, j) relative to the previous pose: (lx + i·res, ly + j·res)
    prev = np.zeros(3) if prior_from is None else np.asarray(prior_from, float)
    lx, ly = x0 + field.origin[0] - prev[0], y0 + field.origin[1] - prev[1]
    phi = 0.5 * (prev[2] + thetas)  # mean heading of the step, per rotation
    ns, nc = -np.sin(phi), np.cos(phi)  # the sideways offset is ns·x + nc·y
    lat = (np.array([weight, lx, ly, res]), ns, nc)
    if weight > 0:  # each coarse bound less the least penalty over its cell's translations
        bounds = bounds - weight * _least_lateral_sq(ns, nc, lx, ly, res, k, nfx, ncx)
    flat = bounds.ravel()
    ca, ci, cj = np.unravel_index(np.arange(flat.size), bounds.shape)
    common = (field.fine, x0 / res, y0 / res, px, py, thetas, lat)
    rest = (ci, cj, ca, flat, k, nfx, nfy)
    top = np.array([np.argmax(flat)])

    def search(*exclude):
        # the fine score found inside the best-bounded coarse cell is reached, so no coarse
        # cell bounded below it can hold the answer: only the others are sorted (a full sort
        # of every rotation × coarse cell took a fifth of a tracking search), in the order a
        # stable sort of all of them gives them, so the result is the exhaustive one
        reached = _refine(*common, top, *rest, *exclude)[0]
        keep = np.flatnonzero(flat >= reached)
        return _refine(*common, keep[np.argsort(-flat[keep], kind="stable")], *rest, *exclude)

    def pose_of(a: int, i: int, j: int) -> np.ndarray:
        return np.array([x0 + i * res + field.origin[0], y0 + j * res + field.origin[1], thetas[a]])

    best, a, i, j = search(0, 0, -1.0)
    if weight > 0:  # the likelihood alone
        best += weight * lateral_motion(prev, pose_of(a, i, j)) ** 2
    runner_up, runner_up_pose = np.nan, None
    if distinct > 0:
        second, *cell = search(i, j, distinct / res)
        runner_up_pose = pose_of(*cell)
        if weight > 0:
            second += weight * lateral_motion(prev, runner_up_pose) ** 2
        runner_up = max(second, 0.0) / len(pts)
    return CorrelativeMatch(
        pose_of(a, i, j), float(best / len(pts)), float(runner_up), runner_up_pose
    )


def match_covariance(
    field: LikelihoodField,
    current: np.ndarray,
    pose,
    temperature: float = 2.0,
    linear_span: float = 1.0,
    angular_span: float = 0.05,
    angular_step: float = 0.01,
    max_points: int = 400,
) -> np.ndarray:
    """Covariance (3 × 3: x [m], y [m], θ [rad]) of a match of ``current`` (M × 2 points,
    sensor frame) at ``pose`` in ``field``, from how its score spreads over the poses around it
    (Olson 2009 §III-C): every translation on the field's grid within ± ``linear_span`` [m]
    and rotation within ± ``angular_span`` [rad] (every ``angular_step``) gets the weight
    exp((S − S_max) / ``temperature``), S the sum of the field under the points (at most
    ``max_points`` of them, evenly picked), and the covariance is that of the weights:
    K/s − u uᵀ/s² with s = Σ w, u = Σ w x, K = Σ w x xᵀ (Olson's, x the offset from ``pose``).

    Olson's table holds log-likelihoods, so his S is one; ours holds likelihoods (1 on a
    surface, exp(−d²/2σ²) off it), whose sum near a surface falls as N δ²/2σ² for an offset δ
    across it: with temperature T, the variance T σ²/N of N points each σ-precise. Below the
    grid's cell the weights sit in one cell and the variance is about 0 (a caller adds its
    floor). Where the scene leaves a direction free (a corridor's length), the weights stay
    flat along it and the variance grows to the span's uniform one, where Censi's closed form
    (002 eqs. 4-10) trusts the few far points and stays centimetre-small."""
    pts = _evenly(current, max_points, "match_covariance")
    res = field.resolution
    n = int(np.floor(linear_span / res))
    m = int(np.floor(angular_span / angular_step))
    dth = angular_step * np.arange(-m, m + 1)
    x0 = (pose[0] - n * res - field.origin[0]) / res
    y0 = (pose[1] - n * res - field.origin[1]) / res
    px, py = pts[:, 0] / res, pts[:, 1] / res
    sums = _score_grid(field.fine, x0, y0, px, py, pose[2] + dth, 2 * n + 1, 2 * n + 1, 1)
    w = np.exp((sums - sums.max()) / temperature)
    w = np.moveaxis(w / w.sum(), 0, -1)  # (x, y, θ) like the offsets
    d = res * np.arange(-n, n + 1)
    offsets = np.stack(np.meshgrid(d, d, dth, indexing="ij"), axis=-1)
    centred = offsets - np.tensordot(w, offsets, 3)
    return np.einsum("ijk,ijka,ijkb->ab", w, centred, centred)
