"""Solids of a world: vertical prisms over a convex footprint (polygon or circle), between
z_min and z_max [m] above the water, optionally cut by one more half-space (sloped faces such as
a wave-generator beach). One description feeds Meshcat, the clearance and occupancy queries and
the ray caster (``usvdrake.worlds.raycast``), so what a person sees is what the sensors get.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class Solid:
    kind: str  # semantic class: quay, building, boat, bridge, wall, rock, tree, bush, leaf, ...
    z_min: float  # [m] bottom above the water surface (negative: below it)
    z_max: float  # [m] top
    polygon: np.ndarray | None = None  # (k × 2) convex footprint, counter-clockwise [m]
    circle: tuple[float, float, float] | None = None  # (x, y, radius) [m] for cylinders
    cut: tuple[float, float, float, float] | None = None  # (nx, ny, nz, d): also n·p ≤ d

    @property
    def is_cylinder(self) -> bool:
        return self.circle is not None

    def bounding_circle(self) -> tuple[float, float, float]:
        """(x, y, r) enclosing the footprint."""
        if self.circle is not None:
            return self.circle
        c = self.polygon.mean(axis=0)
        return float(c[0]), float(c[1]), float(np.max(np.linalg.norm(self.polygon - c, axis=1)))

    def footprint(self, segments: int = 24) -> np.ndarray:
        """The footprint as a polygon (k × 2); circles become ``segments``-gons."""
        if self.circle is None:
            return self.polygon
        x, y, r = self.circle
        a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
        return np.column_stack([x + r * np.cos(a), y + r * np.sin(a)])

    def edge_planes(self) -> tuple[np.ndarray, np.ndarray]:
        """Outward unit normals (k × 2) and offsets (k) with n·p ≤ d inside the footprint."""
        p = self.polygon
        e = np.roll(p, -1, axis=0) - p
        n = np.column_stack([e[:, 1], -e[:, 0]])
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        return n, np.einsum("ij,ij->i", n, p)

    def signed_distance(self, px, py) -> np.ndarray:
        """2D signed distance [m] from points to the footprint (negative inside)."""
        px, py = np.asarray(px, float), np.asarray(py, float)
        if self.circle is not None:
            x, y, r = self.circle
            return np.hypot(px - x, py - y) - r
        n, d = self.edge_planes()
        pts = np.stack([px, py], axis=-1)
        inside = np.max(pts @ n.T - d, axis=-1)
        a = self.polygon
        b = np.roll(a, -1, axis=0)
        ab = b - a
        rel = pts[..., None, :] - a
        t = np.clip(np.einsum("...kj,kj->...k", rel, ab) / np.einsum("kj,kj->k", ab, ab), 0, 1)
        closest = a + t[..., None] * ab
        outside = np.min(np.linalg.norm(pts[..., None, :] - closest, axis=-1), axis=-1)
        return np.where(inside > 0, outside, inside)


def box(
    kind: str, x: float, y: float, lx: float, ly: float, yaw: float, z_min: float, z_max: float
) -> Solid:
    """An oriented box: centre (x, y), size (lx, ly) along its own axes, yaw [rad]."""
    c, s = np.cos(yaw), np.sin(yaw)
    local = np.array([[1, -1], [1, 1], [-1, 1], [-1, -1]]) * [lx / 2, ly / 2]
    return Solid(
        kind, float(z_min), float(z_max), polygon=local @ np.array([[c, s], [-s, c]]) + [x, y]
    )


def cylinder(kind: str, x: float, y: float, radius: float, z_min: float, z_max: float) -> Solid:
    return Solid(kind, float(z_min), float(z_max), circle=(float(x), float(y), float(radius)))


def prism(kind: str, polygon, z_min: float, z_max: float, cut=None) -> Solid:
    """A convex polygon (any orientation; stored counter-clockwise) extruded from z_min to z_max."""
    p = np.asarray(polygon, float)
    area2 = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    if area2 < 0:
        p = p[::-1]
    return Solid(
        kind,
        float(z_min),
        float(z_max),
        polygon=p,
        cut=None if cut is None else tuple(map(float, cut)),
    )
