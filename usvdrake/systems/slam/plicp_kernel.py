"""Compiled PLICP (Censi 2008): the iteration loop of :func:`usvdrake.systems.slam.plicp.plicp` in
one numba kernel, operation for operation the numpy implementation kept there as the reference
(``plicp_reference``), whose ~40 small array calls per iteration bounded it by call overhead.

Nearest neighbours: a uniform grid over the reference scan (:func:`build_grid`, counting sort by
cell, points kept in index order within a cell, built per call in ~15 µs). A query first tries a
hint (the point's nearest at the last iteration, else the previous point's one beam on) and then
scans only the cells of the box of half-width the hint's distance; without a usable hint it
searches ring by ring outwards until the ring's distance lower bound exceeds the best found. Both
are exact: the point of least squared distance (summed as scipy's cKDTree sums it, dx² + dy²)
strictly below ``max_distance``², as ``cKDTree.query(k=1, distance_upper_bound=...)``; exact ties
go to the lower reference index (cKDTree's choice depends on its traversal).

The moved points R(θ) p + t are numpy's bit for bit (its matmul goes through OpenBLAS, which fuses
a multiply-add: :func:`_fma`), and so are the normals and point-to-line errors, so the pairs are
the reference's whenever the pose is. Trimming keeps the ``keep`` smallest errors, as
``np.argpartition``; ties at the cut go to the lower point index (argpartition's choice depends
on its selection algorithm).

The solve's sums are not BLAS's, so its poses differ from numpy's by ~1e-13 (plicp repeats the
last solve in numpy for a bit-identical answer). The quartic's roots are the eigenvalues of its
companion matrix, as ``np.roots``; numba's ``eigvals`` only takes a real matrix whose eigenvalues
are real, so the companion is passed as complex (LAPACK zgeev instead of numpy's dgeev: the roots
agree to rounding, and the chosen candidate is Newton-polished on the reduced cost afterwards).
An ill-conditioned solve (:data:`ILL_CONDITIONED`) is left to numpy altogether.
"""

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

# Condition number (of A, and of the reduced cost's curvature in θ) above which a solve is left to
# numpy: its answer is then rounding noise amplified (a featureless corridor: cond(A) ~ 1e28), which
# only the very same arithmetic reproduces, and callers depend on how it behaves (it slides).
ILL_CONDITIONED = 1e6
MAX_CELLS_PER_POINT = 64  # grid cells per reference point at most (coarser cells beyond)


@intrinsic
def _fma(typingctx, a, b, c):
    """a · b + c rounded once (LLVM's fma): numpy's (N × 2) @ (2 × 2) goes through OpenBLAS, whose
    kernels fuse the second product and sum, so the moved points match it bit for bit."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.DoubleType(), [ir.DoubleType()] * 3)
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True, inline="always")
def _move(px, py, c, s, tx, ty):
    """R(θ) p + t as numpy's ``p @ rot(θ).T + t`` computes it."""
    return _fma(py, -s, px * c) + tx, _fma(py, c, px * s) + ty


@njit(cache=True)
def build_grid(points, cell):
    """Uniform grid of ``points`` (N × 2) with square cells of side ``cell`` [m] (grown while the
    grid would have more than MAX_CELLS_PER_POINT cells per point): (origin (2,), (cell,),
    (nx, ny), start (nx·ny + 1,) offsets into the sorted points, sorted points (N × 2), their
    indices (N,)). Within a cell the points keep their index order (a stable counting sort)."""
    finite = np.isfinite(points[:, 0]) & np.isfinite(points[:, 1])
    n = int(finite.sum())  # a non-finite point is never nearest (as in cKDTree): left out
    origin = np.zeros(2)
    size = np.zeros(2)
    if n > 0:
        xs, ys = points[finite, 0], points[finite, 1]
        origin[0], origin[1] = xs.min(), ys.min()
        size[0], size[1] = xs.max() - origin[0], ys.max() - origin[1]
    cell = max(cell, 1e-6)
    limit = MAX_CELLS_PER_POINT * n + 64
    while True:
        nx, ny = int(size[0] / cell) + 1, int(size[1] / cell) + 1
        if nx * ny <= limit:
            break
        cell *= 2.0
    inv = 1.0 / cell  # the queries map to cells by the same product (monotone: the box is exact)
    cid = np.full(points.shape[0], -1, np.int64)
    start = np.zeros(nx * ny + 1, np.int64)
    for k in range(points.shape[0]):
        if finite[k]:
            ix = min(int((points[k, 0] - origin[0]) * inv), nx - 1)
            iy = min(int((points[k, 1] - origin[1]) * inv), ny - 1)
            cid[k] = iy * nx + ix
            start[cid[k] + 1] += 1
    for c in range(nx * ny):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    sorted_pts = np.empty((n, 2))
    sorted_idx = np.empty(n, np.int64)
    for k in range(points.shape[0]):
        if cid[k] >= 0:
            slot = fill[cid[k]]
            fill[cid[k]] += 1
            sorted_pts[slot, 0], sorted_pts[slot, 1] = points[k, 0], points[k, 1]
            sorted_idx[slot] = k
    return origin, np.array([cell]), np.array([nx, ny]), start, sorted_pts, sorted_idx


@njit(cache=True)
def nearest(grid, qx, qy, bound2, hint=-1):
    """(index, squared distance) of the reference point nearest (qx, qy) with squared distance
    < bound2, lower index on ties; (−1, bound2) if there is none. ``hint``: a reference index
    likely near (it only speeds the search up; the answer does not depend on it)."""
    origin, cell, dims, start, pts, idx = grid
    ref = np.full((max(hint + 1, idx.max() + 1 if idx.shape[0] else 0), 2), np.nan)
    ref[idx] = pts
    j, d2, _ = _nearest(
        origin, cell[0], dims[0], dims[1], start, pts, idx, ref, qx, qy, bound2, hint
    )
    return j, d2


@njit(cache=True, inline="always")
def _scan(start, pts, idx, c, qx, qy, best, best_j, second):
    """Scan cell c: the best (d², index) so far, and ``second``: the least d² of the other
    points seen."""
    for q in range(start[c], start[c + 1]):
        dx, dy = qx - pts[q, 0], qy - pts[q, 1]
        d2 = dx * dx + dy * dy
        j = idx[q]
        if d2 < best or (d2 == best and best_j >= 0 and j < best_j):
            if best_j >= 0:
                second = min(second, best)
            best, best_j = d2, j
        elif j != best_j:
            second = min(second, d2)
    return best, best_j, second


@njit(cache=True, inline="always")
def _nearest(origin, cell, nx, ny, start, pts, idx, ref, qx, qy, bound2, hint):
    """(index, d², clearance): the nearest as :func:`nearest`, and a radius [m] within which
    no other reference point lies (what lets the next iteration skip the search, see pairs)."""
    # (the grid's arrays one by one: passing the tuple per query cost 5x the search)
    best, best_j, second = bound2, -1, np.inf
    if pts.shape[0] == 0 or not (qx == qx and qy == qy):
        return best_j, best, np.inf if pts.shape[0] == 0 else -1.0
    # outside the grid's box by at least the bound: nothing can be nearer
    gx = max(origin[0] - qx, 0.0, qx - (origin[0] + nx * cell))
    gy = max(origin[1] - qy, 0.0, qy - (origin[1] + ny * cell))
    if gx * gx + gy * gy >= bound2:
        return best_j, best, np.sqrt(gx * gx + gy * gy) - 1e-9
    if hint >= 0:
        dx, dy = qx - ref[hint, 0], qy - ref[hint, 1]
        d2 = dx * dx + dy * dy
        if d2 < best:
            best, best_j = d2, hint
    inv = 1.0 / cell
    if best_j >= 0 and best < cell * cell:
        # every point at least as near lies in the box of half-width √best (+1 nm for rounding);
        # 5 % of a cell more leaves a clearance beyond the nearest
        rad = np.sqrt(best) + 0.05 * cell + 1e-9
        x_lo = max(int(np.floor((qx - rad - origin[0]) * inv)), 0)
        x_hi = min(int(np.floor((qx + rad - origin[0]) * inv)), nx - 1)
        y_lo = max(int(np.floor((qy - rad - origin[1]) * inv)), 0)
        y_hi = min(int(np.floor((qy + rad - origin[1]) * inv)), ny - 1)
        for jy in range(y_lo, y_hi + 1):
            for jx in range(x_lo, x_hi + 1):
                best, best_j, second = _scan(
                    start, pts, idx, jy * nx + jx, qx, qy, best, best_j, second
                )
        # the points not scanned lie beyond the block's sides (none beyond the grid's edges)
        edge = np.inf
        if x_lo > 0:
            edge = min(edge, qx - (origin[0] + x_lo * cell))
        if x_hi < nx - 1:
            edge = min(edge, origin[0] + (x_hi + 1) * cell - qx)
        if y_lo > 0:
            edge = min(edge, qy - (origin[1] + y_lo * cell))
        if y_hi < ny - 1:
            edge = min(edge, origin[1] + (y_hi + 1) * cell - qy)
        return best_j, best, min(np.sqrt(second), edge - 1e-9)
    ix, iy = int(np.floor((qx - origin[0]) * inv)), int(np.floor((qy - origin[1]) * inv))
    r = 0
    edge = np.inf
    while True:
        # every cell of ring r is at least (r − 1) cells away (1 nm of slack for the rounding
        # of the cell assignment)
        lb = (r - 1) * cell - 1e-9
        if lb > 0.0 and lb * lb > best:
            edge = lb
            break
        if ix - r < 0 and ix + r >= nx and iy - r < 0 and iy + r >= ny:
            break
        for jy in range(max(iy - r, 0), min(iy + r, ny - 1) + 1):
            # the ring's top and bottom rows whole, its other rows at both ends only
            step = 1 if (jy == iy - r or jy == iy + r) else 2 * r
            for jx in range(ix - r, ix + r + 1, step):
                if 0 <= jx < nx:
                    best, best_j, second = _scan(
                        start, pts, idx, jy * nx + jx, qx, qy, best, best_j, second
                    )
        r += 1
    return best_j, best, min(np.sqrt(second), edge)


@njit(cache=True)
def pairs(
    grid, reference, current, active, c, s, tx, ty, max_distance, max_segment, trim, hint, memo
):
    """plicp's ``_trimmed_pairs`` of current[active] moved by (R(θ) = [[c, −s], [s, c]], t):
    (i (into current), j1, j2, normals (m × 2)), the ``keep`` least point-to-line errors in point
    order. ``hint`` (len(current),): each point's nearest reference point at the last search, or
    −1; ``memo`` (len(current) × 3): where that search was and its clearance (−1: none). Both
    updated; they speed the search up and do not change its answer."""
    n_ref, m = reference.shape[0], active.shape[0]
    i = np.empty(m, np.int64)
    j1 = np.empty(m, np.int64)
    j2 = np.empty(m, np.int64)
    nrm = np.empty((m, 2))
    err = np.empty(m)
    origin, cellv, dims, start, pts, idx = grid
    bound2 = max_distance * max_distance
    seg2_max = max_segment**2
    k, last = 0, -1
    for a in range(m):
        px, py = current[active[a], 0], current[active[a], 1]
        mx, my = _move(px, py, c, s, tx, ty)
        p = active[a]
        guess = hint[p]
        # Skip the search when the last one still decides it: no other point was within
        # ``clear`` of where the point was, it has moved δ since, so if the last nearest is
        # nearer than clear − δ (with 1 nm for rounding), it is still the strict nearest.
        ddx, ddy = mx - memo[p, 0], my - memo[p, 1]
        moved = np.sqrt(ddx * ddx + ddy * ddy)
        ja = -2
        if guess >= 0:
            ex, ey = mx - reference[guess, 0], my - reference[guess, 1]
            d2 = ex * ex + ey * ey
            if d2 < bound2 and np.sqrt(d2) + 2.0 * moved + 1e-9 < memo[p, 2]:
                ja = guess
        elif memo[p, 2] - moved - 1e-9 >= max_distance:
            ja = -1  # no point within the bound before, none now
        if ja == -2:
            if guess < 0 and last >= 0:
                guess = min(last + 1, n_ref - 1)  # the previous point's, one beam on
            ja, _, clear = _nearest(
                origin,
                cellv[0],
                dims[0],
                dims[1],
                start,
                pts,
                idx,
                reference,
                mx,
                my,
                bound2,
                guess,
            )
            hint[p] = ja
            memo[p, 0], memo[p, 1], memo[p, 2] = mx, my, clear
        last = ja
        if ja < 0:
            continue
        lo, hi = max(ja - 1, 0), min(ja + 1, n_ref - 1)
        ex, ey = reference[lo, 0] - mx, reference[lo, 1] - my
        d_lo = ex * ex + ey * ey
        ex, ey = reference[hi, 0] - mx, reference[hi, 1] - my
        d_hi = ex * ex + ey * ey
        # at the ends of the scan one neighbour is ja itself: never pick it
        if lo == ja:
            d_lo = np.inf
        if hi == ja:
            d_hi = np.inf
        jb = lo if d_lo <= d_hi else hi
        dx, dy = reference[jb, 0] - reference[ja, 0], reference[jb, 1] - reference[ja, 1]
        seg2 = dx * dx + dy * dy
        if jb == ja or not (seg2 <= seg2_max and seg2 > 0.0):
            continue
        n0, n1 = -dy, dx
        norm = np.sqrt(n0 * n0 + n1 * n1)
        n0, n1 = n0 / norm, n1 / norm
        i[k], j1[k], j2[k] = a, ja, jb
        nrm[k, 0], nrm[k, 1] = n0, n1
        err[k] = abs(n0 * (mx - reference[ja, 0]) + n1 * (my - reference[ja, 1]))
        k += 1
    keep = max(3, int(np.ceil(trim * k)))
    take = np.ones(k, np.bool_)
    if keep < k:
        kth = np.partition(err[:k], keep - 1)[keep - 1]
        below = 0
        for q in range(k):
            below += err[q] < kth
        ties = keep - below  # ties at the cut: the lowest point indices
        for q in range(k):
            if err[q] < kth:
                continue
            if err[q] == kth and ties > 0:
                ties -= 1
            else:
                take[q] = False
    out = take.sum()
    ri = np.empty(out, np.int64)
    r1 = np.empty(out, np.int64)
    r2 = np.empty(out, np.int64)
    rn = np.empty((out, 2))
    o = 0
    for q in range(k):
        if take[q]:
            ri[o], r1[o], r2[o] = active[i[q]], j1[q], j2[q]
            rn[o, 0], rn[o, 1] = nrm[q, 0], nrm[q, 1]
            o += 1
    return ri, r1, r2, rn


@njit(cache=True)
def _lu2(a00, a01, a10, a11):
    """LU with partial pivoting of [[a00, a01], [a10, a11]] as LAPACK getrf: (swapped, l, u00,
    u01, u11); u00 or u11 zero when singular."""
    swapped = abs(a10) > abs(a00)
    if swapped:
        a00, a01, a10, a11 = a10, a11, a00, a01
    if a00 == 0.0:
        return swapped, 0.0, 0.0, a01, 0.0
    l = a10 * (1.0 / a00)
    return swapped, l, a00, a01, a11 - l * a01


@njit(cache=True)
def _det2(s00, s01, s10, s11):
    """np.linalg.det of a 2 × 2: sign · exp(Σ log|u_ii|) of its LU factors, as numpy computes it."""
    swapped, _, u00, _, u11 = _lu2(s00, s01, s10, s11)
    if u00 == 0.0 or u11 == 0.0:
        return 0.0
    sign = -1.0 if swapped else 1.0
    if u00 < 0.0:
        sign = -sign
    if u11 < 0.0:
        sign = -sign
    return sign * np.exp(0.0 + np.log(abs(u00)) + np.log(abs(u11)))


@njit(cache=True)
def _roots(p):
    """np.roots of the coefficients ``p`` (leading one non-zero): trailing zeros give zero roots,
    the rest the eigenvalues of the companion matrix."""
    deg = p.shape[0] - 1
    last = deg
    while last > 0 and p[last] == 0.0:
        last -= 1
    out = np.zeros(deg, np.complex128)
    if last > 0:
        comp = np.zeros((last, last), np.complex128)
        for c in range(last):
            comp[0, c] = -p[c + 1] / p[0]
        for r in range(1, last):
            comp[r, r - 1] = 1.0
        out[:last] = np.linalg.eigvals(comp)
    return out


@njit(cache=True)
def solve(p, q, n, w):
    """solve_point_to_line (Censi 2008 §IV, Pham et al. eqs. 1-3) in the reference's arithmetic:
    (ok, t_x, t_y, θ). Not ok when the problem is ill-conditioned (:data:`ILL_CONDITIONED`; A
    singular included, where numpy raises LinAlgError) or the quartic is not finite: the caller
    then leaves the match to numpy."""
    # M = Σ w k kᵀ and Σ w k c with k = [n_x, n_y, n·p, n×p], c = n·q (symmetric: 10 sums)
    m00 = m01 = m02 = m03 = m11 = m12 = m13 = m22 = m23 = m33 = 0.0
    g0 = g1 = g2 = g3 = 0.0
    for r in range(p.shape[0]):
        n0, n1, p0, p1 = n[r, 0], n[r, 1], p[r, 0], p[r, 1]
        k2, k3 = n0 * p0 + n1 * p1, n1 * p0 - n0 * p1
        c = n0 * q[r, 0] + n1 * q[r, 1]
        w0, w1, w2, w3 = n0 * w[r], n1 * w[r], k2 * w[r], k3 * w[r]
        m00 += w0 * n0
        m01 += w0 * n1
        m02 += w0 * k2
        m03 += w0 * k3
        m11 += w1 * n1
        m12 += w1 * k2
        m13 += w1 * k3
        m22 += w2 * k2
        m23 += w2 * k3
        m33 += w3 * k3
        g0 += w0 * c
        g1 += w1 * c
        g2 += w2 * c
        g3 += w3 * c
    mm = np.array(
        [
            [m00, m01, m02, m03],
            [m01, m11, m12, m13],
            [m02, m12, m22, m23],
            [m03, m13, m23, m33],
        ]
    )
    g = np.array([g0, g1, g2, g3])
    m2 = 2.0 * mm
    g = -2.0 * g
    tr_a = m2[0, 0] + m2[1, 1]
    det_a = m2[0, 0] * m2[1, 1] - m2[0, 1] * m2[1, 0]
    if not (det_a > 0.0 and tr_a * tr_a < ILL_CONDITIONED * det_a):  # ≥ λmax / λmin
        return False, 0.0, 0.0, 0.0
    swapped, l, u00, u01, u11 = _lu2(m2[0, 0], m2[0, 1], m2[1, 0], m2[1, 1])
    # A⁻¹ = solve(A, I) through the LU factors (numpy's inv is LAPACK gesv)
    ai = np.empty((2, 2))
    for col in range(2):
        e0, e1 = (1.0 if col == 0 else 0.0), (1.0 if col == 1 else 0.0)
        if swapped:
            e0, e1 = e1, e0
        y1 = e1 - l * e0
        x1 = y1 * (1.0 / u11)
        ai[0, col], ai[1, col] = (e0 - u01 * x1) * (1.0 / u00), x1
    b = m2[:2, 2:]
    # S = D − (Bᵀ A⁻¹) B and h = g_r − (Bᵀ A⁻¹) g_t, in scalars (BLAS calls cost more here)
    bta = np.empty((2, 2))
    s = np.empty((2, 2))
    h = np.empty(2)
    for r in range(2):
        for c in range(2):
            bta[r, c] = b[0, r] * ai[0, c] + b[1, r] * ai[1, c]
    for r in range(2):
        for c in range(2):
            s[r, c] = m2[2 + r, 2 + c] - (bta[r, 0] * b[0, c] + bta[r, 1] * b[1, c])
        h[r] = g[2 + r] - (bta[r, 0] * g[0] + bta[r, 1] * g[1])
    det_s, tr_s = _det2(s[0, 0], s[0, 1], s[1, 0], s[1, 1]), s[0, 0] + s[1, 1]
    sah0 = s[1, 1] * h[0] + -s[0, 1] * h[1]
    sah1 = -s[1, 0] * h[0] + s[0, 0] * h[1]
    coeffs = np.array(
        [
            16.0,
            16.0 * tr_s,
            8.0 * det_s + 4.0 * tr_s**2 - (4.0 * h[0] * h[0] + 4.0 * h[1] * h[1]),
            4.0 * det_s * tr_s - (4.0 * h[0] * sah0 + 4.0 * h[1] * sah1),
            det_s**2 - (sah0 * sah0 + sah1 * sah1),
        ]
    )
    if not np.all(np.isfinite(coeffs)):
        return False, 0.0, 0.0, 0.0
    roots = _roots(coeffs)
    scale = max(1.0, np.abs(roots).max())
    n_lam = 0
    lam = np.empty(4)
    for r in range(4):
        if abs(roots[r].imag) <= 1e-6 * scale:
            lam[n_lam] = roots[r].real
            n_lam += 1
    if n_lam == 0:  # cannot happen in exact arithmetic (the minimum has a real λ)
        for r in range(4):
            lam[r] = roots[r].real
        n_lam = 4
    # each candidate λ's direction θ; the least reduced cost ½ uᵀ S u + hᵀ u wins
    best, best_cost, found = 0.0, np.inf, False
    for r in range(n_lam):
        den = lam[r] ** 2 * 4.0 + 2.0 * tr_s * lam[r] + det_s
        x0 = -(sah0 + 2.0 * lam[r] * h[0]) / den
        x1 = -(sah1 + 2.0 * lam[r] * h[1]) / den
        if not (np.isfinite(x0) and np.isfinite(x1) and (x0 != 0.0 or x1 != 0.0)):
            continue
        phi = np.arctan2(x1, x0)
        u0, u1 = np.cos(phi), np.sin(phi)
        cost = 0.5 * (u0 * (s[0, 0] * u0 + s[0, 1] * u1) + u1 * (s[1, 0] * u0 + s[1, 1] * u1))
        cost += h[0] * u0 + h[1] * u1
        if not found or cost < best_cost:
            best, best_cost, found = phi, cost, True
    s00, s01, s11, h0, h1 = s[0, 0], 0.5 * (s[0, 1] + s[1, 0]), s[1, 1], h[0], h[1]
    for _ in range(8):
        c, sn = np.cos(best), np.sin(best)
        # f'(φ) and f''(φ) of f = ½ uᵀ S u + hᵀ u, u = (c, sn), u' = (−sn, c)
        f1 = (s11 - s00) * c * sn + s01 * (c * c - sn * sn) - h0 * sn + h1 * c
        f2 = (s11 - s00) * (c * c - sn * sn) - 4.0 * s01 * c * sn - h0 * c - h1 * sn
        if not f2 > 0.0:
            break
        best -= f1 / f2
        if abs(f1) <= 1e-15 * f2:
            break
    c, sn = np.cos(best), np.sin(best)
    f2 = (s11 - s00) * (c * c - sn * sn) - 4.0 * s01 * c * sn - h0 * c - h1 * sn
    if not f2 * ILL_CONDITIONED > abs(s00) + abs(s11) + 2.0 * abs(s01) + abs(h0) + abs(h1):
        return False, 0.0, 0.0, 0.0  # θ barely determined (a circular room about the sensor)
    xr0, xr1 = c, sn
    v0 = g[0] + (b[0, 0] * xr0 + b[0, 1] * xr1)
    v1 = g[1] + (b[1, 0] * xr0 + b[1, 1] * xr1)
    tx = -ai[0, 0] * v0 + -ai[0, 1] * v1
    ty = -ai[1, 0] * v0 + -ai[1, 1] * v1
    return True, tx, ty, np.arctan2(xr1, xr0)


@njit(cache=True)
def run(reference, current, cell, pose, params, max_iterations, coarse_stride):
    """plicp's iteration loop from ``pose`` = (t_x, t_y, θ) (rotation search already applied),
    the reference indexed by a grid of ``cell`` [m]. ``params`` = (max_distance, max_segment,
    trim, tolerance_t, tolerance_theta, coarse_tolerance). Returns ((t_x, t_y, θ), iterations,
    converged, (i, j1, j2) of the last solve's pairs, whether a solve was left to numpy (then the
    caller runs plicp_reference instead)). One call: numba's dispatch of several is not free."""
    max_distance, max_segment, trim, tol_t, tol_th, coarse_tol = params
    tx, ty, theta = pose[0], pose[1], pose[2]
    grid = build_grid(reference, cell)
    n_cur = current.shape[0]
    active = np.arange(0, n_cur, max(1, coarse_stride))
    fine = active.shape[0] == n_cur
    all_points = np.arange(n_cur)
    prev_i = np.empty(0, np.int64)
    prev_j1 = np.empty(0, np.int64)
    prev_j2 = np.empty(0, np.int64)
    have_prev = False
    sel_i, sel_j1, sel_j2 = prev_i, prev_j1, prev_j2
    converged, iterations, fallback = False, 0, False
    hint = np.full(n_cur, -1, np.int64)
    memo = np.full((n_cur, 3), -1.0)
    for _ in range(max_iterations):
        c, s = np.cos(theta), np.sin(theta)
        i, j1, j2, nrm = pairs(
            grid,
            reference,
            current,
            active,
            c,
            s,
            tx,
            ty,
            max_distance,
            max_segment,
            trim,
            hint,
            memo,
        )
        if i.shape[0] < 3:
            break
        if (
            have_prev
            and i.shape[0] == prev_i.shape[0]
            and np.array_equal(i, prev_i)
            and np.array_equal(j1, prev_j1)
            and np.array_equal(j2, prev_j2)
        ):
            if fine:
                converged = True
                break
            active, fine, have_prev = all_points, True, False
            continue
        prev_i, prev_j1, prev_j2, have_prev = i, j1, j2, True
        p = np.empty((i.shape[0], 2))
        q = np.empty((i.shape[0], 2))
        for r in range(i.shape[0]):
            p[r, 0], p[r, 1] = current[i[r], 0], current[i[r], 1]
            q[r, 0], q[r, 1] = reference[j1[r], 0], reference[j1[r], 1]
        ok, tx_new, ty_new, theta_new = solve(p, q, nrm, np.ones(i.shape[0]))
        if not ok:
            fallback = True
            break
        iterations += 1
        step_t = np.sqrt((tx_new - tx) ** 2 + (ty_new - ty) ** 2)
        step_theta = abs(np.mod(theta_new - theta + np.pi, 2 * np.pi) - np.pi)
        tx, ty, theta = tx_new, ty_new, theta_new
        sel_i, sel_j1, sel_j2 = i, j1, j2
        if not fine:
            if step_t < coarse_tol and step_theta < coarse_tol:
                active, fine, have_prev = all_points, True, False
        elif step_t < tol_t and step_theta < tol_th:
            converged = True
            break
    return np.array([tx, ty, theta]), iterations, converged, sel_i, sel_j1, sel_j2, fallback


@njit(cache=True)
def held(reference, current, cell, pose, max_distance, max_segment, trim):
    """plicp_at: the trimmed pairs (i, j1, j2) of all current points held at ``pose``."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    active = np.arange(current.shape[0])
    hint = np.full(current.shape[0], -1, np.int64)
    memo = np.full((current.shape[0], 3), -1.0)
    grid = build_grid(reference, cell)
    tx, ty = pose[0], pose[1]
    i, j1, j2, _ = pairs(
        grid, reference, current, active, c, s, tx, ty, max_distance, max_segment, trim, hint, memo
    )
    return i, j1, j2
