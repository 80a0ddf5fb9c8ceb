"""Map processing and cost weighting for exploration (Ueland 2017 §Map Processing, §Path Planner eq.
1).

Ueland 2017 imports Hector SLAM's occupancy grid, reads each cell as occupied, free or unexplored
and prepares it for its planner in four steps (Ueland 2017 Fig. 10 a-d), all here:

1. **Coarsening** (:func:`coarsen`): the SLAM map (5 cm for the scan matcher) is reduced to the
   planning resolution (Ueland 2017 plans on a coarser grid): a planning cell is occupied when any
   of its fine cells is, free when at least ``free_fraction`` of them are seen free, else unknown.
2. **Unknown cells near the vessel are free**: the lidar never sees the water under the hull
   (the RPLIDAR's minimum range is 0.15 m), so cells within ``near_free_radius`` of the vessel
   that the map does not know are taken as free.
3. **Inflation** by ``inflation`` (Ueland 2017: 0.4 m): every cell whose centre lies within that
   distance of an occupied cell is inaccessible, so the vessel can be planned for as a point.
   Distances come from one Euclidean distance transform (``scipy.ndimage``), not a search per
   cell. An occupied cell says only that something lies somewhere in its square, so the
   clearance is the distance to the nearest occupied *centre* less the square's half-diagonal,
   edt − resolution/√2: never more than the distance to any point of that square (triangle
   inequality), so inflating by it is safe.
4. **Reachability**: free cells not 8-connected to the vessel's cell are dropped.

The weight of each remaining cell is Ueland 2017 eq. (1), w = 1 + 5 / (0.1 + d_obj), with d_obj [m]
the distance from the cell's centre to the closest occupied cell's centre (Ueland 2017's
definition), from the same transform; the planner integrates w along its path, so it prefers to keep
away from objects.
"""

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from usvdrake.worlds.world import OccupancyGrid

EIGHT = np.ones((3, 3), dtype=bool)  # 8-connectivity for labelling and dilation
DEFAULT_INFLATION = 0.4  # [m] Ueland 2017 §Map Processing: "the inflation distance is set to 0.4 m"
WEIGHT_GAIN = 5.0  # [m] Ueland 2017 eq. (1): w = 1 + 5 / (0.1 + d_obj)
WEIGHT_OFFSET = 0.1  # [m] Ueland 2017 eq. (1)


def cost_weight(d_obj: np.ndarray, gain: float = WEIGHT_GAIN, offset: float = WEIGHT_OFFSET):
    """Ueland 2017 eq. (1): the cost of crossing a cell whose centre is ``d_obj`` [m] from the
    nearest occupied cell, w = 1 + gain / (offset + d_obj); w → 1 far from everything."""
    return 1.0 + gain / (offset + np.asarray(d_obj, dtype=float))


def coarsen(grid: OccupancyGrid, resolution: float, free_fraction: float = 0.5) -> OccupancyGrid:
    """``grid`` at the coarser ``resolution`` [m], an integer multiple k of its own (a
    ValueError otherwise). Each coarse cell covers k × k fine cells (the grid is padded with
    unknown to a multiple of k): occupied if any is occupied, free if at least
    ``free_fraction`` of them are free, unknown otherwise."""
    ratio = resolution / grid.resolution
    k = int(round(ratio))
    if k < 1 or abs(ratio - k) > 1e-6:
        raise ValueError(
            f"coarsen: the planning resolution {resolution} m must be a whole multiple of the "
            f"map's {grid.resolution} m"
        )
    if k == 1:
        return grid
    rows, cols = grid.data.shape
    pr, pc = -rows % k, -cols % k
    data = np.pad(grid.data, ((0, pr), (0, pc)), constant_values=OccupancyGrid.UNKNOWN)
    blocks = data.reshape(data.shape[0] // k, k, data.shape[1] // k, k)
    occupied = (blocks == OccupancyGrid.OCCUPIED).any(axis=(1, 3))
    free = (blocks == OccupancyGrid.FREE).sum(axis=(1, 3)) >= free_fraction * k * k
    out = np.full(occupied.shape, OccupancyGrid.UNKNOWN, dtype=np.int8)
    out[free] = OccupancyGrid.FREE
    out[occupied] = OccupancyGrid.OCCUPIED
    return OccupancyGrid(grid.origin, resolution, out)


@dataclass
class PlanningMap:
    """A processed map: what the planner and the frontier explorer work on.

    Arrays are (rows = y, cols = x) like :class:`OccupancyGrid`; ``traversable`` = free,
    outside the inflation and reachable from ``start``; ``unknown`` = not seen by the map (after
    the near-vessel rule); ``clearance`` [m] a lower bound on the distance to anything in an
    occupied cell (inf with no occupied cell); ``weights`` Ueland 2017 eq. (1) on it.
    """

    origin: tuple[float, float]
    resolution: float
    traversable: np.ndarray
    unknown: np.ndarray
    occupied: np.ndarray
    clearance: np.ndarray
    weights: np.ndarray
    start: tuple[int, int]  # the vessel's cell, snapped to the nearest traversable one

    @property
    def shape(self) -> tuple[int, int]:
        return self.traversable.shape

    def to_cell(self, xy) -> tuple[int, int]:
        """(row, col) of a world point (not clipped to the grid)."""
        col = int(np.floor((xy[0] - self.origin[0]) / self.resolution))
        row = int(np.floor((xy[1] - self.origin[1]) / self.resolution))
        return row, col

    def cell_centres(self, cells) -> np.ndarray:
        """World (x, y) [m] of the centres of (row, col) cells, shape (n, 2)."""
        cells = np.atleast_2d(np.asarray(cells, dtype=float))
        x = self.origin[0] + (cells[:, 1] + 0.5) * self.resolution
        y = self.origin[1] + (cells[:, 0] + 0.5) * self.resolution
        return np.column_stack([x, y])

    def inside(self, cell) -> bool:
        rows, cols = self.shape
        return 0 <= cell[0] < rows and 0 <= cell[1] < cols


class VesselOffMapError(RuntimeError):
    """The vessel is outside the map, or no traversable cell lies within reach of it."""


def _disc(radius_cells: float) -> np.ndarray:
    n = int(np.ceil(radius_cells))
    r, c = np.mgrid[-n : n + 1, -n : n + 1]
    return r * r + c * c <= radius_cells * radius_cells


def process_map(
    grid: OccupancyGrid,
    vessel_xy,
    inflation: float = DEFAULT_INFLATION,
    near_free_radius: float = 0.6,
    max_snap: float = 1.0,
) -> PlanningMap:
    """Ueland 2017 §Map Processing on ``grid`` (steps 2-4 of the module docstring) for a vessel at
    ``vessel_xy`` [m]. When the vessel's own cell is not traversable (it drifted into the
    inflation) the start is the nearest traversable cell within ``max_snap`` [m];
    :class:`VesselOffMapError` if there is none or the vessel is off the map."""
    if inflation < 0 or near_free_radius < 0 or max_snap < 0:
        raise ValueError(
            f"process_map: inflation, near_free_radius and max_snap must be ≥ 0, got "
            f"{inflation}, {near_free_radius}, {max_snap}"
        )
    res = grid.resolution
    data = np.asarray(grid.data)
    rows, cols = data.shape
    col = int(np.floor((vessel_xy[0] - grid.origin[0]) / res))
    row = int(np.floor((vessel_xy[1] - grid.origin[1]) / res))
    if not (0 <= row < rows and 0 <= col < cols):
        raise VesselOffMapError(
            f"process_map: the vessel at ({vessel_xy[0]:.2f}, {vessel_xy[1]:.2f}) m is outside "
            f"the {cols}×{rows} map at origin {tuple(grid.origin)}"
        )
    occupied = data == OccupancyGrid.OCCUPIED
    unknown = data == OccupancyGrid.UNKNOWN
    # Step 2: unknown cells whose centre is within near_free_radius of the vessel are free.
    yy, xx = np.ogrid[:rows, :cols]
    cx = grid.origin[0] + (xx + 0.5) * res - vessel_xy[0]
    cy = grid.origin[1] + (yy + 0.5) * res - vessel_xy[1]
    near = cx * cx + cy * cy <= near_free_radius * near_free_radius
    unknown = unknown & ~near
    free = ~occupied & ~unknown
    # Step 3: distance to the edge of the nearest occupied cell; inflation.
    if occupied.any():
        edt = ndimage.distance_transform_edt(~occupied)
        clearance = np.maximum(edt * res - res / np.sqrt(2.0), 0.0)
        clearance[occupied] = 0.0
        d_obj = edt * res  # Ueland 2017 eq. (1): centre to the closest occupied cell's centre
    else:
        clearance = d_obj = np.full(data.shape, np.inf)
    open_cells = free & (clearance > inflation)
    # Step 4: the 8-connected component of the vessel's (snapped) cell.
    start = (row, col)
    if not open_cells[start]:
        reach = max_snap / res
        candidates = np.argwhere(open_cells)
        if len(candidates):
            d2 = ((candidates - np.array(start)) ** 2).sum(axis=1)
            best = int(np.argmin(d2))
            if d2[best] <= reach * reach:
                start = (int(candidates[best, 0]), int(candidates[best, 1]))
        if start == (row, col):
            raise VesselOffMapError(
                f"process_map: no traversable cell within {max_snap} m of the vessel at "
                f"({vessel_xy[0]:.2f}, {vessel_xy[1]:.2f}) m"
            )
    labels, _ = ndimage.label(open_cells, structure=EIGHT)
    traversable = labels == labels[start]
    weights = cost_weight(d_obj)
    return PlanningMap(grid.origin, res, traversable, unknown, occupied, clearance, weights, start)


def frontier_cells(pmap: PlanningMap, min_cluster: int = 3) -> np.ndarray:
    """Frontier cells (Ueland 2017 §Exploration Strategy step 1; Yamauchi 1997): traversable cells
    with an unknown 8-neighbour, as an (n, 2) (row, col) array. Frontiers are grouped 8-connected
    and groups smaller than ``min_cluster`` cells are dropped: a gap of a cell or two between seen
    cells is lidar sparsity, not unexplored space worth a trip."""
    touches_unknown = ndimage.binary_dilation(pmap.unknown, structure=EIGHT)
    frontier = pmap.traversable & touches_unknown
    if min_cluster > 1 and frontier.any():
        labels, n = ndimage.label(frontier, structure=EIGHT)
        sizes = np.bincount(labels.ravel(), minlength=n + 1)
        keep = sizes >= min_cluster
        keep[0] = False
        frontier = keep[labels]
    return np.argwhere(frontier)


def disc_mask(shape: tuple[int, int], cells: np.ndarray, radius_cells: float) -> np.ndarray:
    """A bool mask of ``shape`` that is True within ``radius_cells`` of any of ``cells``."""
    mask = np.zeros(shape, dtype=bool)
    cells = np.asarray(cells, dtype=int).reshape(-1, 2)
    inside = (cells[:, 0] >= 0) & (cells[:, 0] < shape[0]) & (cells[:, 1] >= 0)
    inside &= cells[:, 1] < shape[1]
    mask[cells[inside, 0], cells[inside, 1]] = True
    if radius_cells > 0 and mask.any():
        mask = ndimage.binary_dilation(mask, structure=_disc(radius_cells))
    return mask
