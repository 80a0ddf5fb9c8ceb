"""Incremental local map of LOAM features: a voxel hash that keyframes are added to and dropped
from without a rebuild, with k-nearest-neighbour search inside a radius.

Roboat II §V-A registers each keyframe against M_t = {M^e, M^p}, the voxel-filtered union of the
previous n keyframes' features. Rebuilding M_t (merge, voxel filter, a new k-d tree) at every
keyframe costs as much as the match; as in iVox (Bai et al., "Faster-LIO", RA-L 2022) and
KISS-ICP (Vizzo et al., RA-L 2023) the map here is a hash of voxels that is edited in place:

* each occupied voxel of side ``voxel`` holds the sum and count of the points in it; its point
  is their centroid. Adding a keyframe adds its (world-frame) points to their voxels, dropping
  one subtracts exactly those points again, so the map is always the PCL VoxelGrid centroid
  filter of the union of the keyframes it holds (what ``voxel_downsample`` of their merged
  points gives, up to rounding).
  ``voxel`` ≤ 0 keeps every point as its own entry (no filtering).
* voxels are grouped into search cells of about ``search_cell`` metres (a whole number of
  voxels, so a voxel lies in one cell); a cell keeps a linked list of its voxels. The k nearest
  map points of q within r are searched in the cells around q's, nearest-possible first, until
  no further cell can hold a nearer point — the exact answer of a k-d tree query with that
  distance bound. Each answer comes with how far q may move before it can change, so a
  registration re-searches only the points that moved that far (:meth:`VoxelMap.knn_update`).
* a keyframe whose pose estimate changed is shifted in place (:meth:`VoxelMap.move`), and the
  window of keyframes slides (:meth:`VoxelMap.slide`).

The query points of a k-NN call are searched on numba's threads (each writes only its own
rows, so the answer does not depend on their number; ``NUMBA_NUM_THREADS=1`` for one).

Voxel and cell coordinates are hashed with the spatial hash of Teschner et al., "Optimized
Spatial Hashing for Collision Detection of Deformable Objects", VMV 2003, into open-addressing
tables (linear probing, load ≤ ½). Entries of voxels that become empty stay until the tables
next grow, when the live ones are compacted; all kernels are numba.
"""

import numpy as np
from numba import njit, prange

_P1, _P2, _P3 = 73856093, 19349663, 83492791  # Teschner 2003's primes
_HALF_RANGE = 1 << 20  # cell / voxel coordinates packed 21 bits each into one int64 key


@njit(cache=True, inline="always")
def _slot(x, y, z, mask):
    # Teschner's hash, then Fibonacci hashing (Knuth, TAOCP vol. 3 §6.4) so that the slot
    # takes the high, well-mixed bits: the low bits of the XOR only see the low bits of x, y, z
    # and neighbouring cells would cluster under linear probing
    h = np.uint64((x * _P1) ^ (y * _P2) ^ (z * _P3)) * np.uint64(0x9E3779B97F4A7C15)
    return np.int64(h >> np.uint64(32)) & mask


@njit(cache=True, inline="always")
def _voxel_of(pts, i, voxel):
    return (
        int(np.floor(pts[i, 0] / voxel)),
        int(np.floor(pts[i, 1] / voxel)),
        int(np.floor(pts[i, 2] / voxel)),
    )


@njit(cache=True)
def _find_or_insert(keys, vals, x, y, z, new_val):
    """Slot of key (x, y, z) in the table (keys (H × 3), vals (H,), −1 = empty), inserted with
    value new_val if absent. Returns (slot, inserted)."""
    mask = len(vals) - 1
    s = _slot(x, y, z, mask)
    while vals[s] >= 0:
        if keys[s, 0] == x and keys[s, 1] == y and keys[s, 2] == z:
            return s, False
        s = (s + 1) & mask
    keys[s, 0], keys[s, 1], keys[s, 2] = x, y, z
    vals[s] = new_val
    return s, True


@njit(cache=True)
def _find(keys, vals, x, y, z):
    mask = len(vals) - 1
    s = _slot(x, y, z, mask)
    while vals[s] >= 0:
        if keys[s, 0] == x and keys[s, 1] == y and keys[s, 2] == z:
            return vals[s]
        s = (s + 1) & mask
    return -1


@njit(cache=True)
def _add_kernel(pts, slots, start, voxel, per_cell, cell, n, vkeys, vvals, ckeys, chead, nxt, ekey,
                sums, cnt, cen):  # fmt: skip
    """Add points pts[start:] (N × 3) to their voxels, writing each one's entry to ``slots``;
    entries n.. are new, each pushed on its cell's list. Stops early when the entry arrays are
    full. Returns (points done, entries in use)."""
    cap = len(cnt)
    for i in range(start, len(pts)):
        if n >= cap and (voxel <= 0.0 or _find(vkeys, vvals, *_voxel_of(pts, i, voxel)) < 0):
            _update_centroids(slots, start, i, sums, cnt, cen)
            return i, n  # a new entry would not fit: the caller grows the arrays
        if voxel > 0.0:
            x, y, z = _voxel_of(pts, i, voxel)
            h, new = _find_or_insert(vkeys, vvals, x, y, z, n)
            e = vvals[h]
            cx, cy, cz = x // per_cell, y // per_cell, z // per_cell
        else:
            new, e = True, n
            x = y = z = 0
            cx = int(np.floor(pts[i, 0] / cell))
            cy = int(np.floor(pts[i, 1] / cell))
            cz = int(np.floor(pts[i, 2] / cell))
        if new:
            n += 1
            ekey[e, 0], ekey[e, 1], ekey[e, 2] = x, y, z
            sums[e, :] = 0.0
            cnt[e] = 0
            c, fresh = _find_or_insert(ckeys, chead, cx, cy, cz, e)
            nxt[e] = -1 if fresh else chead[c]  # push e on the cell's list
            chead[c] = e
        sums[e, 0] += pts[i, 0]
        sums[e, 1] += pts[i, 1]
        sums[e, 2] += pts[i, 2]
        cnt[e] += 1
        slots[i] = e
    _update_centroids(slots, start, len(pts), sums, cnt, cen)
    return len(pts), n


@njit(cache=True)
def _transform_changed(local, R, t, old, voxel):
    """(new, changed, n): the points ``local`` (N × 3) at the pose (R, t), which of them fall in
    another voxel than at ``old``, and how many (the transform and the comparison in one pass:
    a window of 25 keyframes is shifted at every keyframe)."""
    n_pts = len(local)
    new = np.empty((n_pts, 3))
    changed = np.zeros(n_pts, dtype=np.bool_)
    n = 0
    for i in range(n_pts):
        for r in range(3):
            new[i, r] = R[r, 0] * local[i, 0] + R[r, 1] * local[i, 1] + R[r, 2] * local[i, 2] + t[r]
        if voxel > 0 and _voxel_of(old, i, voxel) != _voxel_of(new, i, voxel):
            changed[i] = True
            n += 1
    return new, changed, n


@njit(cache=True)
def _move_kernel(old, new, slots, changed, sums, cnt, cen):
    """Points that stay in their voxel: sums += new − old; the others leave their entries (the
    caller adds them again). Then the touched entries' centroids."""
    for i in range(len(old)):
        e = slots[i]
        if not changed[i]:
            sums[e, 0] += new[i, 0] - old[i, 0]
            sums[e, 1] += new[i, 1] - old[i, 1]
            sums[e, 2] += new[i, 2] - old[i, 2]
            continue
        cnt[e] -= 1
        if cnt[e] <= 0:
            cnt[e] = 0
            sums[e, :] = 0.0
        else:
            sums[e, 0] -= old[i, 0]
            sums[e, 1] -= old[i, 1]
            sums[e, 2] -= old[i, 2]
    done = np.zeros(len(cnt), dtype=np.bool_)
    for i in range(len(old)):
        e = slots[i]
        if not done[e] and cnt[e] > 0:
            done[e] = True
            c = cnt[e]
            cen[e, 0], cen[e, 1], cen[e, 2] = sums[e, 0] / c, sums[e, 1] / c, sums[e, 2] / c


@njit(cache=True)
def _update_centroids(slots, start, end, sums, cnt, cen):
    """cen = sums / cnt of the entries slots[start:end], each once (a voxel gets many points)."""
    done = np.zeros(len(cnt), dtype=np.bool_)
    for i in range(start, end):
        e = slots[i]
        if not done[e]:
            done[e] = True
            c = cnt[e]
            cen[e, 0], cen[e, 1], cen[e, 2] = sums[e, 0] / c, sums[e, 1] / c, sums[e, 2] / c


@njit(cache=True)
def _remove_kernel(pts, slots, sums, cnt, cen):
    """Subtract the points (N × 3) from their entries ``slots`` (as :func:`_add_kernel` gave)."""
    for i in range(len(pts)):
        e = slots[i]
        cnt[e] -= 1
        if cnt[e] <= 0:
            cnt[e] = 0
            sums[e, :] = 0.0  # exactly empty: no rounding residue left behind
            continue
        sums[e, 0] -= pts[i, 0]
        sums[e, 1] -= pts[i, 1]
        sums[e, 2] -= pts[i, 2]
        cen[e, 0], cen[e, 1], cen[e, 2] = (
            sums[e, 0] / cnt[e],
            sums[e, 1] / cnt[e],
            sums[e, 2] / cnt[e],
        )


def _search_offsets(side: float, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell offsets (n × 3) that can hold a point within ``reach`` of a query in cell (0, 0, 0),
    ordered by the least distance any query can have to them (side · √Σ max(|d| − 1, 0)²), the
    27 around first with faces before edges before corners; and those distances squared."""
    s = int(np.ceil(reach / side)) + 1
    r = np.arange(-s, s + 1)
    d = np.stack(np.meshgrid(r, r, r, indexing="ij"), axis=-1).reshape(-1, 3)
    lb2 = side**2 * np.sum(np.maximum(np.abs(d) - 1, 0) ** 2, axis=1)
    order = np.lexsort((np.count_nonzero(d, axis=1), lb2))
    keep = order[lb2[order] <= reach**2]
    return np.ascontiguousarray(d[keep]), lb2[keep]


@njit(cache=True, parallel=True)
def _knn_kernel(q, rows, k, radius, extra, side, offsets, lb2, ckeys, chead, nxt, cnt, cen, idx,
                ok, tau):  # fmt: skip
    """For the query rows ``rows`` of q (M × 3): the k nearest live entries within ``radius``
    into idx[m] (nearest first), ok[m] = all k found, and tau[m], how far q[m] may move before
    that answer can change — half the gap between the k-th and (k+1)-th distance, and the
    k-th distance's margin to the radius (if found); the nearest distance beyond the radius
    minus the radius (if not). The k + 1 nearest are searched within radius + ``extra`` (so a
    miss has tau ≤ extra). Visits the cells of side ``side`` at ``offsets`` from q's cell
    (:func:`_search_offsets`: by least possible distance lb2), skips a cell farther from q than
    the (k+1)-th distance found, and stops at the first offset that cannot hold a nearer one."""
    K = k + 1
    reach_max = radius + extra
    r2 = reach_max * reach_max
    for row in prange(len(rows)):  # each row writes its own idx, ok, tau: thread-safe
        m = rows[row]
        bd = np.empty(K)
        bi = np.empty(K, dtype=np.int64)
        qx, qy, qz = q[m, 0], q[m, 1], q[m, 2]
        bx, by, bz = int(np.floor(qx / side)), int(np.floor(qy / side)), int(np.floor(qz / side))
        found = 0
        for o in range(len(offsets)):
            if found == K and lb2[o] >= bd[K - 1]:
                break  # this and every later cell are farther than the (k+1)-th found
            cx, cy, cz = bx + offsets[o, 0], by + offsets[o, 1], bz + offsets[o, 2]
            # the cell's nearest point to q: skip the cell if beyond what is needed
            gx = max(0.0, max(cx * side - qx, qx - (cx + 1) * side))
            gy = max(0.0, max(cy * side - qy, qy - (cy + 1) * side))
            gz = max(0.0, max(cz * side - qz, qz - (cz + 1) * side))
            g2 = gx * gx + gy * gy + gz * gz
            if g2 > r2 or (found == K and g2 >= bd[K - 1]):
                continue
            e = _find(ckeys, chead, cx, cy, cz)
            while e >= 0:
                if cnt[e] > 0:
                    dx, dy, dz = cen[e, 0] - qx, cen[e, 1] - qy, cen[e, 2] - qz
                    d2 = dx * dx + dy * dy + dz * dz
                    if d2 <= r2 and (found < K or d2 < bd[K - 1]):
                        j = found if found < K else K - 1
                        while j > 0 and bd[j - 1] > d2:  # insertion, ascending
                            bd[j] = bd[j - 1]
                            bi[j] = bi[j - 1]
                            j -= 1
                        bd[j] = d2
                        bi[j] = e
                        if found < K:
                            found += 1
                e = nxt[e]
        inside = 0  # found within the radius (≤ k counted)
        while inside < min(found, k) and bd[inside] <= radius * radius:
            inside += 1
        for j in range(k):
            idx[m, j] = bi[j] if j < inside else 0
        # the next distance after the answer: found, or at least the search's reach
        nxt_d = np.sqrt(bd[inside]) if found > inside else reach_max
        ok[m] = inside == k
        if inside == k:
            dk = np.sqrt(bd[k - 1])
            tau[m] = min(0.5 * (nxt_d - dk), radius - dk)
        else:
            tau[m] = nxt_d - radius


@njit(cache=True)
def moved_rows(q, anchor, tau):
    """The rows of q to search again: no answer yet (tau < 0) or moved at least tau since
    their anchor (the tau of :meth:`VoxelMap.knn_update`); their anchors become q."""
    rows = np.empty(len(q), dtype=np.int64)
    n = 0
    for i in range(len(q)):
        dx, dy, dz = q[i, 0] - anchor[i, 0], q[i, 1] - anchor[i, 1], q[i, 2] - anchor[i, 2]
        if tau[i] < 0 or dx * dx + dy * dy + dz * dz >= tau[i] * abs(tau[i]):
            rows[n] = i
            n += 1
            anchor[i, 0], anchor[i, 1], anchor[i, 2] = q[i, 0], q[i, 1], q[i, 2]
    return rows[:n]


class _Layer:
    """One voxel hash (edges or planes): entries (sum, count, centroid), voxel → entry table,
    cell → first entry table, per-entry next pointer."""

    def __init__(self, voxel: float, search_cell: float, capacity: int = 1 << 12):
        self.voxel = float(voxel)
        if self.voxel > 0:
            self.per_cell = max(1, int(round(search_cell / self.voxel)))
            self.side = self.per_cell * self.voxel
        else:
            self.per_cell, self.side = 1, float(search_cell)
        self.slots: dict = {}  # key → (world points, their entries)
        self._offsets: dict = {}  # search reach → (cell offsets, their least distances²)
        self._allocate(capacity)
        self.n = 0  # entries in use (live or empty)

    def _allocate(self, capacity: int) -> None:
        cap = 1 << max(4, int(np.ceil(np.log2(max(capacity, 2)))))
        self.vkeys = np.zeros((2 * cap, 3), np.int64)
        self.vvals = np.full(2 * cap, -1, np.int64)
        self.ckeys = np.zeros((2 * cap, 3), np.int64)
        self.chead = np.full(2 * cap, -1, np.int64)
        self.nxt = np.full(cap, -1, np.int64)
        self.ekey = np.zeros((cap, 3), np.int64)
        self.sums = np.zeros((cap, 3))
        self.cnt = np.zeros(cap, np.int64)
        self.cen = np.zeros((cap, 3))

    def _grow(self) -> None:
        """Reallocate for twice the live entries and re-add every kept keyframe (the entries
        are renumbered; amortised O(1) per point as the capacity doubles)."""
        live = int(np.count_nonzero(self.cnt[: self.n]))
        self._allocate(2 * live)
        self.n = 0
        for key, (pts, _) in list(self.slots.items()):
            self.slots[key] = (pts, self._insert(pts))

    def _insert(self, pts: np.ndarray) -> np.ndarray:
        slots = np.empty(len(pts), dtype=np.int64)
        done = 0
        while True:
            done, self.n = _add_kernel(
                pts, slots, done, self.voxel, self.per_cell, self.side, self.n, self.vkeys,
                self.vvals, self.ckeys, self.chead, self.nxt, self.ekey, self.sums, self.cnt,
                self.cen,
            )  # fmt: skip
            if done == len(pts):
                return slots
            # full: grow, then the part of these points already in goes in again
            self._grow()
            slots[:done] = self._insert(pts[:done])

    def add(self, key, pts: np.ndarray) -> None:
        pts = np.ascontiguousarray(pts, dtype=float).reshape(-1, 3)
        self.slots[key] = (pts, self._insert(pts))

    def remove(self, key) -> None:
        pts, slots = self.slots.pop(key)
        _remove_kernel(pts, slots, self.sums, self.cnt, self.cen)

    def move(self, key, pts: np.ndarray) -> None:
        """Replace keyframe ``key``'s points by as many others, row for row (the same points at
        a corrected pose): a point that stays in its voxel only shifts the voxel's sum."""
        pts = np.ascontiguousarray(pts, dtype=float).reshape(-1, 3)
        self.move_local(key, pts, np.eye(3), np.zeros(3))  # the identity moves no bit

    def move_local(self, key, local: np.ndarray, R: np.ndarray, t: np.ndarray) -> None:
        """:meth:`move` to the points ``local`` (N × 3, the keyframe's own frame) at the pose
        (R, t): the transform and the voxel comparison in one compiled pass."""
        old = self.slots[key][0]
        if self.voxel <= 0 or len(local) != len(old):
            self.remove(key)
            self.add(key, np.ascontiguousarray(local @ R.T + t))
            return
        pts, changed, n = _transform_changed(local, R, t, old, self.voxel)
        self._shift(key, pts, changed, n)

    def _shift(self, key, pts, changed, n_changed: int) -> None:
        old, slots = self.slots[key]
        if self.n + n_changed > len(self.cnt):  # might not fit: the general path
            self.remove(key)
            self.add(key, pts)
            return
        slots = slots.copy()
        _move_kernel(old, pts, slots, changed, self.sums, self.cnt, self.cen)
        if n_changed:
            moved = np.flatnonzero(changed)
            slots[moved] = self._insert(pts[moved])
        self.slots[key] = (pts, slots)

    def points(self) -> np.ndarray:
        return self.cen[: self.n][self.cnt[: self.n] > 0].copy()

    def knn_update(self, q, rows, k, radius, extra, idx, ok, tau) -> None:
        reach = float(radius) + float(extra)
        if reach not in self._offsets:
            self._offsets[reach] = _search_offsets(self.side, reach)
        offsets, lb2 = self._offsets[reach]
        _knn_kernel(q, rows, int(k), float(radius), float(extra), self.side, offsets, lb2,
                    self.ckeys, self.chead, self.nxt, self.cnt, self.cen, idx, ok, tau)  # fmt: skip


class VoxelMap:
    """The feature map M_t = {M^e, M^p} (Roboat II §V-A) as two incremental voxel hashes.

    edge_voxel, planar_voxel: voxel sides [m] (LIO-SAM 0.2 / 0.4; ≤ 0: no filtering);
    search_cell: [m] about the side of the search cells (≈ the association radius).
    Keyframes are keyed by any hashable (the graph uses its index) and given in the map frame."""

    def __init__(
        self, edge_voxel: float = 0.2, planar_voxel: float = 0.4, search_cell: float = 1.0
    ):
        self.edges = _Layer(edge_voxel, search_cell)
        self.planes = _Layer(planar_voxel, search_cell)
        self.poses: dict = {}  # key → the pose its points were added at (for the caller)

    def __contains__(self, key) -> bool:
        return key in self.edges.slots

    def keys(self) -> list:
        return list(self.edges.slots)

    def add(self, key, edge_points: np.ndarray, planar_points: np.ndarray, pose=None) -> None:
        """Add keyframe ``key``'s features (N × 3) [m], map frame (replacing it if present)."""
        if key in self:
            self.remove(key)
        self.edges.add(key, edge_points)
        self.planes.add(key, planar_points)
        self.poses[key] = None if pose is None else np.array(pose, dtype=float)

    def move(self, key, edge_points: np.ndarray, planar_points: np.ndarray, pose=None) -> None:
        """Keyframe ``key``'s features at a corrected pose: the same points, row for row, moved
        (N × 3) [m]. Equal to dropping and adding it, cheaper: a point that stays in its voxel
        only shifts that voxel's sum (rounding aside)."""
        self.edges.move(key, edge_points)
        self.planes.move(key, planar_points)
        self.poses[key] = None if pose is None else np.array(pose, dtype=float)

    def slide(self, window, poses, edge_clouds, planar_clouds) -> None:
        """Hold exactly the keyframes ``window`` (indices into ``poses``, T_map_keyframe
        (n × 4 × 4), and the per-keyframe sensor-frame clouds (N × 3) [m]): those that left are
        dropped, new ones added, those whose pose changed shifted to it (:meth:`move`)."""
        for i in [i for i in self.keys() if i not in window]:
            self.remove(i)
        for i in window:
            T = poses[i]
            if i in self and np.array_equal(self.poses[i], T):
                continue
            R, t = np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])
            if i in self:
                self.edges.move_local(i, _c(edge_clouds[i]), R, t)
                self.planes.move_local(i, _c(planar_clouds[i]), R, t)
                self.poses[i] = np.array(T, dtype=float)
            else:
                self.add(i, edge_clouds[i] @ R.T + t, planar_clouds[i] @ R.T + t, T)

    def remove(self, key) -> None:
        """Drop keyframe ``key``: its points leave their voxels."""
        self.edges.remove(key)
        self.planes.remove(key)
        self.poses.pop(key, None)

    @property
    def edge_points(self) -> np.ndarray:
        """M^e: the occupied edge voxels' centroids (N × 3) [m]."""
        return self.edges.points()

    @property
    def planar_points(self) -> np.ndarray:
        """M^p: the occupied planar voxels' centroids (N × 3) [m]."""
        return self.planes.points()

    def knn(self, line: bool, q: np.ndarray, k: int, radius: float):
        """(centroid table (E × 3), idx (M × k) into it, ok (M,)): the k nearest edge (``line``)
        or planar map points of each q (M × 3) within ``radius`` [m], nearest first."""
        q = np.ascontiguousarray(q, dtype=float).reshape(-1, 3)
        idx = np.zeros((len(q), k), dtype=np.int64)
        ok = np.zeros(len(q), dtype=np.bool_)
        tau = np.zeros(len(q))
        self.knn_update(line, q, np.arange(len(q)), k, radius, 0.0, idx, ok, tau)
        return self.table(line), idx, ok

    def knn_update(self, line: bool, q, rows, k: int, radius: float, extra: float, idx, ok, tau):
        """:meth:`knn` for the rows ``rows`` of q only, in place into idx, ok and tau (M,):
        how far [m] each q may move before its answer can change (searching k + 1 within
        radius + ``extra``). The map must not change between the calls."""
        layer = self.edges if line else self.planes
        layer.knn_update(q, np.asarray(rows, dtype=np.int64), k, radius, extra, idx, ok, tau)

    def table(self, line: bool) -> np.ndarray:
        """The entry table the indices of :meth:`knn` point into (edges if ``line``)."""
        return (self.edges if line else self.planes).cen


def _c(points: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(points, dtype=float).reshape(-1, 3)


def voxel_filter(points: np.ndarray, voxel: float) -> np.ndarray:
    """The centroid of the points in each occupied voxel of side ``voxel`` [m] (PCL VoxelGrid,
    as ``scan_registration3d.voxel_downsample``), in the order the voxels are first met: one
    hash pass instead of a sort. points: (N × 3) [m]; voxel ≤ 0 returns them unchanged."""
    pts = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
    if voxel <= 0 or len(pts) == 0:
        return pts
    if np.abs(pts).max() / voxel >= _HALF_RANGE - 1:  # beyond the packed keys: the general map
        layer = _Layer(voxel, 8.0 * voxel, capacity=len(pts))
        layer.add(0, pts)
        return layer.points()
    return _voxel_filter_kernel(pts, float(voxel))


@njit(cache=True)
def _voxel_filter_kernel(pts, voxel):
    n = len(pts)
    bits = 1
    while (1 << bits) < 2 * n:
        bits += 1
    size = 1 << bits
    keys = np.empty(size, dtype=np.int64)
    vals = np.full(size, -1, dtype=np.int64)
    sums = np.zeros((n, 3))
    cnt = np.zeros(n, dtype=np.int64)
    m = 0
    for i in range(n):
        x = int(np.floor(pts[i, 0] / voxel)) + _HALF_RANGE
        y = int(np.floor(pts[i, 1] / voxel)) + _HALF_RANGE
        z = int(np.floor(pts[i, 2] / voxel)) + _HALF_RANGE
        key = (x << 42) | (y << 21) | z
        h = np.uint64(key) * np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing (Knuth)
        s = np.int64(h >> np.uint64(64 - bits))
        while vals[s] >= 0 and keys[s] != key:
            s = (s + 1) & (size - 1)
        if vals[s] < 0:
            keys[s], vals[s] = key, m
            m += 1
        e = vals[s]
        sums[e, 0] += pts[i, 0]
        sums[e, 1] += pts[i, 1]
        sums[e, 2] += pts[i, 2]
        cnt[e] += 1
    out = np.empty((m, 3))
    for e in range(m):
        out[e, 0], out[e, 1], out[e, 2] = (
            sums[e, 0] / cnt[e],
            sums[e, 1] / cnt[e],
            sums[e, 2] / cnt[e],
        )
    return out
