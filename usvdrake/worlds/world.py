"""A world: solids, the water region, GPS-denied zones, and the queries everything else uses.

z is up from the water surface (z = 0). The water region is a shapely (Multi)Polygon: inside it
and outside every solid is free water. Ground-truth occupancy (:meth:`World.occupancy`) uses the
ROS convention: 0 free, 100 occupied (solids in the height band, and land), −1 unknown (never in
ground truth; SLAM maps use it).
"""

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import shapely
from scipy.spatial import cKDTree

from usvdrake.worlds.raycast import ColumnLayout, Scene, cast
from usvdrake.worlds.solids import Solid

SKY_CELL = 2.0  # [m] resolution of the memoised sky-blockage map


@dataclass
class OccupancyGrid:
    origin: tuple[float, float]  # [m] world position of the corner of cell (0, 0)
    resolution: float  # [m] cell size
    data: np.ndarray  # (rows = y, cols = x) int8: 0 free, 100 occupied, −1 unknown

    FREE, OCCUPIED, UNKNOWN = 0, 100, -1

    @property
    def shape(self) -> tuple[int, int]:
        return self.data.shape

    def cell_centres(self) -> tuple[np.ndarray, np.ndarray]:
        rows, cols = self.data.shape
        xs = self.origin[0] + (np.arange(cols) + 0.5) * self.resolution
        ys = self.origin[1] + (np.arange(rows) + 0.5) * self.resolution
        return xs, ys

    def to_cell(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(row, col) of world points (may fall outside the grid)."""
        col = np.floor((np.asarray(x) - self.origin[0]) / self.resolution).astype(int)
        row = np.floor((np.asarray(y) - self.origin[1]) / self.resolution).astype(int)
        return row, col


@dataclass
class World:
    name: str
    seed: int
    solids: list[Solid] = field(default_factory=list)
    water: shapely.Geometry = field(default_factory=shapely.Polygon)  # the water region
    gps_denied: shapely.Geometry = field(default_factory=shapely.Polygon)  # no fix inside
    datum: str = "amsterdam"  # GPS datum of the local frame's origin
    description: str = ""
    # Named areas for metrics, e.g. "narrow_passage" (Ueland 2017's position B) in ntnu_basin
    regions: dict = field(default_factory=dict)
    _sky_cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def bounds(self) -> tuple[float, float, float, float]:
        """xmin, ymin, xmax, ymax [m] of the water and every solid."""
        boxes = [self.water.bounds] if not self.water.is_empty else []
        if self.solids:
            c = np.array([s.bounding_circle() for s in self.solids])
            boxes.append(
                (
                    np.min(c[:, 0] - c[:, 2]),
                    np.min(c[:, 1] - c[:, 2]),
                    np.max(c[:, 0] + c[:, 2]),
                    np.max(c[:, 1] + c[:, 2]),
                )
            )
        b = np.array(boxes)
        return (
            float(b[:, 0].min()),
            float(b[:, 1].min()),
            float(b[:, 2].max()),
            float(b[:, 3].max()),
        )

    @cached_property
    def scene(self):
        """The ray-casting acceleration structure, built once."""
        return Scene.from_solids(self.solids)

    @cached_property
    def _centres(self) -> tuple[cKDTree, np.ndarray]:
        c = (
            np.array([s.bounding_circle() for s in self.solids])
            if self.solids
            else np.zeros((0, 3))
        )
        return cKDTree(c[:, :2]), c[:, 2]

    def obstacles(self, height: float = 1.0) -> list[int]:
        """Indices of solids a hull reaching ``height`` [m] above the water can touch."""
        return [i for i, s in enumerate(self.solids) if s.z_min < height and s.z_max > 0.0]

    def clearance(self, px, py, height: float = 1.0, cutoff: float = 10.0) -> np.ndarray:
        """Distance [m] from points to the nearest solid footprint (negative inside one), exact
        up to ``cutoff``; points with nothing within ``cutoff`` get ``inf``."""
        px, py = np.broadcast_arrays(np.asarray(px, float), np.asarray(py, float))
        out = np.full(px.shape, np.inf)
        if not self.solids:
            return out
        tree, radius = self._centres
        pts = np.column_stack([px.ravel(), py.ravel()])
        flat = out.ravel()
        # Each solid against only the points within its bounding radius + cutoff (farther ones
        # are > cutoff from it): a long track no longer meets every solid near any of its points.
        points = cKDTree(pts)
        near = points.query_ball_point(tree.data, r=radius + cutoff)
        for i in self.obstacles(height):
            idx = np.asarray(near[int(i)], int)
            if len(idx):
                d = self.solids[int(i)].signed_distance(pts[idx, 0], pts[idx, 1])
                flat[idx] = np.minimum(flat[idx], d)
        flat[flat > cutoff] = np.inf
        return flat.reshape(px.shape)

    def in_water(self, px, py) -> np.ndarray:
        return shapely.contains_xy(self.water, np.asarray(px, float), np.asarray(py, float))

    def is_free(self, px, py, margin: float = 0.0, height: float = 1.0) -> np.ndarray:
        """In the water region and farther than ``margin`` [m] from every solid."""
        return self.in_water(px, py) & (self.clearance(px, py, height) > margin)

    def gps_denied_at(self, px, py) -> np.ndarray:
        if self.gps_denied.is_empty:
            return np.zeros(np.broadcast(np.asarray(px), np.asarray(py)).shape, bool)
        return shapely.contains_xy(self.gps_denied, np.asarray(px, float), np.asarray(py, float))

    def sky_blocked(
        self, x: float, y: float, z: float = 2.0, elevation_deg: float = 30.0, beams: int = 72
    ) -> float:
        """Fraction of azimuths whose line of sight at ``elevation_deg`` is blocked within
        300 m: the urban-canyon measure that degrades GPS beside tall facades."""
        layout = ColumnLayout(az0=0.0, daz=2 * np.pi / beams, count=beams)
        r = cast(
            self.scene, layout, [np.tan(np.deg2rad(elevation_deg))], np.array([x, y]), z, 0.0, 300.0
        )
        return float(np.mean(np.isfinite(r)))

    def occupancy(
        self, resolution: float, height_band: tuple[float, float] = (0.0, 1.0), bounds=None
    ) -> OccupancyGrid:
        """Ground-truth grid at ``resolution`` [m]: land and solids overlapping the height band
        [m above water] are occupied, the rest of the water free."""
        if not resolution > 0:
            raise ValueError(f"occupancy: resolution must be positive, got {resolution}")
        xmin, ymin, xmax, ymax = bounds or self.bounds
        cols = int(np.ceil((xmax - xmin) / resolution))
        rows = int(np.ceil((ymax - ymin) / resolution))
        grid = OccupancyGrid(
            (xmin, ymin), resolution, np.full((rows, cols), OccupancyGrid.OCCUPIED, np.int8)
        )
        xs, ys = grid.cell_centres()
        water = shapely.contains_xy(self.water, *np.meshgrid(xs, ys))
        grid.data[water] = OccupancyGrid.FREE
        lo, hi = height_band
        for s in self.solids:
            if s.z_max < lo or s.z_min > hi:
                continue
            x, y, r = s.bounding_circle()
            c0, c1 = np.searchsorted(xs, [x - r - resolution, x + r + resolution])
            r0, r1 = np.searchsorted(ys, [y - r - resolution, y + r + resolution])
            if c0 >= c1 or r0 >= r1:
                continue
            gx, gy = np.meshgrid(xs[c0:c1], ys[r0:r1])
            inside = s.signed_distance(gx, gy) <= 0.5 * resolution  # cells the footprint touches
            grid.data[r0:r1, c0:c1][inside] = OccupancyGrid.OCCUPIED
        return grid


def hull_outline(length: float, beam: float, n_per_side: int = 4, shape: str = "box") -> np.ndarray:
    """Sample points (k × 2) on the hull outline, body frame: a ``length`` × ``beam`` rectangle,
    or for ``shape="round"`` (Ueland 2017's cone-like vessel) the circle of diameter ``length`` (the
    widest, top diameter), 8 ``n_per_side`` points."""
    if shape == "round":
        a = np.linspace(0.0, 2.0 * np.pi, 8 * n_per_side, endpoint=False)
        return 0.5 * length * np.column_stack([np.cos(a), np.sin(a)])
    t = np.linspace(-0.5, 0.5, n_per_side + 1)
    pts = [[length * a, beam / 2] for a in t] + [[length * a, -beam / 2] for a in t]
    pts += [[length / 2, beam * a] for a in t] + [[-length / 2, beam * a] for a in t]
    return np.unique(np.array(pts), axis=0)


def hull_clearance(
    world: World,
    states: np.ndarray,
    length: float,
    beam: float,
    height: float,
    shape: str = "box",
) -> np.ndarray:
    """Per state [x y ψ ...], the distance [m] from the hull outline (:func:`hull_outline`) to
    the nearest solid (negative when the hull overlaps one; inf when nothing is within 10 m)."""
    outline = hull_outline(length, beam, shape=shape)
    states = np.atleast_2d(states)
    c, s = np.cos(states[:, 2]), np.sin(states[:, 2])
    px = states[:, [0]] + c[:, None] * outline[:, 0] - s[:, None] * outline[:, 1]
    py = states[:, [1]] + s[:, None] * outline[:, 0] + c[:, None] * outline[:, 1]
    return world.clearance(px, py, height).min(axis=1)
