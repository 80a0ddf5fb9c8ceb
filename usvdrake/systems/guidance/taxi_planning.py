"""Seeing the other boats and planning around them: the taxi pilot's numerical core.

Roboat II plans its paths with A* on a map and tracks them with its NMPC (Roboat II §III); the map
knows the quays, bridges and moored boats but not the other taxis, which the vessel only sees
through its lidar. This module turns a sweep into the other vessels and the A* grid into one
that keeps clear of them:

* :func:`detect_vessels`: returns in the hull's height band whose distance to the mapped
  obstacles is more than ``static_margin`` are not the map: they are clustered (single linkage
  at ``link`` m) into discs (centre, radius). Quays, facades and moored boats are the map.
* :func:`grid_around`: the planning grid with each disc added as an obstacle, grown by the
  separation to keep, and shifted towards the planning vessel's port side so that A*'s
  shortest way round is to starboard: two boats meeting head-on both turn to starboard and
  pass port to port (COLREG rule 14), instead of mirroring each other into the same side.
* :func:`path_conflicts`: whether the reference for the next seconds comes within the keep-out
  distance of a detected vessel (then the pilot replans).
"""

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from usvdrake.systems.guidance.grid_astar import PlanningGrid
from usvdrake.worlds.world import OccupancyGrid


@dataclass(frozen=True)
class Blob:
    """A detected vessel: disc centre [m] and radius [m] around its returns."""

    centre: np.ndarray
    radius: float


def detect_vessels(
    points_world: np.ndarray,
    static: PlanningGrid,
    static_margin: float = 1.0,
    z_band: tuple[float, float] = (-0.2, 1.8),
    link: float = 1.5,
    min_points: int = 3,
) -> list[Blob]:
    """Discs around the returns (n × 3, world) that the static map does not explain.

    ``static``: a grid of the mapped obstacles (its clearance is the distance to them);
    ``static_margin`` [m]: returns closer than this to a mapped obstacle belong to it;
    ``z_band`` [m above water]: hull heights (bridge decks and facades above are ignored);
    ``link`` [m]: returns closer than this are one object; ``min_points``: smaller clusters are
    noise. A disc's radius reaches its farthest return (at least 0.5 m).
    """
    p = np.asarray(points_world, float).reshape(-1, 3)
    p = p[(p[:, 2] >= z_band[0]) & (p[:, 2] <= z_band[1])]
    if len(p) == 0:
        return []
    p = p[static.clearance_at(p[:, :2]) > static_margin]
    if len(p) < min_points:
        return []
    xy = p[:, :2]
    pairs = cKDTree(xy).query_pairs(link, output_type="ndarray")
    n = len(xy)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    count, label = connected_components(graph, directed=False)
    blobs = []
    for k in range(count):
        members = xy[label == k]
        if len(members) < min_points:
            continue
        centre = members.mean(axis=0)
        radius = max(0.5, float(np.max(np.hypot(*(members - centre).T))))
        blobs.append(Blob(centre, radius))
    return blobs


def grid_around(
    static: PlanningGrid,
    blobs: list[Blob],
    own_pose,
    separation: float,
    port_shift: float,
    keep_free=(),
) -> PlanningGrid:
    """``static`` with each blob as an obstacle of radius (its radius + its hidden far side +
    ``separation`` + ``port_shift``) [m], centred ``port_shift`` [m] to the port side of the
    planning vessel's heading (own_pose = [x y ψ]); inflated as ``static`` is. Blobs whose
    obstacle would cover a point of ``keep_free`` (the vessel itself, its goal) are left out:
    the pilot holds for those instead of planning through them."""
    occ = static.occupancy
    data = occ.data.copy()
    psi = float(own_pose[2])
    port = np.array([-np.sin(psi), np.cos(psi)])
    res = occ.resolution
    rows, cols = data.shape
    for b in blobs:
        # the lidar sees one side of a hull: its far side is up to one more radius away
        centre = b.centre + port_shift * port
        # grown by the shift too: on the starboard side the full separation remains, so a path
        # planned here keeps clear of :func:`keep_out` (inflation ≥ own hull radius)
        r = 2.0 * b.radius + separation + port_shift
        if any(np.hypot(*(np.asarray(f) - centre)) < r + static.inflation for f in keep_free):
            continue
        r0, c0 = occ.to_cell(centre[0] - r, centre[1] - r)
        r1, c1 = occ.to_cell(centre[0] + r, centre[1] + r)
        rr, cc = np.mgrid[max(r0, 0) : min(r1 + 1, rows), max(c0, 0) : min(c1 + 1, cols)]
        ox, oy = occ.origin
        x = ox + (cc + 0.5) * res
        y = oy + (rr + 0.5) * res
        inside = np.hypot(x - centre[0], y - centre[1]) <= r
        data[rr[inside], cc[inside]] = OccupancyGrid.OCCUPIED
    return PlanningGrid.from_occupancy(OccupancyGrid(occ.origin, res, data), static.inflation)


def keep_out(blob: Blob, own_radius: float, separation: float) -> float:
    """Centre distance [m] within which the planning vessel would come closer than
    ``separation`` to the hull behind ``blob`` (far side up to one more radius away)."""
    return 2.0 * blob.radius + own_radius + separation


def path_conflicts(
    positions: np.ndarray, blobs: list[Blob], own_radius: float, separation: float
) -> bool:
    """Whether any of the reference ``positions`` (n × 2) [m] comes within the keep-out
    distance of a blob."""
    pos = np.asarray(positions, float).reshape(-1, 2)
    for b in blobs:
        if np.any(np.hypot(*(pos - b.centre).T) < keep_out(b, own_radius, separation)):
            return True
    return False


def ahead_within(pose, blobs: list[Blob], distance: float, half_angle: float) -> bool:
    """Whether a blob's nearest edge is within ``distance`` [m] of the vessel and inside
    ±``half_angle`` [rad] of its heading (pose = [x y ψ])."""
    x, y, psi = (float(v) for v in pose[:3])
    for b in blobs:
        d = b.centre - (x, y)
        rng = float(np.hypot(*d)) - b.radius
        bearing = np.arctan2(d[1], d[0]) - psi
        bearing = (bearing + np.pi) % (2 * np.pi) - np.pi
        if rng < distance and abs(bearing) < half_angle:
            return True
    return False
