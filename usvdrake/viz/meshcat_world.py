"""Draw a :class:`~usvdrake.worlds.World` in Meshcat under ``/world``: one merged triangle mesh
per kind of solid (quay, building, ...), the water region, and the GPS-denied zones."""

import numpy as np
import shapely
from pydrake.geometry import Meshcat, Rgba
from scipy.spatial import ConvexHull, HalfspaceIntersection

from usvdrake.viz.lidar_visualizer import to_drake_cloud
from usvdrake.worlds.solids import Solid
from usvdrake.worlds.world import World

COLORS = {
    "quay": Rgba(0.55, 0.45, 0.38, 1.0),
    "wall": Rgba(0.62, 0.62, 0.60, 1.0),
    "bridge": Rgba(0.30, 0.30, 0.32, 1.0),
    "boat": Rgba(0.90, 0.92, 0.95, 1.0),
    "building": Rgba(0.66, 0.38, 0.28, 1.0),
    "rock": Rgba(0.48, 0.46, 0.44, 1.0),
    "tree": Rgba(0.20, 0.42, 0.18, 1.0),
    "bush": Rgba(0.28, 0.52, 0.22, 1.0),
    "leaf": Rgba(0.45, 0.62, 0.25, 1.0),
    "bank": Rgba(0.45, 0.40, 0.30, 1.0),
}
FACADES = [
    Rgba(0.62, 0.32, 0.25, 1.0),
    Rgba(0.72, 0.60, 0.45, 1.0),
    Rgba(0.50, 0.45, 0.42, 1.0),
    Rgba(0.80, 0.76, 0.68, 1.0),
    Rgba(0.42, 0.22, 0.18, 1.0),
]
WATER = Rgba(0.30, 0.55, 0.80, 0.9)
DENIED = Rgba(1.0, 0.1, 0.1, 0.25)


def solid_mesh(s: Solid) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n × 3) and outward triangles (m × 3) of a solid."""
    foot = s.footprint(16)
    if s.cut is None:
        k = len(foot)
        v = np.vstack(
            [
                np.column_stack([foot, np.full(k, s.z_min)]),
                np.column_stack([foot, np.full(k, s.z_max)]),
            ]
        )
        i = np.arange(k)
        j = (i + 1) % k
        sides = np.vstack([np.column_stack([i, j, j + k]), np.column_stack([i, j + k, i + k])])
        fan = np.arange(1, k - 1)
        top = np.column_stack([np.full(k - 2, k), fan + k, fan + k + 1])
        bottom = np.column_stack([np.zeros(k - 2, int), fan + 1, fan])
        return v, np.vstack([sides, top, bottom])
    n, d = s.edge_planes()
    planes = [np.append(ni, 0.0) for ni in n] + [
        np.array([0, 0, -1.0]),
        np.array([0, 0, 1.0]),
        np.array(s.cut[:3]),
    ]
    offsets = list(d) + [-s.z_min, s.z_max, s.cut[3]]
    halfspaces = np.column_stack([np.array(planes), -np.array(offsets)])
    centre = np.append(foot.mean(axis=0), 0.0)
    # an interior point: lowest corner region of the footprint centroid column
    best = max(
        np.linspace(s.z_min, s.z_max, 21)[1:-1],
        key=lambda z: np.min(np.array(offsets) - np.array(planes) @ np.append(centre[:2], z)),
    )
    hs = HalfspaceIntersection(halfspaces, np.append(centre[:2], best))
    hull = ConvexHull(hs.intersections)
    v, f = hull.points, hull.simplices.copy()
    mid = v.mean(axis=0)
    normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    flip = np.einsum("ij,ij->i", normal, v[f].mean(axis=1) - mid) < 0
    f[flip] = f[flip][:, ::-1]
    return v, f


def merged_mesh(solids: list[Solid]) -> tuple[np.ndarray, np.ndarray]:
    verts, faces, base = [], [], 0
    for s in solids:
        v, f = solid_mesh(s)
        verts.append(v)
        faces.append(f + base)
        base += len(v)
    return np.vstack(verts), np.vstack(faces)


def _polygon_mesh(geom, z: float) -> tuple[np.ndarray, np.ndarray] | None:
    tris = shapely.constrained_delaunay_triangles(geom)
    parts = [np.asarray(t.exterior.coords)[:3] for t in tris.geoms] if not tris.is_empty else []
    if not parts:
        return None
    pts = np.vstack(parts)
    v = np.column_stack([pts, np.full(len(pts), z)])
    f = np.arange(len(pts)).reshape(-1, 3)
    ccw = (v[f[:, 1], 0] - v[f[:, 0], 0]) * (v[f[:, 2], 1] - v[f[:, 0], 1]) - (
        v[f[:, 1], 1] - v[f[:, 0], 1]
    ) * (v[f[:, 2], 0] - v[f[:, 0], 0]) > 0
    f[~ccw] = f[~ccw][:, ::-1]
    return v, f


def draw_world(meshcat: Meshcat, world: World, show_gps_denied: bool = True) -> None:
    meshcat.Delete("/world")
    meshcat.SetProperty("/Grid", "visible", False)
    xmin, ymin, xmax, ymax = world.bounds
    ground = shapely.box(xmin - 10, ymin - 10, xmax + 10, ymax + 10)
    mesh = _polygon_mesh(ground, -0.05)
    meshcat.SetTriangleMesh("/world/ground", mesh[0].T, mesh[1].T, Rgba(0.62, 0.62, 0.58, 1.0))
    mesh = _polygon_mesh(world.water, 0.0) if not world.water.is_empty else None
    if mesh is not None:
        meshcat.SetTriangleMesh("/world/water", mesh[0].T, mesh[1].T, WATER)
    kinds = sorted({s.kind for s in world.solids})
    for kind in kinds:
        v, f = merged_mesh([s for s in world.solids if s.kind == kind])
        meshcat.SetTriangleMesh(
            f"/world/{kind}", v.T, f.T, COLORS.get(kind, Rgba(0.6, 0.6, 0.6, 1.0))
        )
    if show_gps_denied and not world.gps_denied.is_empty:
        mesh = _polygon_mesh(world.gps_denied, 0.03)
        meshcat.SetTriangleMesh("/world/gps_denied", mesh[0].T, mesh[1].T, DENIED)


def draw_occupancy(meshcat: Meshcat, grid, path: str = "/world/occupancy") -> None:
    """Occupied cells of an :class:`~usvdrake.worlds.world.OccupancyGrid` as points at z = 0.05."""
    rows, cols = np.nonzero(grid.data == grid.OCCUPIED)
    xs, ys = grid.cell_centres()
    pts = np.column_stack([xs[cols], ys[rows], np.full(len(rows), 0.05)])
    meshcat.SetObject(
        path, to_drake_cloud(pts), point_size=grid.resolution, rgba=Rgba(0.9, 0.1, 0.1, 0.6)
    )


def view_bounds(points) -> tuple[float, float, float, float]:
    """``(xmin, ymin, xmax, ymax)`` of the (x, y) ``points`` with a margin around them."""
    xy = np.asarray(points, float).reshape(-1, 2)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    margin = max(5.0, 0.08 * float(np.max(hi - lo)))
    return lo[0] - margin, lo[1] - margin, hi[0] + margin, hi[1] + margin


def frame_view(
    meshcat: Meshcat, bounds, elevation_deg: float = 70.0, fov_deg: float = 75.0, aspect=1.4
) -> None:
    """Aim the camera high and oblique so the whole ``(xmin, ymin, xmax, ymax)`` box is in view
    (``fov_deg``: Meshcat's vertical field of view; ``aspect``: the narrowest window width/height
    it is framed for). The box's longer side runs across the screen."""
    xmin, ymin, xmax, ymax = bounds
    centre = np.array([(xmin + xmax) / 2, (ymin + ymax) / 2, 0.0])
    corners = np.array([[x, y, 0.0] for x in (xmin, xmax) for y in (ymin, ymax)])
    el = np.radians(elevation_deg)
    back = np.array([0.0, -1.0]) if xmax - xmin >= ymax - ymin else np.array([1.0, 0.0])
    towards = np.array([*(np.cos(el) * back), np.sin(el)])  # unit, from the centre to the eye
    right = np.cross(-towards, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -towards)
    tan_v = np.tan(np.radians(fov_deg) / 2)

    def fits(distance: float) -> bool:
        rel = corners - (centre + distance * towards)
        depth = rel @ -towards
        return bool(
            np.all(depth > 0)
            and np.all(np.abs(rel @ right) <= depth * tan_v * aspect)
            and np.all(np.abs(rel @ up) <= depth * tan_v)
        )

    distance = 1.0
    while not fits(distance) and distance < 1e5:
        distance *= 1.05
    meshcat.SetCameraPose(centre + distance * towards, centre)
    # Meshcat's camera sees 0.01 to 100 m: a harbour-sized view needs a farther far plane (and a
    # nearer-is-coarser near plane, for depth precision between the water and the lines on it)
    camera = "/Cameras/default/rotated/<object>"
    meshcat.SetProperty(camera, "far", max(100.0, 3.0 * distance))
    meshcat.SetProperty(camera, "near", float(np.clip(distance / 2000, 0.01, 0.5)))


def light_scene(meshcat: Meshcat) -> None:
    """A light background and even daylight: Drake's point lights sit near the origin and make
    a dark scene with glare spots at the scale of a harbour."""
    meshcat.SetProperty("/Background", "top_color", [0.97, 0.97, 0.96])
    meshcat.SetProperty("/Background", "bottom_color", [0.86, 0.87, 0.86])
    for light in ("PointLightNegativeX", "PointLightPositiveX", "SpotLight"):
        meshcat.SetProperty(f"/Lights/{light}", "visible", False)
    meshcat.SetProperty("/Lights/AmbientLight/<object>", "intensity", 2.2)
    meshcat.SetProperty("/Lights/FillLight/<object>", "intensity", 1.2)
