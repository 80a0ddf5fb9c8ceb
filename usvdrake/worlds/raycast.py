"""Vectorised ray casting against a world's solids (Drake has no ray-cast query: its issue 15260).

The acceleration structure (:class:`Scene`, built once per world) packs every solid into arrays:
bounding circles for culling, the footprint's edge half-planes (padded to a common count),
z ranges, an optional extra cutting plane, and circles for cylinders.

A scan is cast as a *depth buffer over azimuth columns* (:func:`cast`): each solid that can be
within range covers an interval of columns as seen from the sensor (from its bounding circle),
which expands into (solid, column) pairs — only the rays that can hit it. For each pair the exact
2D interval [t_in, t_out] of horizontal distance along the column's direction is computed once
(Cyrus-Beck clipping against the footprint's edges; the quadratic for circles); each ring of
elevation e then only adds its z slab (z_min ≤ z_s + t·tan e ≤ z_max) and the cutting plane, and
the nearest entry per ray is kept with ``np.minimum.at``. Rays end at the water surface (calm
water returns nothing to a lidar). Exact for boxes, prisms, cylinders and planes; no Python loop
over rays or solids.

Ray parameter t is the *horizontal* distance; the range along the beam is t / cos e.
"""

from dataclasses import dataclass

import numpy as np

from usvdrake.worlds.solids import Solid

TWO_PI = 2.0 * np.pi


@dataclass
class Scene:
    """Packed solids. Prisms and cylinders share the index space [0, n_prisms + n_cylinders)."""

    centre: np.ndarray  # (N, 2) bounding-circle centres [m]
    radius: np.ndarray  # (N,) bounding-circle radii [m]
    z_min: np.ndarray  # (N,)
    z_max: np.ndarray  # (N,)
    is_cyl: np.ndarray  # (N,) bool
    edge_n: np.ndarray  # (N, K, 2) outward edge normals (zeros: padding / cylinders)
    edge_d: np.ndarray  # (N, K) offsets (padding: 1, always satisfied)
    cyl: np.ndarray  # (N, 3) circle (x, y, r) for cylinders
    cut: np.ndarray  # (N, 4) extra plane n·p ≤ d (padding: 0, 0, 0, 1)
    corners: np.ndarray  # (N, K, 2) footprint corners (padding repeats the last; cylinders: centre)
    kind: np.ndarray  # (N,) str, the solids' kinds

    @classmethod
    def from_solids(cls, solids: list[Solid]) -> "Scene":
        n = len(solids)
        k = max([len(s.polygon) for s in solids if s.polygon is not None] + [3])
        scene = cls(
            centre=np.zeros((n, 2)),
            radius=np.zeros(n),
            z_min=np.zeros(n),
            z_max=np.zeros(n),
            is_cyl=np.zeros(n, bool),
            edge_n=np.zeros((n, k, 2)),
            edge_d=np.ones((n, k)),
            cyl=np.zeros((n, 3)),
            cut=np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
            corners=np.zeros((n, k, 2)),
            kind=np.array([s.kind for s in solids], dtype=object),
        )
        for i, s in enumerate(solids):
            x, y, r = s.bounding_circle()
            scene.centre[i], scene.radius[i] = (x, y), r
            scene.z_min[i], scene.z_max[i] = s.z_min, s.z_max
            if s.is_cylinder:
                scene.is_cyl[i] = True
                scene.cyl[i] = s.circle
                scene.corners[i] = s.circle[:2]
            else:
                normals, offsets = s.edge_planes()
                scene.edge_n[i, : len(offsets)] = normals
                scene.edge_d[i, : len(offsets)] = offsets
                scene.corners[i, : len(s.polygon)] = s.polygon
                scene.corners[i, len(s.polygon) :] = s.polygon[-1]
            if s.cut is not None:
                scene.cut[i] = s.cut
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


def _pairs(
    scene: Scene,
    origin: np.ndarray,
    heading: float,
    layout: ColumnLayout,
    reach: float,
    margin: float,
    slack: float,
):
    """(solid, column) pairs whose solid, seen from ``origin``, may cover the column's direction:
    prisms by the bearings of their corners, cylinders by their circle. ``margin`` [m] is how far
    the sensor moves during the sweep, ``slack`` [rad] how far its heading turns."""
    rel = scene.centre - origin
    dist = np.hypot(rel[:, 0], rel[:, 1])
    rad = scene.radius + margin
    cand = np.nonzero(dist - rad < reach)[0]
    if cand.size == 0:
        return np.zeros(0, int), np.zeros(0, int)
    dist, rad, rel = dist[cand], rad[cand], rel[cand]
    full = layout.full_circle
    inside = dist <= rad
    half = (
        np.where(inside, np.pi, np.arcsin(np.clip(rad / np.maximum(dist, 1e-12), 0.0, 1.0))) + slack
    )
    centre_angle = np.arctan2(rel[:, 1], rel[:, 0])
    # Prisms: the exact bearings of their corners bound what they cover (far tighter than the
    # bounding circle for long walls), widened by what the sweep's motion can change.
    prism = ~scene.is_cyl[cand]
    if prism.any():
        sp = cand[prism]
        out_by = np.max(np.einsum("pkj,j->pk", scene.edge_n[sp], origin) - scene.edge_d[sp], axis=1)
        outside = out_by > margin  # a lower bound of the distance to the footprint
        if outside.any():
            rc = scene.corners[sp[outside]] - origin
            mid = centre_angle[prism][outside]
            bearing = (
                np.mod(np.arctan2(rc[..., 1], rc[..., 0]) - mid[:, None] + np.pi, TWO_PI) - np.pi
            )
            lo_b, hi_b = bearing.min(axis=1), bearing.max(axis=1)
            widen = np.arcsin(np.clip(margin / out_by[outside], 0.0, 1.0))
            idx = np.nonzero(prism)[0][outside]
            centre_angle[idx] = mid + (lo_b + hi_b) / 2
            half[idx] = (hi_b - lo_b) / 2 + widen + slack
            inside[idx] = False
        inside_prism = np.nonzero(prism)[0][~outside]
        inside[inside_prism] = True
        half[inside_prism] = np.pi
    centre_angle = centre_angle - heading - layout.az0
    step = abs(layout.daz)
    sign = 1.0 if layout.daz > 0 else -1.0
    lo = np.mod(sign * centre_angle - half, TWO_PI)  # angular offset from column 0, beam-wise
    k0 = np.ceil(lo / step - 1e-9).astype(int)
    count = np.floor((lo + 2 * half) / step + 1e-9).astype(int) - k0 + 1
    count = np.where(inside | (half >= np.pi), full, np.clip(count, 0, full))
    total = int(count.sum())
    if total == 0:
        return np.zeros(0, int), np.zeros(0, int)
    solid = np.repeat(cand, count)
    start = np.repeat(np.cumsum(count) - count, count)
    col = (np.repeat(k0, count) + np.arange(total) - start) % full
    keep = col < layout.count
    return solid[keep], col[keep]


def _interval_2d(scene: Scene, solid: np.ndarray, o: np.ndarray, h: np.ndarray):
    """Exact [t_in, t_out] of horizontal distance where the line o + t h is inside the footprint."""
    # Cylinders carry only padding edges (always satisfied), so the prism clip leaves them
    # (−inf, inf); their circle then overwrites that. Cheaper than splitting the arrays.
    t_in, t_out = _interval_prism(scene, solid, o, h)
    cyl = scene.is_cyl[solid]
    if cyl.any():
        s, oc, hc = solid[cyl], o[cyl], h[cyl]
        fx, fy = oc[:, 0] - scene.cyl[s, 0], oc[:, 1] - scene.cyl[s, 1]
        b = fx * hc[:, 0] + fy * hc[:, 1]
        disc = b * b - (fx * fx + fy * fy - scene.cyl[s, 2] ** 2)
        root = np.sqrt(np.maximum(disc, 0.0))
        miss = disc < 0
        t_in[cyl] = np.where(miss, np.inf, -b - root)
        t_out[cyl] = np.where(miss, -np.inf, -b + root)
    return t_in, t_out


def _interval_prism(scene: Scene, solid: np.ndarray, o: np.ndarray, h: np.ndarray):
    """Cyrus-Beck clipping of o + t h against each footprint's edge half-planes."""
    n, d = scene.edge_n[solid], scene.edge_d[solid]
    nx, ny = n[..., 0], n[..., 1]
    den = nx * h[:, 0:1] + ny * h[:, 1:2]
    num = d - nx * o[:, 0:1] - ny * o[:, 1:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    enter = np.max(t, axis=1, where=den < 0, initial=-np.inf)
    leave = np.min(t, axis=1, where=den > 0, initial=np.inf)
    parallel_out = ((den == 0) & (num < 0)).any(axis=1)
    enter[parallel_out] = np.inf
    leave[parallel_out] = -np.inf
    return enter, leave


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
    tan_e = np.asarray(tan_elevation, float).reshape(-1)
    cos_e = 1.0 / np.sqrt(1.0 + tan_e**2)
    rings, cols = len(tan_e), layout.count
    out = np.full(rings * cols, np.inf)
    origin_xy = np.asarray(origin_xy, float)
    margin, slack = 0.0, 0.0
    if column_origin_xy is not None:
        margin = float(np.max(np.linalg.norm(column_origin_xy - origin_xy, axis=1)))
    if column_heading is not None:
        slack = float(np.max(np.abs(np.mod(column_heading - heading + np.pi, TWO_PI) - np.pi)))
    t_reach = max_range  # horizontal reach never exceeds the range
    if cull:
        solid, col = _pairs(
            scene, origin_xy, heading, layout, t_reach, margin, slack + abs(layout.daz)
        )
    else:
        solid = np.repeat(np.arange(len(scene)), layout.count)
        col = np.tile(np.arange(layout.count), len(scene))
    if solid.size == 0:
        return out.reshape(rings, cols)
    az = layout.az0 + layout.daz * col
    az = az + (heading if column_heading is None else column_heading[col])
    h = np.column_stack([np.cos(az), np.sin(az)])
    o = (
        np.broadcast_to(origin_xy, (len(col), 2))
        if column_origin_xy is None
        else column_origin_xy[col]
    )
    t_in, t_out = _interval_2d(scene, solid, o, h)
    hit2d = (t_in <= t_out) & (t_out >= 0.0) & (t_in <= t_reach)
    solid, col, t_in, t_out, o, h = (
        solid[hit2d],
        col[hit2d],
        t_in[hit2d],
        t_out[hit2d],
        o[hit2d],
        h[hit2d],
    )

    # Per ring: z slab of each solid, expressed in horizontal distance. For a rising beam the
    # slab is [z_min, z_max] / tan e, for a falling one reversed; level beams are all-or-nothing.
    zl = scene.z_min[solid] - origin_z
    zh = scene.z_max[solid] - origin_z
    flat = tan_e == 0.0
    up = tan_e > 0.0
    with np.errstate(divide="ignore"):
        inv = np.where(flat, 0.0, 1.0 / np.where(flat, 1.0, tan_e))
    inv_up, inv_down = np.where(up, inv, 0.0), np.where(up | flat, 0.0, inv)
    enter = np.multiply.outer(zl, inv_up)
    enter += np.multiply.outer(zh, inv_down)
    np.maximum(enter, t_in[:, None], out=enter)
    leave = np.multiply.outer(zh, inv_up)
    leave += np.multiply.outer(zl, inv_down)
    np.minimum(leave, t_out[:, None], out=leave)
    if flat.any():
        level_inside = (zl <= 0.0) & (zh >= 0.0)
        enter[:, flat] = np.where(level_inside, t_in, np.inf)[:, None]
        leave[:, flat] = np.where(level_inside, t_out, -np.inf)[:, None]

    cut = scene.cut[solid]
    has_cut = np.any(cut[:, :3] != 0.0, axis=1)
    if has_cut.any():
        c = cut[has_cut]
        den = (np.einsum("pj,pj->p", c[:, :2], h[has_cut]))[:, None] + c[:, 2:3] * tan_e[None, :]
        num = (c[:, 3] - np.einsum("pj,pj->p", c[:, :2], o[has_cut]) - c[:, 2] * origin_z)[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / den
        enter[has_cut] = np.maximum(enter[has_cut], np.where(den < 0, t, -np.inf))
        leave[has_cut] = np.minimum(
            leave[has_cut], np.where(den > 0, t, np.where((den == 0) & (num < 0), -np.inf, np.inf))
        )

    limit = np.full(rings, max_range) * cos_e
    if water_level is not None and origin_z > water_level:
        with np.errstate(divide="ignore"):
            t_water = np.where(
                tan_e < 0, (water_level - origin_z) / np.where(tan_e < 0, tan_e, -1.0), np.inf
            )
        limit = np.minimum(limit, t_water)
    np.maximum(enter, 0.0, out=enter)
    np.minimum(leave, limit[None, :], out=leave)
    ok = enter <= leave
    p_idx, r_idx = np.nonzero(ok)
    if p_idx.size:
        np.minimum.at(out, r_idx * cols + col[p_idx], enter[p_idx, r_idx] / cos_e[r_idx])
    # A surface closer than the minimum range blocks the beam and returns nothing.
    out[out <= min_range] = np.inf
    return out.reshape(rings, cols)
