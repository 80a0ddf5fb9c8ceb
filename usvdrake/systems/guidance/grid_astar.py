"""Grid A* on a world's occupancy: the "simple A* planner" of Roboat II (§III, §VI-B).

Roboat II plans its reference paths with a simple A* planner and tracks them with the NMPC
(Roboat II §III); goals are given one after another (Roboat II §VI-B). This module is that planner:

1. :class:`PlanningGrid` takes the ground-truth occupancy (:meth:`World.occupancy`) and its
   Euclidean distance transform (``scipy.ndimage``), giving every cell's clearance [m] to the
   nearest obstacle; cells with less clearance than ``inflation`` (hull radius + margin) are
   blocked, so the vessel can be planned for as a point.
2. :func:`grid_astar` is A* (Hart, Nilsson & Raphael 1968) on the 8-connected grid with step
   costs 1 and √2 [cells] and the octile distance
       h(n) = max(|Δr|, |Δc|) + (√2 − 1) min(|Δr|, |Δc|),
   the exact cost in an empty grid, hence admissible and consistent: the first expansion of the
   goal is optimal (to the f-ordering quantum ``TIE_QUANTUM``) and no node is expanded twice.
3. :meth:`PlanningGrid.plan` converts the cell path to world points and shortcuts it by line of
   sight on the clearance map, so the result is a few straight legs instead of a staircase.

Unreachable goals: :func:`grid_astar` returns ``None`` (a search that finds nothing is a normal
outcome); :meth:`PlanningGrid.plan` and :func:`plan_path` raise :class:`NoPathError`, since
their callers need a path. A start or goal outside the grid or on an occupied cell is a
``ValueError``; :meth:`PlanningGrid.plan` first moves one that is in free water but inside the
inflation (a vessel moored at a quay) to the nearest clear cell within ``max_snap``.
"""

import heapq
import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from usvdrake.worlds.world import OccupancyGrid, World

SQRT2 = math.sqrt(2.0)
# f is ordered on a grid of 2⁻²⁴ cell: sums of 1 and √2 in different orders differ by rounding
# noise (~1e-13), which would otherwise decide between equal-f nodes instead of the h
# tie-break, and A* would expand every cell of the parallelogram of equally short paths.
TIE_QUANTUM = float(2**24)  # [1/cell]
# Roboat II (Table I, 2.0 m × 1.0 m): circumscribed radius √(1.0² + 0.5²) = 1.12 m, plus
# 0.5 m margin for tracking error (Roboat II §VI-B reports 0.096 m position RMSE) and quay fenders.
DEFAULT_INFLATION = 1.6  # [m]


class NoPathError(RuntimeError):
    """No collision-free path joins the start to the goal on the inflated grid."""


def octile_distance(a: tuple[int, int], b: tuple[int, int]) -> float:
    """Octile distance [cells] between two cells: the A* heuristic of :func:`grid_astar`."""
    dr, dc = abs(a[0] - b[0]), abs(a[1] - b[1])
    return max(dr, dc) + (SQRT2 - 1.0) * min(dr, dc)


def _check_cell(occupied: np.ndarray, cell, what: str) -> tuple[int, int]:
    r, c = (int(v) for v in cell)
    rows, cols = occupied.shape
    if not (0 <= r < rows and 0 <= c < cols):
        raise ValueError(f"grid_astar: {what} cell {(r, c)} is outside the {rows}×{cols} grid")
    if occupied[r, c]:
        raise ValueError(f"grid_astar: {what} cell {(r, c)} is occupied")
    return r, c


def grid_astar(
    occupied: np.ndarray, start_cell: tuple[int, int], goal_cell: tuple[int, int]
) -> list[tuple[int, int]] | None:
    """Shortest 8-connected path of (row, col) cells from ``start_cell`` to ``goal_cell``.

    ``occupied``: bool (rows = y, cols = x), True where the vessel may not be. Orthogonal steps
    cost 1, diagonal steps √2 [cells]. A diagonal step is refused when *both* cells beside it
    are occupied (no squeezing through the corner where two obstacles touch); a diagonal past
    a single occupied cell is allowed. A* of Hart, Nilsson & Raphael (1968) with the octile
    heuristic (see the module docstring) and a binary heap. Ties in f (to 2⁻²⁴ cell,
    ``TIE_QUANTUM``) are broken towards the smaller heuristic, so of many equally short paths
    one is followed depth-first instead of all being expanded; the path is optimal to within
    that quantum per step.

    Returns the cells from start to goal inclusive, or ``None`` if the goal is unreachable.
    Raises ``ValueError`` if the grid is not 2-D or a cell is outside it or occupied.
    """
    occ = np.asarray(occupied, dtype=bool)
    if occ.ndim != 2:
        raise ValueError(f"grid_astar: occupied must be a 2-D array, got shape {occ.shape}")
    start = _check_cell(occ, start_cell, "start")
    goal = _check_cell(occ, goal_cell, "goal")
    if start == goal:
        return [start]

    # A one-cell occupied border removes every bounds check from the inner loop; cells are
    # flat indices into the padded grid, and Python lists/bytes beat numpy scalars here.
    rows, cols = occ.shape
    width = cols + 2
    blocked = np.pad(occ, 1, constant_values=True).tobytes()
    n_cells = len(blocked)
    s = (start[0] + 1) * width + start[1] + 1
    t = (goal[0] + 1) * width + goal[1] + 1
    gr, gc = goal[0] + 1, goal[1] + 1
    k = SQRT2 - 2.0  # octile: |Δr| + |Δc| + (√2 − 2) min(|Δr|, |Δc|)
    # (offset, cost, the two cells beside a diagonal step or 0)
    moves = [
        (1, 1.0, 0, 0),
        (-1, 1.0, 0, 0),
        (width, 1.0, 0, 0),
        (-width, 1.0, 0, 0),
        (width + 1, SQRT2, width, 1),
        (width - 1, SQRT2, width, -1),
        (-width + 1, SQRT2, -width, 1),
        (-width - 1, SQRT2, -width, -1),
    ]
    g = [math.inf] * n_cells
    parent = [-1] * n_cells
    closed = bytearray(blocked)  # blocked cells count as closed: one test per neighbour
    g[s] = 0.0
    heap = [(0, 0.0, s)]
    pop, push = heapq.heappop, heapq.heappush
    while heap:
        _, _, n = pop(heap)
        if closed[n]:
            continue  # a stale entry: n was reached more cheaply since it was pushed
        if n == t:
            break
        closed[n] = 1
        gn = g[n]
        for d, cost, a, b in moves:
            m = n + d
            if closed[m]:
                continue
            if a and blocked[n + a] and blocked[n + b]:
                continue
            gm = gn + cost
            if gm < g[m]:
                g[m] = gm
                parent[m] = n
                r, c = divmod(m, width)
                dr = r - gr if r > gr else gr - r
                dc = c - gc if c > gc else gc - c
                h = dr + dc + k * (dr if dr < dc else dc)
                push(heap, (int((gm + h) * TIE_QUANTUM), h, m))
    else:
        return None

    path = []
    n = t
    while n != -1:
        r, c = divmod(n, width)
        path.append((r - 1, c - 1))
        n = parent[n]
    return path[::-1]


def path_cost(cells: list[tuple[int, int]]) -> float:
    """Length [cells] of a cell path with unit orthogonal and √2 diagonal steps."""
    steps = np.abs(np.diff(np.asarray(cells, int), axis=0)).sum(axis=1)
    return float(np.sum(np.where(steps == 2, SQRT2, 1.0)))


@dataclass(frozen=True)
class PlanningGrid:
    """An occupancy grid with each cell's clearance, inflated for a hull of given radius.

    Built once per world, resolution and inflation (:meth:`from_world`) and reused for every
    plan: it is a pure function of those, never changed after construction, so sharing it
    between plans (or goals of :meth:`ReferenceTrajectory.from_goals`) is safe.

    ``clearance`` [m] estimates the distance from each cell centre to the nearest obstacle:
    the Euclidean distance transform to the nearest non-free cell centre, less half a cell
    (a cell is occupied when the obstacle comes within half a cell of its centre), so it is
    accurate to about ±resolution/2. Unknown cells count as obstacles.
    """

    occupancy: OccupancyGrid  # the grid planned on (0 free, 100 occupied, −1 unknown)
    clearance: np.ndarray  # (rows, cols) [m] estimated clearance of each cell centre
    blocked: np.ndarray  # (rows, cols) bool: clearance < inflation
    inflation: float  # [m] least clearance of the planned path (hull radius + margin)

    @classmethod
    def from_occupancy(cls, occupancy: OccupancyGrid, inflation: float) -> "PlanningGrid":
        if not inflation >= 0:
            raise ValueError(f"PlanningGrid: inflation must be ≥ 0 m, got {inflation}")
        res = occupancy.resolution
        free = occupancy.data == OccupancyGrid.FREE
        clearance = ndimage.distance_transform_edt(free) * res - 0.5 * res
        blocked = clearance < inflation
        for a in (clearance, blocked):
            a.flags.writeable = False
        return cls(occupancy, clearance, blocked, float(inflation))

    @classmethod
    def from_world(
        cls,
        world: World,
        resolution: float = 0.5,
        inflation: float = DEFAULT_INFLATION,
        height_band: tuple[float, float] = (0.0, 1.0),
    ) -> "PlanningGrid":
        """Grid of ``world`` at ``resolution`` [m], blocking cells closer than ``inflation``
        [m] to land or to a solid within ``height_band`` [m above water] (bridge decks above
        the hull are passable)."""
        return cls.from_occupancy(world.occupancy(resolution, height_band), inflation)

    @property
    def resolution(self) -> float:
        return self.occupancy.resolution

    def to_cell(self, xy) -> tuple[int, int]:
        row, col = self.occupancy.to_cell(xy[0], xy[1])
        return int(row), int(col)

    def cell_centres(self, cells) -> np.ndarray:
        """World points (n × 2) [m] of (row, col) cells."""
        rc = np.asarray(cells, float).reshape(-1, 2)
        ox, oy = self.occupancy.origin
        return np.column_stack([ox, oy]) + (rc[:, ::-1] + 0.5) * self.resolution

    def clearance_at(self, points: np.ndarray) -> np.ndarray:
        """Clearance [m] at world points (n × 2), bilinear between cell centres; outside the
        grid it is −resolution (blocked)."""
        p = np.asarray(points, float).reshape(-1, 2)
        ox, oy = self.occupancy.origin
        coords = [(p[:, 1] - oy) / self.resolution - 0.5, (p[:, 0] - ox) / self.resolution - 0.5]
        return ndimage.map_coordinates(
            self.clearance, coords, order=1, mode="constant", cval=-self.resolution
        )

    def segment_clear(self, a: np.ndarray, b: np.ndarray, clearance: float | None = None) -> bool:
        """Whether the straight segment a → b keeps ``clearance`` [m] (default the inflation),
        sampled every quarter cell."""
        need = self.inflation if clearance is None else clearance
        n = max(2, int(np.ceil(np.hypot(*(np.subtract(b, a))) / (0.25 * self.resolution))) + 1)
        s = np.linspace(0.0, 1.0, n)[:, None]
        return bool(np.all(self.clearance_at((1 - s) * a + s * b) >= need - 1e-9))

    def snap(self, xy: np.ndarray, what: str, max_snap: float) -> tuple[tuple[int, int], bool]:
        """The cell to plan from for a world point: its own if unblocked, else the nearest
        unblocked cell within ``max_snap`` [m] reachable in a straight line through free water
        (a vessel moored at a quay starts inside the inflation). Returns (cell, snapped)."""
        rows, cols = self.blocked.shape
        r, c = self.to_cell(xy)
        if not (0 <= r < rows and 0 <= c < cols):
            raise ValueError(f"plan: {what} {tuple(xy)} is outside the grid")
        if not self.blocked[r, c]:
            return (r, c), False
        if self.occupancy.data[r, c] != OccupancyGrid.FREE:
            raise ValueError(f"plan: {what} {tuple(xy)} is not in free water")
        k = int(np.ceil(max_snap / self.resolution))
        r0, r1, c0, c1 = max(r - k, 0), min(r + k + 1, rows), max(c - k, 0), min(c + k + 1, cols)
        rr, cc = np.nonzero(~self.blocked[r0:r1, c0:c1])
        centres = self.cell_centres(np.column_stack([rr + r0, cc + c0]))
        dist = np.hypot(*(centres - xy).T)
        for i in np.argsort(dist):
            if dist[i] > max_snap:
                break
            if self.segment_clear(xy, centres[i], clearance=0.0):
                return (int(rr[i] + r0), int(cc[i] + c0)), True
        raise ValueError(
            f"plan: {what} {tuple(xy)} has clearance {float(self.clearance_at(xy)[0]):.2f} m, "
            f"less than the inflation {self.inflation} m, and no clear cell is within "
            f"{max_snap} m"
        )

    def plan(self, start_xy, goal_xy, simplify: bool = True, max_snap: float = 2.0) -> np.ndarray:
        """Path (n × 2) [m] from ``start_xy`` to ``goal_xy``, both included exactly.

        A* on the blocked cells, the cell centres in between, then (``simplify``) line-of-sight
        shortcutting: from each kept point, the farthest later point whose straight segment
        keeps the inflation clearance (exponential then binary search along the path; the
        search's own steps are always accepted). A start or goal in free water but inside the
        inflation is first joined straight to the nearest clear cell within ``max_snap`` [m].
        Raises :class:`NoPathError` if no path exists, ``ValueError`` for a start or goal
        outside the grid or not in free water.
        """
        start = np.asarray(start_xy, float)
        goal = np.asarray(goal_xy, float)
        s_cell, s_snapped = self.snap(start, "start", max_snap)
        g_cell, g_snapped = self.snap(goal, "goal", max_snap)
        cells = grid_astar(self.blocked, s_cell, g_cell)
        if cells is None:
            raise NoPathError(
                f"no path from {tuple(start)} to {tuple(goal)} keeping {self.inflation} m "
                f"clearance at {self.resolution} m resolution"
            )
        # An unsnapped start or goal lies in its end cell, whose centre is then a needless
        # detour of up to half a cell; a snapped one must go through it.
        keep = np.ones(len(cells), bool)
        keep[0] &= s_snapped
        keep[-1] &= g_snapped
        keep[0] |= len(cells) == 1 and (s_snapped or g_snapped)
        points = np.vstack([start, self.cell_centres(cells)[keep], goal])
        points = points[np.r_[True, np.any(np.diff(points, axis=0) != 0, axis=1)]]
        return self.shortcut(points) if simplify else points

    def shortcut(self, points: np.ndarray) -> np.ndarray:
        """Line-of-sight simplification of a path whose consecutive points are joined by
        allowed steps (see :meth:`plan`)."""
        n = len(points)
        keep = [0]
        i = 0
        while i < n - 1:
            lo, step = i + 1, 1  # lo: known visible from i (a path step)
            hi = None
            while hi is None:
                j = min(i + 2 * step, n - 1)
                if j <= lo:
                    break
                if self.segment_clear(points[i], points[j]):
                    lo, step = j, 2 * step
                    if j == n - 1:
                        break
                else:
                    hi = j
            while hi is not None and hi - lo > 1:
                mid = (lo + hi) // 2
                if self.segment_clear(points[i], points[mid]):
                    lo = mid
                else:
                    hi = mid
            keep.append(lo)
            i = lo
        return points[keep]


def plan_path(
    world: World,
    start_xy,
    goal_xy,
    resolution: float = 0.5,
    inflation: float = DEFAULT_INFLATION,
    simplify: bool = True,
) -> np.ndarray:
    """Collision-free path (n × 2) [m] from ``start_xy`` to ``goal_xy`` in ``world``: occupancy
    at ``resolution`` [m], obstacles inflated by ``inflation`` [m], A*, line-of-sight shortcut.
    Planning several paths in one world? Build :meth:`PlanningGrid.from_world` once and call
    its :meth:`~PlanningGrid.plan`."""
    return PlanningGrid.from_world(world, resolution, inflation).plan(
        start_xy, goal_xy, simplify=simplify
    )
