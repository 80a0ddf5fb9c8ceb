"""Weighted multi-goal A* with long connections: the path planner of Ueland 2017 §Path Planner.

The exploration planner of Ueland 2017 ("Marine autonomous exploration using a lidar and SLAM") is
A* (Hart, Nilsson & Raphael 1968) on an occupancy grid with one node per cell centre, extended in
three ways (Ueland 2017 §Path Planner):

1. **Connection distance** d ∈ {1, 2, 3, 4} (Ueland 2017 Fig. 7): a node connects to the nodes up to
d
   cells away in either direction, one edge per heading, i.e. the offsets (Δr, Δc) with
   max(|Δr|, |Δc|) ≤ d and gcd(|Δr|, |Δc|) = 1 (:func:`connection_offsets`): 8, 16, 32 and
   48 headings. Longer connections give shorter, smoother paths (Ueland 2017 Fig. 8).
2. **Multiple goals** (the frontier cells of the exploration): the heuristic is the distance to
   the *nearest* goal, so the first goal taken off the open list is the cheapest to reach and
   the path is retraced from it.
3. **Cost weighting**: every cell has a weight w(s) ≥ 1, in Ueland 2017 eq. (1)
   w = 1 + 5 / (0.1 + d_obj) with d_obj the distance to the nearest obstacle; the weights are
   the caller's (this module takes them as an array), so the vessel keeps off obstacles.

Edge model (:func:`edge_table`). An edge is the straight segment between two cell centres. It
*crosses* the cells whose interior it meets, each for a length ℓ (the two end cells each for
L / (2 max(|Δr|, |Δc|)), from the centre to the cell's edge; the lengths sum to the segment
length L), and costs the line integral of the weight along it,

    c(n → m) = Σ_{crossed cells s} w(s) ℓ(s)      [cells; the caller multiplies by resolution],

so a unit orthogonal step costs ½(w_a + w_b), and the cost of a path does not depend on how it
is cut into edges: a d = 4 path is genuinely cheaper than the d = 1 staircase, not an artefact
of a different metric. An edge crossing a non-traversable cell is rejected. Where the segment
passes exactly through a grid corner (both |Δr| and |Δc| odd: the corner at its midpoint) it
meets the two cells beside that corner only at a point, so they are not crossed; the edge is
then rejected only when *both* are blocked (no squeezing between two obstacles touching at a
corner), which is the usual 8-connected diagonal rule for d = 1.

Heuristic: h(n) = w_min · D(n), with D the Euclidean distance [cells] from n's centre to the
nearest goal centre (one ``scipy.ndimage.distance_transform_edt`` over the grid; for a single
goal its closed form) and w_min the least weight of a traversable cell. D is 1-Lipschitz and
every edge costs at least w_min times its length, so h(n) ≤ c(n → m) + h(m): h is consistent
(hence admissible), each node is expanded at most once and never reopened, and the first goal
expanded is the cheapest one.

The search runs in a numba kernel (compiled on the first call, ~1-2 s, cached on disk): flat
indices into a grid padded with d blocked cells (no bound checks), an indexed binary heap with
decrease-key, per-offset crossed-cell lists as flat arrays. Open nodes are ordered by f on a
grid of 2⁻³² cell (``TIE_QUANTUM``), ties towards the smaller h: sums of the same weights in a
different order differ by rounding noise, which would otherwise decide between equal-f nodes,
and A* would expand every equally cheap cell of an open area instead of following one.
"""

from dataclasses import dataclass
from fractions import Fraction
from functools import lru_cache
from math import gcd

import numpy as np
from numba import njit
from scipy import ndimage

TIE_QUANTUM = float(2**32)  # [1/cell]: open nodes are ordered on f to 2⁻³² cell, then on h
MAX_CONNECTION_DISTANCE = 4


def _check_distance(distance) -> int:
    ok = isinstance(distance, int | np.integer) and not isinstance(distance, bool)
    if not ok or not 1 <= distance <= MAX_CONNECTION_DISTANCE:
        raise ValueError(
            f"connection distance must be 1, 2, 3 or 4 (Ueland 2017 Fig. 7), got {distance!r}"
        )
    return int(distance)


def connection_offsets(distance: int) -> np.ndarray:
    """The (Δr, Δc) neighbour offsets (K, 2) of connection distance ``distance`` ∈ {1..4}:
    max(|Δr|, |Δc|) ≤ d and gcd(|Δr|, |Δc|) = 1, one per heading; K = 8, 16, 32, 48
    (Ueland 2017 Fig. 7). Sorted by heading angle atan2(Δr, Δc), from −π."""
    d = _check_distance(distance)
    out = [
        (dr, dc)
        for dr in range(-d, d + 1)
        for dc in range(-d, d + 1)
        if (dr, dc) != (0, 0) and gcd(abs(dr), abs(dc)) == 1
    ]
    out.sort(key=lambda o: np.arctan2(o[0], o[1]))
    return np.array(out, dtype=np.int64)


def _crossing(dr: int, dc: int):
    """Crossed cells of the segment (0, 0) → (dr, dc) between cell centres, in order, with the
    fraction of the segment inside each, and the cell pair beside a corner passage (or None).
    Exact: the parameters where the segment meets the grid lines are rationals."""
    ts = {Fraction(0), Fraction(1)}
    row_t = {Fraction(2 * k + 1, 2 * abs(dr)) for k in range(abs(dr))}
    col_t = {Fraction(2 * k + 1, 2 * abs(dc)) for k in range(abs(dc))}
    ts |= row_t | col_t
    ts = sorted(ts)
    cells, fractions = [], []
    for t0, t1 in zip(ts[:-1], ts[1:], strict=True):
        mid = (t0 + t1) / 2  # never on a grid line: rounding is exact
        cells.append((round(mid * dr), round(mid * dc)))
        fractions.append(t1 - t0)
    corners = sorted(row_t & col_t)  # the segment passes through a grid corner
    beside = None
    if corners:
        assert len(corners) == 1 and corners[0] == Fraction(1, 2), (dr, dc, corners)
        # the cells before and after the corner are crossed; the other two only touch it
        sr, sc = int(np.sign(dr)), int(np.sign(dc))
        r0, c0 = (dr - sr) // 2, (dc - sc) // 2  # the cell before the corner
        beside = ((r0 + sr, c0), (r0, c0 + sc))
    return cells, fractions, beside


@dataclass(frozen=True)
class EdgeTable:
    """The edges of a connection distance, per offset k (rows of ``offsets``): the cells the
    segment between the two centres crosses, relative to the start cell and in order from the
    start cell (first) to the end cell (last), ``cells[ptr[k]:ptr[k + 1]]``, with the length
    [cells] of the segment inside each, ``cell_length[ptr[k]:ptr[k + 1]]`` (summing to
    ``length[k]``). ``has_corner[k]``: the segment passes through the grid corner shared by
    the two cells ``corner[k]``, which it does not cross; the edge is blocked only when both
    are blocked."""

    distance: int
    offsets: np.ndarray  # (K, 2) int (Δr, Δc)
    length: np.ndarray  # (K,) [cells] segment length
    ptr: np.ndarray  # (K + 1,) int
    cells: np.ndarray  # (M, 2) int (Δr, Δc) of the crossed cells
    cell_length: np.ndarray  # (M,) [cells]
    has_corner: np.ndarray  # (K,) bool
    corner: np.ndarray  # (K, 2, 2) int (Δr, Δc) of the two cells beside the corner (or 0)

    def crossed(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(cells (n, 2), lengths (n,)) crossed by the edge of offset k."""
        s = slice(self.ptr[k], self.ptr[k + 1])
        return self.cells[s], self.cell_length[s]

    def edge_cost(self, weights: np.ndarray, cell, k: int) -> float:
        """Cost [cells] of the edge of offset k from ``cell`` (row, col): Σ w(s) ℓ(s) over
        the crossed cells, traversability not checked."""
        cells, lengths = self.crossed(k)
        rc = np.asarray(cell, int) + cells
        return float(np.dot(weights[rc[:, 0], rc[:, 1]], lengths))

    def edge_free(self, traversable: np.ndarray, cell, k: int) -> bool:
        """Whether the edge of offset k from ``cell`` stays in the grid, crosses only
        traversable cells and does not squeeze between two blocked cells at a corner."""
        rows, cols = traversable.shape
        rc = np.asarray(cell, int) + self.crossed(k)[0]
        if np.any((rc < 0) | (rc >= (rows, cols))):
            return False
        if not np.all(traversable[rc[:, 0], rc[:, 1]]):
            return False
        if self.has_corner[k]:
            a, b = np.asarray(cell, int) + self.corner[k]
            inside = [0 <= p[0] < rows and 0 <= p[1] < cols for p in (a, b)]
            free = [ok and traversable[p[0], p[1]] for ok, p in zip(inside, (a, b), strict=True)]
            return any(free)
        return True


def edge_table(distance: int) -> EdgeTable:
    """The :class:`EdgeTable` of connection distance ``distance`` ∈ {1..4} (cached; arrays are
    read-only). ValueError for another distance."""
    return _edge_table(_check_distance(distance))


@lru_cache(maxsize=MAX_CONNECTION_DISTANCE)
def _edge_table(distance: int) -> EdgeTable:
    offsets = connection_offsets(distance)
    ptr, cells, cell_length, length = [0], [], [], []
    has_corner = np.zeros(len(offsets), bool)
    corner = np.zeros((len(offsets), 2, 2), np.int64)
    for k, (dr, dc) in enumerate(offsets.tolist()):
        c, f, beside = _crossing(dr, dc)
        seg = float(np.hypot(dr, dc))
        cells += c
        cell_length += [float(x) * seg for x in f]
        ptr.append(len(cells))
        length.append(seg)
        if beside is not None:
            has_corner[k] = True
            corner[k] = beside
    table = EdgeTable(
        distance=int(distance),
        offsets=offsets,
        length=np.array(length),
        ptr=np.array(ptr, np.int64),
        cells=np.array(cells, np.int64),
        cell_length=np.array(cell_length),
        has_corner=has_corner,
        corner=corner,
    )
    for a in (table.offsets, table.length, table.ptr, table.cells, table.cell_length):
        a.flags.writeable = False
    table.has_corner.flags.writeable = False
    table.corner.flags.writeable = False
    return table


@dataclass(frozen=True)
class AStarResult:
    """A planned path: ``cells`` (N, 2) int (row, col) from the start to the goal inclusive,
    its ``cost`` [cells] (Σ of edge costs; × resolution for metres), ``goal_index`` the index
    of the goal reached in the ``goals`` given, ``expanded`` the number of nodes expanded."""

    cells: np.ndarray
    cost: float
    goal_index: int
    expanded: int


# --- numba kernel --------------------------------------------------------------------------


# The open list: a binary min-heap on (key, h), stored by position in three parallel arrays
# (the comparisons read contiguous memory, not the grid), with pos[node] its position or −1
# (decrease-key, so a node is in the heap at most once).


@njit(cache=True, inline="always")
def _put(hkey, hh, hnode, pos, i, key, h, node):
    """Store (key, h, node) at heap position i."""
    hkey[i] = key
    hh[i] = h
    hnode[i] = node
    pos[node] = i


@njit(cache=True, inline="always")
def _sift_up(hkey, hh, hnode, pos, i, key, h, node):
    """Place (key, h, node) at position i or above."""
    while i > 0:
        up = (i - 1) >> 1
        ku = hkey[up]
        if ku < key or (ku == key and hh[up] <= h):
            break
        _put(hkey, hh, hnode, pos, i, ku, hh[up], hnode[up])
        i = up
    _put(hkey, hh, hnode, pos, i, key, h, node)


@njit(cache=True, inline="always")
def _sift_down(hkey, hh, hnode, pos, size, key, h, node):
    """Place (key, h, node) at the root or below, in a heap of ``size`` entries."""
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        right = child + 1
        if right < size and (
            hkey[right] < hkey[child] or (hkey[right] == hkey[child] and hh[right] < hh[child])
        ):
            child = right
        kc = hkey[child]
        if key < kc or (key == kc and h <= hh[child]):
            break
        _put(hkey, hh, hnode, pos, i, kc, hh[child], hnode[child])
        i = child
    _put(hkey, hh, hnode, pos, i, key, h, node)


@njit(cache=True)
def _astar_kernel(
    blocked,  # (n,) uint8, padded flat grid
    weights,  # (n,) float64, 0 on blocked cells
    hval,  # (n,) float64 heuristic
    is_goal,  # (n,) uint8
    start,  # flat index
    nbr,  # (K,) int64 flat offset of the end cell
    end_len,  # (K,) length inside each end cell
    mid_lb,  # (K,) w_min × length inside the interior cells (lower bound of their cost)
    ptr,  # (K + 1,) interior crossed cells of offset k: mid_off[ptr[k]:ptr[k + 1]]
    mid_off,  # (M,) int64 flat offsets
    mid_len,  # (M,) lengths
    has_corner,  # (K,) uint8
    corner_a,  # (K,) int64 flat offsets of the two cells beside a corner passage
    corner_b,
    quantum,
):
    n = blocked.shape[0]
    n_nbr = nbr.shape[0]
    g = np.full(n, np.inf)
    parent = np.full(n, -1, np.int32)
    closed = np.zeros(n, np.uint8)
    pos = np.full(n, -1, np.int32)
    hkey = np.empty(n)
    hh = np.empty(n)
    hnode = np.empty(n, np.int32)

    g[start] = 0.0
    hkey[0] = np.floor(hval[start] * quantum)
    hh[0] = hval[start]
    hnode[0] = start
    pos[start] = 0
    size = 1
    expanded = 0
    while size > 0:
        cur = np.int64(hnode[0])
        pos[cur] = -1
        size -= 1
        if size > 0:
            _sift_down(hkey, hh, hnode, pos, size, hkey[size], hh[size], hnode[size])
        if is_goal[cur]:
            return cur, expanded, g[cur], parent
        closed[cur] = 1
        expanded += 1
        gc = g[cur]
        wc = weights[cur]
        for k in range(n_nbr):
            m = cur + nbr[k]
            if blocked[m] or closed[m]:
                continue
            ends = end_len[k] * (wc + weights[m])
            gm_old = g[m]
            if gc + ends + mid_lb[k] >= gm_old:
                continue  # cannot improve even over cells of the least weight
            if has_corner[k] and blocked[cur + corner_a[k]] and blocked[cur + corner_b[k]]:
                continue
            cost = ends
            ok = True
            for j in range(ptr[k], ptr[k + 1]):
                s = cur + mid_off[j]
                if blocked[s]:
                    ok = False
                    break
                cost += weights[s] * mid_len[j]
            if not ok:
                continue
            gm = gc + cost
            if gm < gm_old:
                g[m] = gm
                parent[m] = cur
                hm = hval[m]
                i = pos[m]
                if i < 0:
                    i = size
                    size += 1
                _sift_up(hkey, hh, hnode, pos, i, np.floor((gm + hm) * quantum), hm, m)
    return -1, expanded, np.inf, parent


@lru_cache(maxsize=64)
def _kernel_tables(distance: int, width: int):
    """The edge table of ``distance`` as flat offsets in a padded grid ``width`` cells wide."""
    t = _edge_table(distance)
    k_count = len(t.offsets)
    flat = t.cells[:, 0] * width + t.cells[:, 1]
    mid = np.ones(len(t.cells), bool)
    mid[t.ptr[:-1]] = False  # first (start) and last (end) cell of each edge
    mid[t.ptr[1:] - 1] = False
    counts = np.diff(t.ptr) - 2
    ptr = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    end_len = t.cell_length[t.ptr[1:] - 1].copy()
    mid_len = t.cell_length[mid].copy()
    mid_sum = np.array([mid_len[ptr[k] : ptr[k + 1]].sum() for k in range(k_count)])
    return (
        (t.offsets[:, 0] * width + t.offsets[:, 1]).astype(np.int64),
        end_len,
        mid_sum,
        ptr,
        flat[mid].astype(np.int64),
        mid_len,
        t.has_corner.astype(np.uint8),
        (t.corner[:, 0, 0] * width + t.corner[:, 0, 1]).astype(np.int64),
        (t.corner[:, 1, 0] * width + t.corner[:, 1, 1]).astype(np.int64),
    )


def _padded(a: np.ndarray, p: int, fill, dtype) -> np.ndarray:
    """``a`` inside a border of ``p`` cells of ``fill``, flattened."""
    rows, cols = a.shape
    out = np.full((rows + 2 * p, cols + 2 * p), fill, dtype)
    out[p : p + rows, p : p + cols] = a
    return out.ravel()


def weighted_astar(
    traversable: np.ndarray,
    weights: np.ndarray,
    start,
    goals,
    connection_distance: int = 4,
) -> AStarResult | None:
    """Cheapest path from ``start`` to the cheapest of ``goals`` (Ueland 2017 §Path Planner, eq.
    (1)).

    ``traversable``: bool (rows, cols), True where the vessel may be (an inflated map).
    ``weights``: float (rows, cols), w(s) ≥ 1 on every traversable cell (Ueland 2017 eq. (1); other
    cells are not read). ``start``: (row, col). ``goals``: (K, 2) int (row, col), or one
    (row, col); goals on non-traversable cells are ignored. ``connection_distance`` ∈ {1..4}:
    8, 16, 32 or 48 headings (:func:`connection_offsets`).

    Edge cost: the line integral of w along the segment between cell centres [cells]
    (:func:`edge_table`); an edge crossing a non-traversable cell, or squeezing between two
    blocked cells touching at a corner, is not allowed. Heuristic: w_min × the Euclidean
    distance to the nearest goal (w_min the least traversable weight), consistent, so the
    first goal expanded is the cheapest and no node is reopened; optimal to within the
    ordering quantum 2⁻³² cell per step (``TIE_QUANTUM``).

    Returns an :class:`AStarResult`, or ``None`` if no goal is traversable and reachable
    (also for an empty ``goals``). ValueError for a start outside the grid or not
    traversable, a goal outside the grid (a caller's bug, unlike a blocked goal),
    weights < 1 (or NaN) on a traversable cell, mismatched shapes, or a bad distance.
    """
    trav = np.asarray(traversable, dtype=bool)
    if trav.ndim != 2:
        raise ValueError(f"weighted_astar: traversable must be 2-D, got shape {trav.shape}")
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != trav.shape:
        raise ValueError(
            f"weighted_astar: weights shape {w.shape} differs from traversable {trav.shape}"
        )
    p = _check_distance(connection_distance)  # the padding: the longest step
    rows, cols = trav.shape
    sr, sc = (int(v) for v in np.asarray(start).reshape(2))
    if not (0 <= sr < rows and 0 <= sc < cols):
        raise ValueError(f"weighted_astar: start {(sr, sc)} is outside the {rows}×{cols} grid")
    if not trav[sr, sc]:
        raise ValueError(f"weighted_astar: start {(sr, sc)} is not traversable")
    w_min = float(np.min(w, where=trav, initial=np.inf))
    if not w_min >= 1.0:  # NaN too: min propagates it
        bad = np.argwhere(trav & ~(w >= 1.0))[0]
        raise ValueError(
            f"weighted_astar: weights must be ≥ 1 on traversable cells, got "
            f"{w[bad[0], bad[1]]} at {tuple(int(v) for v in bad)}"
        )
    g_arr = np.asarray(goals)
    if g_arr.size == 0:
        return None
    g_arr = g_arr.reshape(-1, 2)
    if not np.issubdtype(g_arr.dtype, np.integer):
        raise ValueError(f"weighted_astar: goals must be integer cells, got {g_arr.dtype}")
    g_arr = g_arr.astype(np.int64)
    outside = (g_arr[:, 0] < 0) | (g_arr[:, 0] >= rows) | (g_arr[:, 1] < 0) | (g_arr[:, 1] >= cols)
    if outside.any():
        bad = tuple(int(v) for v in g_arr[np.argmax(outside)])
        raise ValueError(f"weighted_astar: goal {bad} is outside the {rows}×{cols} grid")
    valid = trav[g_arr[:, 0], g_arr[:, 1]]
    if not valid.any():
        return None
    goal_mask = np.zeros((rows, cols), bool)
    goal_mask[g_arr[valid, 0], g_arr[valid, 1]] = True

    def goal_index(r: int, c: int) -> int:
        return int(np.flatnonzero(valid & (g_arr[:, 0] == r) & (g_arr[:, 1] == c))[0])

    if goal_mask[sr, sc]:
        return AStarResult(np.array([[sr, sc]], np.int64), 0.0, goal_index(sr, sc), 0)

    # h = w_min × distance [cells] to the nearest goal: closed form for one goal, else an EDT.
    width = cols + 2 * p
    hpad = np.zeros((rows + 2 * p, width))
    h = hpad[p : p + rows, p : p + cols]
    goal_cells = np.unique(g_arr[valid], axis=0)
    if len(goal_cells) == 1:
        gr, gc = goal_cells[0]
        dr2 = (w_min * (np.arange(rows) - gr)) ** 2
        dc2 = (w_min * (np.arange(cols) - gc)) ** 2
        np.sqrt(np.add(dr2[:, None], dc2[None, :], out=h), out=h)
    else:
        np.multiply(ndimage.distance_transform_edt(~goal_mask), w_min, out=h)
    hpad = hpad.ravel()

    blocked = _padded(~trav, p, 1, np.uint8)
    wpad = _padded(w, p, 0.0, np.float64)  # the kernel reads no blocked cell's weight
    gpad = _padded(goal_mask, p, 0, np.uint8)
    nbr, end_len, mid_sum, ptr, mid_off, mid_len, has_corner, ca, cb = _kernel_tables(p, width)
    s_flat = (sr + p) * width + sc + p
    reached, expanded, cost, parent = _astar_kernel(
        blocked,
        wpad,
        hpad,
        gpad,
        s_flat,
        nbr,
        end_len,
        w_min * mid_sum,
        ptr,
        mid_off,
        mid_len,
        has_corner,
        ca,
        cb,
        TIE_QUANTUM,
    )
    if reached < 0:
        return None
    path = [reached]
    while path[-1] != s_flat:
        path.append(int(parent[path[-1]]))
    flat = np.array(path[::-1], np.int64)
    cells = np.column_stack([flat // width - p, flat % width - p])
    return AStarResult(cells, float(cost), goal_index(*cells[-1]), int(expanded))


def path_length(cells: np.ndarray) -> float:
    """Euclidean length [cells] of the polyline through the cell centres."""
    c = np.asarray(cells, float).reshape(-1, 2)
    return float(np.hypot(*np.diff(c, axis=0).T).sum())
