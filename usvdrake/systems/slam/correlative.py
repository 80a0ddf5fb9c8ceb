"""Correlative scan matching (Olson, "Real-time correlative scan matching", ICRA 2009): the
global search that seeds PLICP when the motion is too large for its basin, and that finds loop
closures.

The reference points are rasterised into a likelihood field
(:mod:`usvdrake.systems.slam.likelihood_field`): each cell holds
exp(−d² / 2σ²), d the distance from its centre to the nearest reference point
(an exact Euclidean distance transform). A candidate pose (t_x, t_y, θ) of the current
points scores the mean field value under them (Olson's eq. 4 with the lookup table of his
§III-B; 1 on the surfaces, 0 far away), so the best pose of a search window is the maximum of a
3D grid of candidates.

That grid is searched exactly by branch and bound over bounds tables (Olson §IV-B; more
levels as in Hess et al. 2016): a coarse table whose cell holds the maximum of the k × k fine
cells it starts, and mid, top and top2 ones holding that of (k·m/2)², (k·m)² and (2·k·m)²
cells, bound the score of every fine translation inside a block. Every rotation × top2 block
is scored (a numba kernel, rotations on parallel threads), then blocks are opened best bound
first, each into its 2 × 2 (or m/2 × m/2, k × k) children, while their bound can still reach
the best score found: the result equals the exhaustive fine search (ties broken as the
two-level search before it broke them), at the cost of the first level and a few blocks. On
Intel's raw log the tracking searches (±92°) took 2.8 ms instead of 12.5 ms with the two-level
one (median of 120); the top2 and mid levels took 400 searches captured from raw ACES from
9.1 to 7.3 ms each (the same answers).
The fine answer is as accurate as the grid (``resolution`` in translation, ``angular_step``
in rotation); PLICP refines it.
"""

from typing import NamedTuple

import numpy as np
from numba import njit, prange

from usvdrake.systems.slam.likelihood_field import LikelihoodField


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
def _base_cells(cell0x, cell0y, px, py, thetas):
    """(bx, by)[θ, p] = floor(R(θ) p + cell0): the cell of point p (px, py: coordinates
    [cells] relative to a table's origin) rotated by θ and moved by cell0. A translation of
    the search window shifts it by whole cells, so a search computes it once per rotation and
    point, not once per candidate."""
    bx = np.empty((len(thetas), len(px)), np.int64)
    by = np.empty((len(thetas), len(px)), np.int64)
    for a in prange(len(thetas)):
        c, s = np.cos(thetas[a]), np.sin(thetas[a])
        for p in range(len(px)):
            bx[a, p] = int(np.floor(c * px[p] - s * py[p] + cell0x))
            by[a, p] = int(np.floor(s * px[p] + c * py[p] + cell0y))
    return bx, by


@njit(cache=True, inline="always")
def _bound_cell(g, n, reach):
    """A bound table's index for cell g of a table n cells long whose entries cover ``reach``
    cells onwards: g itself, 0 for a block that starts before the table but reaches into it
    (its max is that of the table's first cells, which entry 0 bounds), −1 off the table."""
    if g >= n or g <= -reach:
        return -1
    return max(g, 0)


@njit(cache=True, inline="always")
def _cell_sum(table, bx, by, a, di, dj, reach):
    """Σ_p table[by[a, p] + dj, bx[a, p] + di], the cells through :func:`_bound_cell`: one
    candidate's score (``reach`` 1) or one block's bound (``reach`` its side), summed in the
    points' order."""
    rows, cols = table.shape
    total = 0.0
    for p in range(bx.shape[1]):
        gx = _bound_cell(bx[a, p] + di, cols, reach)
        gy = _bound_cell(by[a, p] + dj, rows, reach)
        if gx >= 0 and gy >= 0:
            total += table[gy, gx]
    return total


@njit(cache=True, parallel=True)
def _sum_cells(table, bx, by, nx, ny, stride, reach):
    """scores[θ, i, j] = Σ_p table[by[θ, p] + j·stride, bx[θ, p] + i·stride], the cells
    through :func:`_bound_cell` (``reach`` 1: a plain table, off it counts 0). Rotations run in
    parallel (numba threads; each writes its own slice, so the result does not depend on the
    thread count): on 2 cores the two-level search's coarse level, over ±92° on Freiburg 079
    scans, took 16 ms instead of 40 ms serially."""
    rows, cols = table.shape
    out = np.zeros((bx.shape[0], nx, ny))
    for a in prange(bx.shape[0]):
        for p in range(bx.shape[1]):
            for i in range(nx):
                gx = _bound_cell(bx[a, p] + i * stride, cols, reach)
                if gx < 0:
                    continue
                for j in range(ny):
                    gy = _bound_cell(by[a, p] + j * stride, rows, reach)
                    if gy >= 0:
                        out[a, i, j] += table[gy, gx]
    return out


def _score_grid(table, cell0x, cell0y, px, py, thetas, nx, ny, stride):
    """scores[θ, i, j] = Σ_points table[cell of (R(θ) p) + cell0 + (i, j)·stride] for points
    given in cells (px, py: coordinates [cells] relative to the table's origin)."""
    return _sum_cells(table, *_base_cells(cell0x, cell0y, px, py, thetas), nx, ny, stride, 1)


@njit(cache=True, inline="always")
def _least_sq(ns, nc, x0, x1, y0, y1):
    """Least (ns x + nc y)² over the rectangle [x0, x1] × [y0, y1]: the sideways offset is
    linear in (x, y), so its extremes lie on the corners (0 when they straddle 0)."""
    c00 = ns * x0 + nc * y0
    c01 = ns * x0 + nc * y1
    c10 = ns * x1 + nc * y0
    c11 = ns * x1 + nc * y1
    lo = min(min(c00, c01), min(c10, c11))
    hi = max(max(c00, c01), max(c10, c11))
    if lo > 0.0:
        return lo * lo
    if hi < 0.0:
        return hi * hi
    return 0.0


@njit(cache=True, inline="always")
def _block_penalty(lat, a, i0, j0, size, nf):
    """The least lateral penalty weight · (ns[a] x + nc[a] y)² over the fine translations
    (i, j) ∈ [i0, i0 + size) × [j0, j0 + size) (clipped to the nf × nf window) of rotation a:
    what a block's bound loses (``lat`` as in :func:`_branch_and_bound`)."""
    w, lx, ly, res = lat[0][0], lat[0][1], lat[0][2], lat[0][3]
    return w * _least_sq(
        lat[1][a],
        lat[2][a],
        lx + i0 * res,
        lx + min(i0 + size - 1, nf - 1) * res,
        ly + j0 * res,
        ly + min(j0 + size - 1, nf - 1) * res,
    )


@njit(cache=True)
def _branch_and_bound(
    fine, coarse, mid, top, top2, bx, by, k, m, nf, lat, ex_i, ex_j, ex_r, floor, first=False
):
    """(score, θ index, i, j, found): the best fine candidate of a window of nf × nf
    translations whose score exceeds ``floor`` (found False, and (0, 0, 0), if none does),
    searched best-first over five levels of bounds (Olson 2009 §IV-B, with more levels as in
    Hess et al. 2016's branch and bound): cells of (2·k·m)² translations scored on ``top2``
    for every rotation (each a sum over the points, bx/by their base cells of
    :func:`_base_cells`), their 2 × 2 top cells on ``top`` when that bound can still reach the
    best score, a top cell's 2 × 2 blocks on ``mid`` likewise, a mid block's (m/2)² blocks on
    ``coarse`` likewise, the k × k fine candidates of a block on ``fine`` likewise. (Over ±92°
    a scan has ~1000 rotations: scoring 4 cells a rotation rather than 16 more than pays for the
    top cells then opened.)

    Ties go where the two-level search over coarse cells in decreasing bound order put them
    (the same answer, to the bit, as that search wherever its bounds held): among the fine
    candidates of the best score, the one of the largest coarse bound, then the lowest
    (θ, coarse i, coarse j) index, then the lowest (i, j) within. Translations within ``ex_r``
    cells of (ex_i, ex_j) are excluded (ex_r < 0: none). ``lat`` = ([weight, lx, ly, res],
    ns, nc), ns and nc per rotation: a fine cell's score loses weight · (ns[a] (lx + i·res) +
    nc[a] (ly + j·res))², the arc prior of :func:`lateral_motion`, each bound its least value
    over the cell (weight 0: none). ``first``: return the first candidate found above
    ``floor`` (whether there is one, not which is best)."""
    w, lx, ly, res = lat[0][0], lat[0][1], lat[0][2], lat[0][3]
    ns, nc = lat[1], lat[2]
    big = k * m
    h = m // 2  # coarse cells per side of a mid block (m even)
    nc1 = -(-nf // k)  # coarse cells per side
    n_top = -(-nc1 // m)  # top cells per side
    n_t2 = -(-n_top // 2)  # top2 cells per side
    n_a = bx.shape[0]
    # first level: every rotation × top2 cell, 1/(4m²) as many cells as a two-level search
    t2 = _sum_cells(top2, bx, by, n_t2, n_t2, 2 * big, 2 * big)
    if w > 0.0:
        for a in range(n_a):
            for ui in range(n_t2):
                for uj in range(n_t2):
                    t2[a, ui, uj] -= _block_penalty(lat, a, ui * 2 * big, uj * 2 * big, 2 * big, nf)
    flat2 = t2.ravel()
    order2 = np.argsort(-flat2)
    best, ba, bi, bj = floor, 0, 0, 0
    # the winner's (−coarse bound, coarse index, fine index); −∞ until one beats the floor
    key_b, key_o, key_f = -np.inf, 0, 0
    b1 = np.empty(m * m)
    o1 = np.empty(m * m, np.int64)
    b2 = np.empty(4)
    o2 = np.empty(4, np.int64)
    b3 = np.empty(4)
    o3 = np.empty(4, np.int64)
    for n2 in range(len(order2)):
        u = order2[n2]
        if flat2[u] < best:
            break
        a = u // (n_t2 * n_t2)
        ui, uj = (u // n_t2) % n_t2, u % n_t2
        # its top cells' bounds, as the three-level search summed them for every rotation
        n_t = 0
        for ti in range(2 * ui, min(2 * ui + 2, n_top)):
            for tj in range(2 * uj, min(2 * uj + 2, n_top)):
                total = _cell_sum(top, bx, by, a, ti * big, tj * big, big)
                if w > 0.0:
                    total -= _block_penalty(lat, a, ti * big, tj * big, big, nf)
                b2[n_t] = total
                o2[n_t] = ti * n_top + tj
                n_t += 1
        tops = np.argsort(-b2[:n_t])
        for q2 in range(n_t):
            if b2[tops[q2]] < best:
                break
            ti, tj = o2[tops[q2]] // n_top, o2[tops[q2]] % n_top
            # its half-size blocks' bounds (h × h coarse cells each) on ``mid``
            n_h = 0
            for hi in range(ti * 2, ti * 2 + 2):
                for hj in range(tj * 2, tj * 2 + 2):
                    if hi * h >= nc1 or hj * h >= nc1:
                        continue
                    total = _cell_sum(mid, bx, by, a, hi * h * k, hj * h * k, h * k)
                    if w > 0.0:
                        total -= _block_penalty(lat, a, hi * h * k, hj * h * k, h * k, nf)
                    b3[n_h] = total
                    o3[n_h] = hi * 2 * n_top + hj
                    n_h += 1
            halves = np.argsort(-b3[:n_h])
            for q3 in range(n_h):
                if b3[halves[q3]] < best:
                    break
                hi, hj = o3[halves[q3]] // (2 * n_top), o3[halves[q3]] % (2 * n_top)
                # the coarse bounds of its blocks, summed in the points' order as a coarse-only
                # search sums them (so equal to its bounds to the bit)
                n_b = 0
                for ci in range(hi * h, min(hi * h + h, nc1)):
                    for cj in range(hj * h, min(hj * h + h, nc1)):
                        total = _cell_sum(coarse, bx, by, a, ci * k, cj * k, k)
                        if w > 0.0:
                            total -= _block_penalty(lat, a, ci * k, cj * k, k, nf)
                        b1[n_b] = total
                        o1[n_b] = (a * nc1 + ci) * nc1 + cj
                        n_b += 1
                blocks = np.argsort(-b1[:n_b])
                for q in range(n_b):
                    bound, o = b1[blocks[q]], o1[blocks[q]]
                    if bound < best:
                        break
                    if bound == best and (-bound, o) > (key_b, key_o):
                        continue
                    ci, cj = (o // nc1) % nc1, o % nc1
                    for di in range(k):
                        i = ci * k + di
                        if i >= nf:
                            break
                        for dj in range(k):
                            j = cj * k + dj
                            if j >= nf:
                                break
                            if (i - ex_i) ** 2 + (j - ex_j) ** 2 <= ex_r * ex_r:
                                continue
                            total = _cell_sum(fine, bx, by, a, i, j, 1)
                            if w > 0.0:
                                d = ns[a] * (lx + i * res) + nc[a] * (ly + j * res)
                                total -= w * d * d
                            f = di * k + dj
                            if total > best or (
                                total == best and (-bound, o, f) < (key_b, key_o, key_f)
                            ):
                                best, ba, bi, bj = total, a, i, j
                                key_b, key_o, key_f = -bound, o, f
                                if first:
                                    return best, ba, bi, bj, True
    return best, ba, bi, bj, key_b > -np.inf


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
    rival_above: float = 0.0,
    min_score: float = 0.0,
    first_rival: bool = False,
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
    With ``rival_above`` ∈ (0, 1] the runner-up is looked for only among scores above that
    fraction of the best one (none there: ``runner_up`` 0, its pose None): the branch and
    bound then drops every cell bounded below it, and a caller that only asks "is there a
    rival within that fraction?" gets the exact search's answer sooner (240 of Intel's loop
    searches at 0.7: 2.15 s instead of 3.31 s). With ``first_rival`` too, the search stops at
    the first rival above that fraction (``runner_up`` is its score, not the best rival's):
    the same answer to that question, sooner.

    ``min_score`` ∈ (0, 1]: scores below it are not looked for (without ``prior_from``): every
    cell bounded below it is dropped, and when nothing reaches it the match is the ``guess``
    with score 0 (runner-up 0). A caller that refuses matches below it (a loop search's
    ``min_loop_score``) gets the same answer sooner; a best above it is the same pose.

    With ``prior_from`` (the pose (x, y, θ) the sensor had at the previous scan, in the field's
    frame) and ``lateral_weight`` > 0, a candidate's score is lowered by lateral_weight ·
    :func:`lateral_motion`² [1/m²] (the coarse bounds by its least value over their cell, so
    the search stays exact): of two poses a corridor fits alike, the one reached without
    sliding sideways wins. The returned ``score`` is the likelihood alone."""
    pts = _evenly(current, max_points, "correlative_match")
    if not 0.0 <= rival_above <= 1.0:
        raise ValueError(f"correlative_match: rival_above must be in [0, 1], got {rival_above}")
    if rival_above > 0 and prior_from is not None and lateral_weight > 0:
        # the search's floor would be on the prior-weighted score, the question on the
        # likelihood alone: the two disagree
        raise ValueError("correlative_match: rival_above with a lateral prior is not supported")
    if min_score > 0 and prior_from is not None and lateral_weight > 0:
        raise ValueError("correlative_match: min_score with a lateral prior is not supported")
    res, k = field.resolution, field.k
    if angular_step is None:
        reach = float(np.max(np.hypot(pts[:, 0], pts[:, 1])))
        angular_step = min(np.deg2rad(2.0), res / max(reach, res))
    n_a = int(np.floor(angular_window / angular_step))
    thetas = guess[2] + angular_step * np.arange(-n_a, n_a + 1)
    n_f = int(np.floor(linear_window / res))
    nfx = 2 * n_f + 1  # fine translations per side
    # candidate (i, j) translates by guess − window + (i, j)·res; points in cells from the origin
    x0 = guess[0] - n_f * res - field.origin[0]
    y0 = guess[1] - n_f * res - field.origin[1]
    px, py = pts[:, 0] / res, pts[:, 1] / res
    bx, by = _base_cells(x0 / res, y0 / res, px, py, thetas)
    weight = lateral_weight * len(pts) if prior_from is not None else 0.0
    # (x, y) of fine cell (i, j) relative to the previous pose: (lx + i·res, ly + j·res)
    prev = np.zeros(3) if prior_from is None else np.asarray(prior_from, float)
    lx, ly = x0 + field.origin[0] - prev[0], y0 + field.origin[1] - prev[1]
    phi = 0.5 * (prev[2] + thetas)  # mean heading of the step, per rotation
    ns, nc = -np.sin(phi), np.cos(phi)  # the sideways offset is ns·x + nc·y
    lat = (np.array([weight, lx, ly, res]), ns, nc)
    tables = (
        field.fine, field.coarse, field.mid, field.top, field.top2, bx, by, k, field.m, nfx, lat
    )  # fmt: skip

    def search(ex_i: int, ex_j: int, ex_r: float, floor: float = -1.0, first: bool = False):
        return _branch_and_bound(*tables, ex_i, ex_j, ex_r, floor, first)

    def pose_of(a: int, i: int, j: int) -> np.ndarray:
        return np.array([x0 + i * res + field.origin[0], y0 + j * res + field.origin[1], thetas[a]])

    # (a hair below the least score: one exactly at it is found)
    least = min_score * len(pts) * (1.0 - 1e-9) if min_score > 0 else -1.0
    best, a, i, j, found = search(0, 0, -1.0, least)
    if not found:
        return CorrelativeMatch(np.asarray(guess, float).copy(), 0.0, 0.0, None)
    if weight > 0:  # the likelihood alone
        best += weight * lateral_motion(prev, pose_of(a, i, j)) ** 2
    runner_up, runner_up_pose = np.nan, None
    if distinct > 0:
        # (a hair below the fraction: a rival exactly at it is found, its score exact; with
        # first_rival exactly at it, so that any rival found is above it)
        floor = rival_above * best * (1.0 if first_rival else 1.0 - 1e-9)
        floor = floor if rival_above > 0 else -1.0
        first = first_rival and rival_above > 0
        second, *cell, found = search(i, j, distinct / res, floor, first)
        if found or rival_above == 0:
            runner_up_pose = pose_of(*cell)
            if weight > 0:
                second += weight * lateral_motion(prev, runner_up_pose) ** 2
            runner_up = max(second, 0.0) / len(pts)
        else:
            runner_up = 0.0
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
    (Pham et al. eqs. 4-10) trusts the few far points and stays centimetre-small."""
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
