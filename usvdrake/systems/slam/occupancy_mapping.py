"""A log-odds occupancy grid built from 2D laser scans with Bresenham rays.

Pham et al. (2022, "Online Robust Sliding-Windowed LiDAR SLAM in Natural Environments", §IV)
update each cell mᵢ with the binary Bayes filter in log-odds form (eq. 15; Thrun, Burgard and
Fox, *Probabilistic Robotics*, §9.2, Table 9.1)::

    l(mᵢ | z₁:ₜ, x₁:ₜ) = l(mᵢ | z₁:ₜ₋₁, x₁:ₜ₋₁) + l(mᵢ | zₜ, xₜ) − l(mᵢ)

with the prior l(mᵢ) = 0 (p = ½) and the inverse sensor model of eq. 16: every ray is
discretised to the grid with Bresenham's line algorithm, the cell holding its end point gets
``l_occ`` and the cells before it ``l_free``. As in Thrun's algorithm, each cell is updated at
most once per scan; a cell that is one ray's end point and another ray's pass-through counts as
occupied. A ray with no return clears free space up to ``max_range`` and marks nothing occupied.

The log-odds are accumulated as integers (``_QUANTUM`` log-odds units), so :meth:`remove_scan`
undoes :meth:`insert_scan` exactly, in any order — what the paper's map module needs to
re-render the scans of nodes that moved after optimisation (§IV-B). For the same reason the
clamp to [l_min, l_max] (which keeps cells able to change their mind) is applied when the grid
is read rather than at each update: clamping per update is not invertible.

Frames: the grid's cell (row, col) covers x ∈ origin_x + [col, col+1)·resolution,
y ∈ origin_y + [row, row+1)·resolution, as :class:`usvdrake.worlds.world.OccupancyGrid`.
"""

import copy
import sys

import numpy as np

from usvdrake.sensors.messages import LaserScan
from usvdrake.worlds.world import OccupancyGrid

_QUANTUM = 1e-4  # [log-odds] integer unit of the accumulated log-odds


def _refs(a: np.ndarray) -> int:
    return sys.getrefcount(a)


class _Probe:
    pass


def _attribute_refs() -> int:
    """:func:`_refs` of an array held by one object's attribute and nothing else (measured,
    not assumed: the count depends on how the interpreter passes arguments)."""
    probe = _Probe()
    probe.array = np.empty(1)
    return _refs(probe.array)


_ALONE = _attribute_refs()


def _held_elsewhere(grid, name: str) -> bool:
    """Whether anything but ``grid`` holds its array ``name`` (another grid sharing it, a view):
    then writing needs a copy. Drake drops the state a clone replaced, so the sharer is often gone
    by the time the grid is read, and the copy (96 MB for a 5 cm lake map) is saved."""
    return _refs(getattr(grid, name)) > _ALONE


MAX_DIRTY = 4096  # changed windows kept for the classes' next update (then: all anew)
MAX_PENDING = 256  # queued scans applied at the latest then (bounds the queue's memory)


class _Scratch:
    """Flat work arrays reused from scan to scan: fresh multi-megabyte temporaries cost more in
    page faults (~2000 per scan) than the arithmetic done in them."""

    def __init__(self):
        self._buffers: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...], dtype) -> np.ndarray:
        size = int(np.prod(shape))
        buf = self._buffers.get(name)
        if buf is None or buf.size < size or buf.dtype != dtype:
            buf = self._buffers[name] = np.empty(max(size, 1), dtype)
        return buf[:size].reshape(shape)


def bresenham_cells(c0: int, r0: int, c1, r1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cells of integer Bresenham lines from one start cell to many end cells, all at once.

    c0, r0: start column and row; c1, r1: end columns and rows (k,). Returns (ray, col, row):
    one entry per cell, ray index first, cells of each ray in order from the start to the end
    (both included). Along the major axis the line advances one cell per step; the minor
    coordinate after i steps is round-half-up(i·b/a) = ⌊(2ib + a) / 2a⌋ (a, b = major and
    minor extents), the closed form of the textbook integer (error-term) algorithm.
    """
    c1 = np.asarray(c1, dtype=np.int64).ravel()
    r1 = np.asarray(r1, dtype=np.int64).ravel()
    dc, dr = c1 - c0, r1 - r0
    counts = np.maximum(np.abs(dc), np.abs(dr)) + 1
    i, m = _line_steps(dc, dr, counts, _Scratch())
    x_major = (np.abs(dc) >= np.abs(dr))[:, None]
    sc, sr = np.sign(dc)[:, None], np.sign(dr)[:, None]
    col = c0 + np.where(x_major, sc * i, sc * m)
    row = r0 + np.where(x_major, sr * m, sr * i)
    keep = np.arange(i.shape[1])[None, :] < counts[:, None]
    ray = np.broadcast_to(np.arange(len(counts))[:, None], i.shape)
    return ray[keep], col[keep], row[keep]


def _line_steps(dc: np.ndarray, dr: np.ndarray, counts: np.ndarray, scratch: _Scratch):
    """Major- and minor-axis offsets (i, m) of the first ``counts[k]`` cells of Bresenham lines
    with extents (dc[k], dr[k]), as (k × max(counts)) int32 matrices — one row per ray, so numpy
    works on whole scans at once. Columns past a ray's count repeat its last cell (marking a
    cell twice is harmless); a ray with count 0 yields its start cell.

    m = ⌊(2ib + a) / 2a⌋ is evaluated in float64 as ⌊i·(b/a) + ½ + 10⁻⁹⌋: the true quotient is
    either an integer or at least 1/2a away from one, so the 10⁻⁹ guard (≫ rounding error,
    ≪ 1/2a for any a < 10⁸) makes it exact. The results live in ``scratch``.
    """
    adc, adr = np.abs(dc), np.abs(dr)
    a = np.maximum(adc, adr)
    q = (np.minimum(adc, adr) / np.maximum(a, 1))[:, None]
    shape = (len(counts), int(counts.max()) if counts.size else 0)
    i = scratch.get("i", shape, np.int32)
    last = np.maximum(counts - 1, 0).astype(np.int32)[:, None]
    np.minimum(np.arange(shape[1], dtype=np.int32)[None, :], last, out=i)
    f = scratch.get("f", shape, np.float64)
    np.multiply(i, q, out=f)
    f += 0.5 + 1e-9
    m = scratch.get("m", shape, np.int32)
    np.copyto(m, f, casting="unsafe")  # truncation = floor: f > 0
    return i, m


class LogOddsGrid:
    """Log-odds occupancy grid (Pham et al. eqs. 15-16) with exact scan insertion and removal.

    origin: (x, y) [m] world position of the corner of cell (0, 0); resolution: cell size [m];
    shape: (rows = y, cols = x); l_occ > 0 and l_free < 0: log-odds [-] added to a ray's end
    cell and to the cells it crosses (defaults p = 0.7 and p = 0.35); l_min, l_max: clamp of
    the log-odds when read (defaults p ≈ 0.12 and 0.97, as OctoMap).
    """

    def __init__(
        self,
        origin: tuple[float, float],
        resolution: float,
        shape: tuple[int, int],
        l_occ: float = 0.85,
        l_free: float = -0.62,
        l_min: float = -2.0,
        l_max: float = 3.5,
    ):
        if not (l_occ > 0.0 > l_free and l_min < 0.0 < l_max and resolution > 0.0):
            raise ValueError("need l_occ > 0 > l_free, l_min < 0 < l_max and resolution > 0")
        self.origin = (float(origin[0]), float(origin[1]))
        self.resolution = float(resolution)
        self.shape = (int(shape[0]), int(shape[1]))
        self.l_min, self.l_max = float(l_min), float(l_max)
        self._q_occ = int(round(l_occ / _QUANTUM))
        self._q_free = int(round(l_free / _QUANTUM))
        self._sum = np.zeros(self.shape, np.int64)  # [_QUANTUM] unclamped Σ of updates
        self._count = np.zeros(self.shape, np.int32)  # scans that observed each cell
        self._scratch = _Scratch()
        self._shared = False  # _sum/_count may be another grid's too: copy before writing
        self._pending: list[tuple] = []  # scans inserted (+1) or removed (−1), not yet applied
        # the last to_occupancy_grid's classes, its thresholds, whether another grid shares the
        # array, and the windows scans changed since (only those are classified again)
        self._classes: np.ndarray | None = None
        self._classes_key: tuple[float, float] | None = None
        self._classes_shared = False
        self._dirty: list[tuple[slice, slice]] = []

    def shared_copy(self) -> "LogOddsGrid":
        """A copy that shares the arrays until either grid writes (copy on write): Drake clones
        a Context's abstract state at every update, and most updates never touch the map. Scans
        are applied to the arrays when the grid is read (or ``MAX_PENDING`` have queued), so a
        grid cloned at every node copies its arrays once per read, not once per scan."""
        other = copy.copy(self)
        other._pending = list(self._pending)
        other._dirty = list(self._dirty)
        self._shared = other._shared = True
        self._classes_shared = other._classes_shared = True
        return other

    @property
    def l_occ(self) -> float:
        return self._q_occ * _QUANTUM

    @property
    def l_free(self) -> float:
        return self._q_free * _QUANTUM

    @property
    def log_odds(self) -> np.ndarray:
        """Clamped log-odds l(mᵢ | z₁:ₜ, x₁:ₜ) [-], (rows, cols) float."""
        self._flush()
        return np.clip(self._sum * _QUANTUM, self.l_min, self.l_max)

    @property
    def observed(self) -> np.ndarray:
        """Cells some inserted (and not removed) scan has seen, (rows, cols) bool."""
        self._flush()
        return self._count > 0

    def probability(self) -> np.ndarray:
        """p(mᵢ | z₁:ₜ, x₁:ₜ) = 1 − 1 / (1 + exp l) [-]; ½ where never observed."""
        return 1.0 / (1.0 + np.exp(-self.log_odds))

    def insert_scan(self, pose, ranges, angles, max_range: float) -> None:
        """Add one scan's inverse sensor model (eqs. 15-16).

        pose: sensor pose (x [m], y [m], θ [rad]) in the grid's frame; ranges [m] and angles
        [rad] (sensor frame, x forward, y left) of each beam; max_range [m]: ranges ≥ it or
        ``inf`` are no-return beams (free up to max_range, nothing occupied); NaN and
        non-positive ranges are ignored.
        """
        self._update(pose, ranges, angles, max_range, +1)

    def remove_scan(self, pose, ranges, angles, max_range: float) -> None:
        """Subtract a scan inserted earlier with the same arguments (exactly)."""
        self._update(pose, ranges, angles, max_range, -1)

    def insert_laser_scan(self, pose, scan: LaserScan, max_range: float | None = None) -> None:
        """:meth:`insert_scan` of a :class:`LaserScan` (invalid beams are no-returns);
        max_range defaults to ``scan.range_max``."""
        r = np.where(scan.valid, scan.ranges, np.inf)
        self.insert_scan(pose, r, scan.angles, scan.range_max if max_range is None else max_range)

    def to_occupancy_grid(
        self, occupied_above: float = 0.6, free_below: float = 0.4
    ) -> OccupancyGrid:
        """The map as an :class:`OccupancyGrid`: 100 where p > occupied_above, 0 where
        p < free_below, −1 where never observed or undecided in between [p: probability].

        Compared in the integer sums (p > p₀ ⟺ clamped l > logit p₀), not through exp() of a
        float copy of the map: a 5 cm lake map is 8 M cells, drawn every second."""
        self._flush()
        key = (float(occupied_above), float(free_below))
        if self._classes is None or self._classes_key != key:
            whole = (slice(0, self.shape[0]), slice(0, self.shape[1]))
            self._classes = self._classify(whole, occupied_above, free_below)
            self._classes_key, self._classes_shared = key, False
        elif self._dirty:  # only the windows scans changed since the last call
            if self._classes_shared and _held_elsewhere(self, "_classes"):
                self._classes = self._classes.copy()
            self._classes_shared = False
            for window in self._dirty:
                self._classes[window] = self._classify(window, occupied_above, free_below)
        self._dirty = []
        data = self._classes.copy()
        return OccupancyGrid(origin=self.origin, resolution=self.resolution, data=data)

    def _classify(self, window, occupied_above: float, free_below: float) -> np.ndarray:
        """The occupancy classes (:meth:`to_occupancy_grid`) of the cells in ``window``."""
        s, n = self._sum[window], self._count[window]
        data = np.full(s.shape, OccupancyGrid.UNKNOWN, np.int8)
        data[self._log_odds_beyond(free_below, True, s)] = OccupancyGrid.FREE
        data[self._log_odds_beyond(occupied_above, False, s)] = OccupancyGrid.OCCUPIED
        data[n == 0] = OccupancyGrid.UNKNOWN
        return data

    def _log_odds_beyond(self, p0: float, below: bool, sums: np.ndarray) -> np.ndarray | bool:
        """Cells of ``sums`` whose probability is below (or above) p0 [-], as a mask or a
        constant."""
        with np.errstate(divide="ignore"):
            l0 = (
                float(np.log(p0) - np.log1p(-p0))
                if 0.0 < p0 < 1.0
                else (np.inf if p0 >= 1.0 else -np.inf)
            )
        if below:  # clamped l < l0
            return l0 > self.l_max or (l0 > self.l_min and sums < l0 / _QUANTUM)
        return l0 < self.l_min or (l0 < self.l_max and sums > l0 / _QUANTUM)

    def _update(self, pose, ranges, angles, max_range: float, sign: int) -> None:
        rays = self._ray_cells(pose, ranges, angles, max_range)
        if rays is None:
            return
        c0, r0, c1, r1, _ = rays
        rmin, rmax = min(r0, int(r1.min())), max(r0, int(r1.max()))
        cmin, cmax = min(c0, int(c1.min())), max(c0, int(c1.max()))
        if (rmax - rmin + 1) * (cmax - cmin + 1) >= 2**31:  # window-flat indices are int32
            raise ValueError("scan window too large: lower max_range or coarsen resolution")
        self._pending.append((*rays, sign))
        if len(self._pending) >= MAX_PENDING:
            self._flush()

    def _ray_cells(self, pose, ranges, angles, max_range: float):
        """(c0, r0, c1, r1, hit) of a scan: the sensor's cell, each usable ray's end cell and
        whether it hit; None without a usable ray. New arrays: the caller may reuse its own."""
        x, y, theta = (float(v) for v in pose)
        ranges = np.asarray(ranges, dtype=float)
        angles = np.broadcast_to(np.asarray(angles, dtype=float), ranges.shape)
        use = ranges > 0.0  # NaN compares False
        ranges, angles = ranges[use], angles[use]
        if ranges.size == 0:
            return None
        hit = ranges < max_range
        length = np.where(hit, ranges, max_range)
        bearing = theta + angles
        res, (ox, oy) = self.resolution, self.origin
        c0 = int(np.floor((x - ox) / res))
        r0 = int(np.floor((y - oy) / res))
        c1 = np.floor((x + length * np.cos(bearing) - ox) / res).astype(np.int64)
        r1 = np.floor((y + length * np.sin(bearing) - oy) / res).astype(np.int64)
        return c0, r0, c1, r1, hit

    def _flush(self) -> None:
        """Apply the queued scans (the integer sums commute: order does not matter)."""
        if not self._pending:
            return
        if self._shared and (_held_elsewhere(self, "_sum") or _held_elsewhere(self, "_count")):
            self._sum, self._count = self._sum.copy(), self._count.copy()
        self._shared = False
        pending, self._pending = self._pending, []
        for op in pending:
            self._apply(*op)

    def _apply(self, c0: int, r0: int, c1, r1, hit, sign: int) -> None:
        # Cells are marked in the scan's bounding window (lines stay inside their end points'
        # box) so that each is updated once per scan; then the window is cut to the grid.
        rmin, rmax = min(r0, int(r1.min())), max(r0, int(r1.max()))
        cmin, cmax = min(c0, int(c1.min())), max(c0, int(c1.max()))
        rows, cols = self.shape
        rlo, clo = max(rmin, 0), max(cmin, 0)
        rhi, chi = min(rmax + 1, rows), min(cmax + 1, cols)
        if rlo >= rhi or clo >= chi:
            return
        h, w = rmax - rmin + 1, cmax - cmin + 1
        dc, dr = c1 - c0, r1 - r0
        # A hit ray's cells before its end are free; a no-return ray's cells all are.
        counts = np.maximum(np.abs(dc), np.abs(dr)) + (~hit)
        i, m = _line_steps(dc, dr, counts, self._scratch)
        # Window-flat index = start + i·(major step) + m·(minor step), one row per ray.
        x_major = np.abs(dc) >= np.abs(dr)
        step_c, step_r = np.sign(dc).astype(np.int32), (np.sign(dr) * w).astype(np.int32)
        np.multiply(i, np.where(x_major, step_c, step_r)[:, None], out=i)
        np.multiply(m, np.where(x_major, step_r, step_c)[:, None], out=m)
        i += m
        i += (r0 - rmin) * w + (c0 - cmin)
        # 0 untouched, 1 free, 2 occupied: end points are written last, so a ray's end point
        # outranks another ray passing through the same cell.
        mark = self._scratch.get("mark", (h * w,), np.uint8)
        mark.fill(0)
        mark[i] = 1
        mark[(r1[hit] - rmin) * w + (c1[hit] - cmin)] = 2
        mark = mark.reshape(h, w)[rlo - rmin : rhi - rmin, clo - cmin : chi - cmin]
        window = (slice(rlo, rhi), slice(clo, chi))
        delta = self._scratch.get("delta", mark.shape, np.int32)
        lut = np.array([0, sign * self._q_free, sign * self._q_occ], np.int32)
        np.take(lut, mark, out=delta)
        self._sum[window] += delta
        np.take(np.array([0, sign, sign], np.int32), mark, out=delta)
        self._count[window] += delta
        if self._classes is not None:
            self._dirty.append(window)
            if len(self._dirty) > MAX_DIRTY:  # a grid no longer read: drop the classes
                self._classes, self._classes_key, self._dirty = None, None, []
