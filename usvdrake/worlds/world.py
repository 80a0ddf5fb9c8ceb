"""Worlds as data: oriented boxes (quays, facades, boats, bridges) and water patches.

One geometry serves Meshcat (``viz.meshcat_world``), the clearance metric here and, later, the
simulated lidars. z is up from the water surface (z = 0).
"""

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Box:
    """An oriented box: centre (x, y) [m], size along its own axes (lx, ly) [m], yaw [rad],
    vertical extent z_min..z_max [m] above the water surface."""

    kind: str  # "quay", "building", "boat", "bridge", "wall", ...
    x: float
    y: float
    lx: float
    ly: float
    yaw: float
    z_min: float
    z_max: float

    def signed_distance(self, px: np.ndarray, py: np.ndarray) -> np.ndarray:
        """Signed distance [m] from points to the box footprint (negative inside)."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        dx, dy = px - self.x, py - self.y
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        qx, qy = np.abs(lx) - self.lx / 2, np.abs(ly) - self.ly / 2
        outside = np.hypot(np.maximum(qx, 0.0), np.maximum(qy, 0.0))
        inside = np.minimum(np.maximum(qx, qy), 0.0)
        return outside + inside


@dataclass
class World:
    name: str
    seed: int
    boxes: list[Box] = field(default_factory=list)
    water: list[Box] = field(default_factory=list)  # flat patches (z_min = z_max = 0) of water
    bounds: tuple[float, float, float, float] = (-50.0, -50.0, 50.0, 50.0)  # xmin ymin xmax ymax

    def obstacles_at_waterline(self, height: float = 1.0) -> list[Box]:
        """Boxes a hull of ``height`` [m] can hit (bridges above it are not obstacles)."""
        return [b for b in self.boxes if b.z_min < height]

    def clearance(self, px, py, height: float = 1.0) -> np.ndarray:
        """Distance [m] from points to the nearest obstacle footprint (negative: inside one)."""
        px, py = np.asarray(px, float), np.asarray(py, float)
        d = np.full(np.broadcast(px, py).shape, np.inf)
        for b in self.obstacles_at_waterline(height):
            d = np.minimum(d, b.signed_distance(px, py))
        return d


def hull_outline(length: float, beam: float, n_per_side: int = 4) -> np.ndarray:
    """Sample points (k × 2) on a rectangular hull outline, body frame."""
    t = np.linspace(-0.5, 0.5, n_per_side + 1)
    pts = [[length * a, beam / 2] for a in t] + [[length * a, -beam / 2] for a in t]
    pts += [[length / 2, beam * a] for a in t] + [[-length / 2, beam * a] for a in t]
    return np.unique(np.array(pts), axis=0)


def hull_clearance(
    world: World, states: np.ndarray, length: float, beam: float, height: float
) -> np.ndarray:
    """Per state [x y ψ ...], the distance [m] from the hull outline to the nearest obstacle
    (negative when the hull overlaps one)."""
    outline = hull_outline(length, beam)
    states = np.atleast_2d(states)
    c, s = np.cos(states[:, 2]), np.sin(states[:, 2])
    px = states[:, [0]] + c[:, None] * outline[:, 0] - s[:, None] * outline[:, 1]
    py = states[:, [1]] + s[:, None] * outline[:, 0] + c[:, None] * outline[:, 1]
    return world.clearance(px, py, height).min(axis=1)
