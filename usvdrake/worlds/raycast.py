"""Ray casting against a world's solids (Drake has no ray-cast query: its issue 15260).

The acceleration structure (:class:`Scene`, built once per world) packs every solid into flat
arrays: bounding circles for culling, the footprint's edge half-planes and corners (one run per
solid, indexed by ``edge_ptr``), z ranges, an optional extra cutting plane, and circles for
cylinders.

A scan is cast as a *depth buffer over azimuth columns* (:func:`cast`), in one compiled numba
kernel (no per-scan array calls): each solid that can be within range covers an interval of
columns as seen from the sensor (from its corners' bearings, or its bounding circle; the angles
from a polynomial arctangent, widened by its error bound), so only the rays that can hit it are
tested. Solids are visited nearest first, and a (solid, column) pair is skipped when the solid
cannot come nearer than what every ring of that column already holds (occlusion). For each pair
the exact 2D interval [t_in, t_out] of horizontal distance along the column's direction is
computed once (Cyrus-Beck 1978 clipping against the footprint's edges; the quadratic for
circles); each ring of elevation e then only adds its z slab (z_min ≤ z_s + t·tan e ≤ z_max)
and the cutting plane, and the nearest entry per ray is kept. Rays end at the water surface
(calm water returns nothing to a lidar). Exact for boxes, prisms, cylinders and planes; the
culling and the skip only drop pairs that cannot change a range, so the ranges equal those of
casting every solid at every column, in the same floating-point operations.

Ray parameter t is the *horizontal* distance; the range along the beam is t / cos e.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from usvdrake.worlds.solids import Solid

TWO_PI = 2.0 * np.pi
ATAN_ERR = 1e-7  # [rad] > the summed error of _fast_atan2's angles in one culling span


@dataclass
class Scene:
    """Packed solids. Prisms and cylinders share the index space [0, n_prisms + n_cylinders);
    solid i's edges and corners are rows edge_ptr[i]:edge_ptr[i + 1] (none for cylinders)."""

    centre: np.ndarray  # (N, 2) bounding-circle centres [m]
    radius: np.ndarray  # (N,) bounding-circle radii [m]
    z_min: np.ndarray  # (N,)
    z_max: np.ndarray  # (N,)
    is_cyl: np.ndarray  # (N,) bool
    edge_ptr: np.ndarray  # (N + 1,) int64 row offsets into edge_n, edge_d, corners
    edge_n: np.ndarray  # (E, 2) outward edge normals
    edge_d: np.ndarray  # (E,) offsets: n·p ≤ d inside
    corners: np.ndarray  # (E, 2) footprint corners
    cyl: np.ndarray  # (N, 3) circle (x, y, r) for cylinders
    cut: np.ndarray  # (N, 4) extra plane n·p ≤ d (padding: 0, 0, 0, 1)
    has_cut: np.ndarray  # (N,) bool
    kind: np.ndarray  # (N,) str, the solids' kinds

    @classmethod
    def from_solids(cls, solids: list[Solid]) -> "Scene":
        n = len(solids)
        counts = [0 if s.is_cylinder else len(s.polygon) for s in solids]
        ptr = np.zeros(n + 1, np.int64)
        ptr[1:] = np.cumsum(counts)
        e = int(ptr[-1])
        scene = cls(
            centre=np.zeros((n, 2)),
            radius=np.zeros(n),
            z_min=np.zeros(n),
            z_max=np.zeros(n),
            is_cyl=np.zeros(n, bool),
            edge_ptr=ptr,
            edge_n=np.zeros((e, 2)),
            edge_d=np.zeros(e),
            corners=np.zeros((e, 2)),
            cyl=np.zeros((n, 3)),
            cut=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
            has_cut=np.zeros(n, bool),
            kind=np.array([s.kind for s in solids], dtype=object),
        )
        for i, s in enumerate(solids):
            x, y, r = s.bounding_circle()
            scene.centre[i], scene.radius[i] = (x, y), r
            scene.z_min[i], scene.z_max[i] = s.z_min, s.z_max
            if s.is_cylinder:
                scene.is_cyl[i] = True
                scene.cyl[i] = s.circle
            else:
                normals, offsets = s.edge_planes()
                scene.edge_n[ptr[i] : ptr[i + 1]] = normals
                scene.edge_d[ptr[i] : ptr[i + 1]] = offsets
                scene.corners[ptr[i] : ptr[i + 1]] = s.polygon
            if s.cut is not None:
                scene.cut[i] = s.cut
                scene.has_cut[i] = any(v != 0.0 for v in s.cut[:3])
        return scene

    def __len__(self) -> int:
        return len(self.radius)


@dataclass
class ColumnLayout:
    """Evenly spaced beam azimuths in the sensor frame: column k at az0 + k · daz [rad]."""

    az0: float
    daz: float
    count: int

    @property
    def full_circle(self) -> int:
        return int(round(TWO_PI / abs(self.daz)))

    @property
    def azimuths(self) -> np.ndarray:
        return self.az0 + self.daz * np.arange(self.count)


@njit(cache=True, inline="always")
def _fast_atan2(y, x):
    """atan2 within 2e-8 rad at a fraction of libm's cost: the octant polynomial of Abramowitz &
    Stegun 4.4.49 (Hastings). Culling widens its angles by ATAN_ERR, so it stays conservative."""
    ax, ay = abs(x), abs(y)
    hi = max(ax, ay)
    if hi == 0.0:
        return 0.0
    z = min(ax, ay) / hi
    q = z * z
    p = -0.0161657367 + q * 0.0028662257
    p = -0.0752896400 + q * (0.0429096138 + q * p)
    p = -0.1420889944 + q * (0.1065626393 + q * p)
    r = z * (1.0 + q * (-0.3333314528 + q * (0.1999355085 + q * p)))
    if ay > ax:
        r = 0.5 * np.pi - r
    if x < 0.0:
        r = np.pi - r
    return -r if y < 0.0 else r


@njit(cache=True)
def _span(s, centre, radius, is_cyl, edge_ptr, edge_n, edge_d, corners, ox, oy, view, reach, mg):
    """(first column modulo the full circle, number of columns, a lower bound of the distance
    [m]) of what solid s may cover seen from (ox, oy) or within ``margin`` of it: prisms by the
    bearings of their corners, cylinders by their circle; no columns if out of reach.
    ``view`` = (heading + az0, daz, full-circle columns); ``mg`` = (margin [m]: how far the
    sensor moves during the sweep, slack [rad]: how far its heading turns)."""
    look, daz, full = view
    margin, slack = mg
    relx, rely = centre[s, 0] - ox, centre[s, 1] - oy
    dist = np.sqrt(relx * relx + rely * rely)  # libm's hypot costs more than the cull
    rad = radius[s] + margin
    near = dist - rad
    if not near < reach:
        return 0, 0, near
    mid = _fast_atan2(rely, relx)
    if is_cyl[s]:
        if dist <= rad:
            return 0, full, near
        half = _fast_atan2(rad, np.sqrt((dist - rad) * (dist + rad)))  # arcsin(rad / dist)
    else:
        a, b = edge_ptr[s], edge_ptr[s + 1]
        out_by = -np.inf  # a lower bound of the distance to the footprint
        for k in range(a, b):
            out_by = max(out_by, edge_n[k, 0] * ox + edge_n[k, 1] * oy - edge_d[k])
        near = max(near, out_by - margin)
        if out_by <= margin:
            return 0, full, near
        # The bearings of the corners bound what a prism covers (far tighter than the bounding
        # circle for long walls), widened by what the sweep's motion can change.
        lo_b, hi_b = np.inf, -np.inf
        for k in range(a, b):
            bearing = _fast_atan2(corners[k, 1] - oy, corners[k, 0] - ox) - mid
            if bearing > np.pi:
                bearing -= TWO_PI
            elif bearing < -np.pi:
                bearing += TWO_PI
            lo_b, hi_b = min(lo_b, bearing), max(hi_b, bearing)
        mid += (lo_b + hi_b) / 2
        half = (hi_b - lo_b) / 2
        half += _fast_atan2(margin, np.sqrt((out_by - margin) * (out_by + margin)))
    half += slack + ATAN_ERR
    if half >= np.pi:
        return 0, full, near
    step = abs(daz)
    lo = ((1.0 if daz > 0 else -1.0) * (mid - look) - half) % TWO_PI  # from column 0, beam-wise
    k0 = int(np.ceil(lo / step - 1e-9))
    count = int(np.floor((lo + 2 * half) / step + 1e-9)) - k0 + 1
    return k0, min(max(count, 0), full), near


@njit(cache=True)
def _spans(centre, radius, is_cyl, edge_ptr, edge_n, edge_d, corners, ox, oy, view, reach, mg):
    n = len(radius)
    k0, count = np.zeros(n, np.int64), np.zeros(n, np.int64)
    for s in range(n):
        k0[s], count[s], _ = _span(
            s, centre, radius, is_cyl, edge_ptr, edge_n, edge_d, corners, ox, oy, view, reach, mg
        )
    return k0, count


@njit(cache=True, inline="always")
def _interval_2d(s, is_cyl, edge_ptr, edge_n, edge_d, cyl, ox, oy, hx, hy):
    """Exact [t_in, t_out] of horizontal distance where the line o + t h is inside solid s's
    footprint: the quadratic for a circle, Cyrus-Beck 1978 clipping against a polygon's edges."""
    if is_cyl[s]:
        fx, fy = ox - cyl[s, 0], oy - cyl[s, 1]
        b = fx * hx + fy * hy
        disc = b * b - (fx * fx + fy * fy - cyl[s, 2] ** 2)
        if disc < 0:
            return np.inf, -np.inf
        root = np.sqrt(disc)
        return -b - root, -b + root
    enter, leave = -np.inf, np.inf
    for k in range(edge_ptr[s], edge_ptr[s + 1]):
        nx, ny = edge_n[k, 0], edge_n[k, 1]
        den = nx * hx + ny * hy
        num = edge_d[k] - nx * ox - ny * oy
        if den < 0:
            enter = max(enter, num / den)
        elif den > 0:
            leave = min(leave, num / den)
        elif num < 0:  # parallel to the edge and outside it
            return np.inf, -np.inf
    return enter, leave


@njit(cache=True)
def _cast_kernel(
    centre, radius, is_cyl, edge_ptr, edge_n, edge_d, corners, z_min, z_max, cyl, cut, has_cut,
    az0, daz, ncols, full, tan_e, pose, col_xy, col_psi, ranges, water, cull,
):  # fmt: skip
    """The depth buffer (rings × ncols) of :func:`cast`; pose = (x, y, z, heading), ranges =
    (max, min), water: the water level (NaN: none); col_xy, col_psi empty when standing."""
    ox0, oy0, oz, heading = pose
    max_range, min_range = ranges
    rings = len(tan_e)
    moving_xy, moving_psi = len(col_xy) > 0, len(col_psi) > 0
    out = np.full((rings, ncols), np.inf)
    cos_e, inv, limit = np.empty(rings), np.empty(rings), np.empty(rings)
    for r in range(rings):
        cos_e[r] = 1.0 / np.sqrt(1.0 + tan_e[r] ** 2)
        inv[r] = 0.0 if tan_e[r] == 0.0 else 1.0 / tan_e[r]
        limit[r] = max_range * cos_e[r]
        if oz > water and tan_e[r] < 0:  # NaN water compares false: no water plane
            limit[r] = min(limit[r], (water - oz) / tan_e[r])
    # How far the sensor moves and turns during the sweep widen the culling. Only culling uses
    # them, and it has a column of slack, so the cheap forms (no sqrt, no mod per column) do.
    margin2, slack = 0.0, 0.0
    for c in range(len(col_xy)):
        margin2 = max(margin2, (col_xy[c, 0] - ox0) ** 2 + (col_xy[c, 1] - oy0) ** 2)
    for c in range(len(col_psi)):
        turn = abs(col_psi[c] - heading)
        slack = max(slack, turn if turn <= np.pi else abs((turn + np.pi) % TWO_PI - np.pi))
    margin = np.sqrt(margin2)
    view = (heading + az0, daz, full)
    mg = (margin, slack + abs(daz))
    # Culling, then the candidates nearest first: a pair whose solid cannot come nearer than
    # what its column already holds is skipped (occlusion), which saves most pairs behind a
    # shore. ``near`` is a lower bound of the horizontal distance from any column's origin.
    n = len(radius)
    cand, k0s, counts = np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64)
    near = np.empty(n)
    m = 0
    for s in range(n):
        if cull:
            k0, count, d = _span(
                s, centre, radius, is_cyl, edge_ptr, edge_n, edge_d, corners, ox0, oy0, view,
                max_range, mg,
            )  # fmt: skip
        else:
            k0, count, d = 0, ncols, -np.inf
        if count > 0:
            cand[m], k0s[m], counts[m] = s, k0, count
            near[m] = d - 1e-9 * (1.0 + abs(d))  # rounding of d must not skip a real hit
            m += 1
    order = np.argsort(near[:m])
    hx, hy = np.full(ncols, np.nan), np.empty(ncols)  # column directions, computed on first use
    for i in order:
        s, k0, count = cand[i], k0s[i], counts[i]
        zl, zh = z_min[s] - oz, z_max[s] - oz
        level_inside = zl <= 0.0 and zh >= 0.0
        for j in range(count):
            c = (k0 + j) % full if cull else j
            if c >= ncols:
                continue
            far = out[0, c]
            for r in range(1, rings):
                far = max(far, out[r, c])
            if near[i] > far:
                continue
            if np.isnan(hx[c]):
                az = az0 + daz * c
                az += col_psi[c] if moving_psi else heading
                hx[c], hy[c] = np.cos(az), np.sin(az)
            ox, oy = (col_xy[c, 0], col_xy[c, 1]) if moving_xy else (ox0, oy0)
            t_in, t_out = _interval_2d(
                s, is_cyl, edge_ptr, edge_n, edge_d, cyl, ox, oy, hx[c], hy[c]
            )
            if not (t_in <= t_out and t_out >= 0.0 and t_in <= max_range):
                continue
            for r in range(rings):
                # The z slab in horizontal distance: [z_min, z_max] / tan e for a rising beam,
                # reversed for a falling one; a level beam is all-or-nothing.
                if tan_e[r] > 0.0:
                    enter, leave = max(zl * inv[r], t_in), min(zh * inv[r], t_out)
                elif tan_e[r] < 0.0:
                    enter, leave = max(zh * inv[r], t_in), min(zl * inv[r], t_out)
                elif level_inside:
                    enter, leave = t_in, t_out
                else:
                    continue
                if has_cut[s]:
                    den = cut[s, 0] * hx[c] + cut[s, 1] * hy[c] + cut[s, 2] * tan_e[r]
                    num = cut[s, 3] - (cut[s, 0] * ox + cut[s, 1] * oy) - cut[s, 2] * oz
                    if den < 0:
                        enter = max(enter, num / den)
                    elif den > 0:
                        leave = min(leave, num / den)
                    elif num < 0:
                        continue
                enter, leave = max(enter, 0.0), min(leave, limit[r])
                if enter <= leave and enter / cos_e[r] < out[r, c]:
                    out[r, c] = enter / cos_e[r]
    # A surface closer than the minimum range blocks the beam and returns nothing.
    for r in range(rings):
        for c in range(ncols):
            if out[r, c] <= min_range:
                out[r, c] = np.inf
    return out


_NO_XY, _NO_PSI = np.zeros((0, 2)), np.zeros(0)


def _pairs(
    scene: Scene,
    origin: np.ndarray,
    heading: float,
    layout: ColumnLayout,
    reach: float,
    margin: float,
    slack: float,
):
    """(solid, column) pairs whose solid, seen from ``origin``, may cover the column's
    direction (the culling :func:`cast` applies; ``margin`` [m] is how far the sensor moves
    during the sweep, ``slack`` [rad] how far its heading turns)."""
    full = layout.full_circle
    k0, count = _spans(
        *(scene.centre, scene.radius, scene.is_cyl, scene.edge_ptr),
        *(scene.edge_n, scene.edge_d, scene.corners, float(origin[0]), float(origin[1])),
        (float(heading + layout.az0), float(layout.daz), full),
        float(reach),
        (float(margin), float(slack)),
    )
    total = int(count.sum())
    solid = np.repeat(np.arange(len(scene)), count)
    start = np.repeat(np.cumsum(count) - count, count)
    col = (np.repeat(k0, count) + np.arange(total) - start) % full
    keep = col < layout.count
    return solid[keep], col[keep]


def cast(
    scene: Scene,
    layout: ColumnLayout,
    tan_elevation: np.ndarray,
    origin_xy: np.ndarray,
    origin_z: float,
    heading: float,
    max_range: float,
    min_range: float = 0.0,
    water_level: float | None = 0.0,
    column_origin_xy: np.ndarray | None = None,
    column_heading: np.ndarray | None = None,
    cull: bool = True,
) -> np.ndarray:
    """Ranges [m] along each beam, shape (rings, columns); ``inf`` where nothing is hit within
    [min_range, max_range] before the beam meets the water.

    ``origin_xy``, ``heading``: the sensor pose used for culling. To apply the sweep's own
    motion, pass each column's origin (``column_origin_xy``, C × 2) and heading
    (``column_heading``, C); the culling is widened to cover them. ``cull=False`` tests every
    solid against every column (a reference for tests).
    """
    tan_e = np.ascontiguousarray(tan_elevation, dtype=np.float64).reshape(-1)
    col_xy = (
        _NO_XY
        if column_origin_xy is None
        else np.ascontiguousarray(column_origin_xy, dtype=np.float64)
    )
    col_psi = (
        _NO_PSI if column_heading is None else np.ascontiguousarray(column_heading, np.float64)
    )
    return _cast_kernel(
        *(scene.centre, scene.radius, scene.is_cyl, scene.edge_ptr, scene.edge_n, scene.edge_d),
        *(scene.corners, scene.z_min, scene.z_max, scene.cyl, scene.cut, scene.has_cut),
        *(float(layout.az0), float(layout.daz), int(layout.count), layout.full_circle, tan_e),
        (float(origin_xy[0]), float(origin_xy[1]), float(origin_z), float(heading)),
        *(col_xy, col_psi, (float(max_range), float(min_range))),
        np.nan if water_level is None else float(water_level),
        bool(cull),
    )
