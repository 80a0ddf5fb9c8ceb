"""Ship hull outlines and their overlap: the collision test of the encounter evaluation (numpy).

A hull is the length × width rectangle of trafficgen's dimensions, placed around the tracked
reference point (the AIS/GPS antenna) by the offsets a/b/c/d to bow/stern/port/starboard and
oriented by the heading ψ (our convention, counter-clockwise from east; body x forward, y to
port). Overlap of two convex outlines is decided by the separating axis theorem: two convex
polygons are disjoint iff their projections on one of their edge normals are disjoint.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from usvdrake.angles import wrap_angle


@dataclass(frozen=True)
class Hull:
    """A rectangular hull: length, width [m] and the reference point's offsets [m]."""

    length: float
    width: float
    a: float | None = None  # reference point → bow
    b: float | None = None  # → stern
    c: float | None = None  # → port side
    d: float | None = None  # → starboard side

    @classmethod
    def from_ship(cls, ship) -> Hull:
        """From a :class:`usvdrake.systems.colav.situation.Ship` (or anything with the same
        ``length, width, a, b, c, d`` attributes)."""
        return cls(ship.length, ship.width, ship.a, ship.b, ship.c, ship.d)

    def body_corners(self) -> np.ndarray:
        """(4, 2) corners in the body frame (x forward, y port), counter-clockwise from the
        starboard bow. Offsets missing (or inconsistent with length/width) → centred."""
        L, W = self.length, self.width
        a, b = (self.a, self.b) if None not in (self.a, self.b) else (L / 2, L / 2)
        c, d = (self.c, self.d) if None not in (self.c, self.d) else (W / 2, W / 2)
        if abs(a + b - L) > 0.05 * L:
            a, b = L / 2, L / 2
        if abs(c + d - W) > 0.05 * W:
            c, d = W / 2, W / 2
        return np.array([[a, -d], [a, c], [-b, c], [-b, -d]], float)

    @property
    def radius(self) -> float:
        """Distance from the reference point to the farthest corner [m]."""
        return float(np.max(np.linalg.norm(self.body_corners(), axis=1)))


def hull_corners(hull: Hull, x, y, psi) -> np.ndarray:
    """World-frame corners (n, 4, 2) of ``hull`` at poses (x, y, ψ) (arrays of length n)."""
    x, y, psi = (np.atleast_1d(np.asarray(v, float)) for v in (x, y, psi))
    c, s = np.cos(psi), np.sin(psi)
    body = hull.body_corners()
    wx = x[:, None] + c[:, None] * body[None, :, 0] - s[:, None] * body[None, :, 1]
    wy = y[:, None] + s[:, None] * body[None, :, 0] + c[:, None] * body[None, :, 1]
    return np.stack([wx, wy], axis=-1)


def _edge_normals(poly: np.ndarray) -> np.ndarray:
    """(n, k, 2) normals of the edges of (n, k, 2) polygons."""
    edges = np.roll(poly, -1, axis=1) - poly
    return np.stack([-edges[..., 1], edges[..., 0]], axis=-1)


def polygons_overlap(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Whether convex polygons ``p[i]`` and ``q[i]`` ((n, k, 2) each) overlap (touching counts),
    by the separating axis theorem; a bool array of length n."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    if p.ndim == 2:
        p, q = p[None], q[None]
    axes = np.concatenate([_edge_normals(p), _edge_normals(q)], axis=1)  # (n, m, 2)
    proj_p = np.einsum("nmd,nkd->nmk", axes, p)
    proj_q = np.einsum("nmd,nkd->nmk", axes, q)
    separated = (proj_p.max(axis=2) < proj_q.min(axis=2)) | (
        proj_q.max(axis=2) < proj_p.min(axis=2)
    )
    return ~np.any(separated, axis=1)


def first_collision(t, own_pose, own_hull: Hull, tgt_pose, tgt_hull: Hull, step_m: float = 0):
    """The first time [s] the two hulls overlap, or None.

    ``own_pose`` and ``tgt_pose`` are (x, y, ψ) arrays sampled at the same times ``t``. Between
    samples the poses are interpolated linearly (ψ along the shorter arc) wherever the reference
    points come within the sum of the hulls' radii, with sub-steps of at most ``step_m`` of
    relative motion (default: a quarter of the narrower beam), so a crossing is not missed
    between coarse samples."""
    t = np.asarray(t, float)
    po = np.column_stack([np.asarray(v, float) for v in own_pose])
    pt = np.column_stack([np.asarray(v, float) for v in tgt_pose])
    reach = own_hull.radius + tgt_hull.radius
    step = step_m if step_m > 0 else 0.25 * min(own_hull.width, tgt_hull.width)
    rel = pt[:, :2] - po[:, :2]
    if len(t) == 1:
        hit = polygons_overlap(hull_corners(own_hull, *po.T), hull_corners(tgt_hull, *pt.T))
        return float(t[0]) if hit[0] else None
    d0, dd = rel[:-1], np.diff(rel, axis=0)
    a = np.sum(dd * dd, axis=1)
    s = np.clip(
        np.where(a > 1e-18, -np.sum(d0 * dd, axis=1) / np.where(a > 1e-18, a, 1.0), 0.0), 0, 1
    )
    seg_min = np.linalg.norm(d0 + s[:, None] * dd, axis=1)
    for i in np.flatnonzero(seg_min <= reach):
        n_sub = int(min(2000, np.ceil(np.sqrt(a[i]) / step) + 1))
        u = np.linspace(0.0, 1.0, n_sub + 1)
        o = _lerp_pose(po[i], po[i + 1], u)
        g = _lerp_pose(pt[i], pt[i + 1], u)
        hit = polygons_overlap(hull_corners(own_hull, *o), hull_corners(tgt_hull, *g))
        if np.any(hit):
            k = int(np.argmax(hit))
            return float(t[i] + u[k] * (t[i + 1] - t[i]))
    return None


def _lerp_pose(p0, p1, u):
    dpsi = wrap_angle(p1[2] - p0[2])
    return p0[0] + u * (p1[0] - p0[0]), p0[1] + u * (p1[1] - p0[1]), p0[2] + u * dpsi
