"""Draw a :class:`~usvdrake.worlds.World` in Meshcat (static geometry under ``/world``)."""

import numpy as np
from pydrake.geometry import Box as MeshcatBox
from pydrake.geometry import Meshcat, Rgba
from pydrake.math import RigidTransform, RotationMatrix

from usvdrake.worlds.world import World

COLORS = {
    "quay": Rgba(0.55, 0.45, 0.38, 1.0),
    "wall": Rgba(0.45, 0.40, 0.36, 1.0),
    "bridge": Rgba(0.30, 0.30, 0.32, 1.0),
    "boat": Rgba(0.90, 0.92, 0.95, 1.0),
    "water": Rgba(0.15, 0.40, 0.65, 0.85),
}
FACADES = [
    Rgba(0.62, 0.32, 0.25, 1.0),
    Rgba(0.72, 0.60, 0.45, 1.0),
    Rgba(0.50, 0.45, 0.42, 1.0),
    Rgba(0.80, 0.76, 0.68, 1.0),
]


def draw_world(meshcat: Meshcat, world: World) -> None:
    meshcat.Delete("/world")
    meshcat.SetProperty("/Grid", "visible", False)
    xmin, ymin, xmax, ymax = world.bounds
    ground = RigidTransform([(xmin + xmax) / 2, (ymin + ymax) / 2, -0.06])
    meshcat.SetObject(
        "/world/ground", MeshcatBox(xmax - xmin, ymax - ymin, 0.02), Rgba(0.35, 0.37, 0.33, 1.0)
    )
    meshcat.SetTransform("/world/ground", ground)
    for i, w in enumerate(world.water):
        path = f"/world/water/{i}"
        meshcat.SetObject(path, MeshcatBox(w.lx, w.ly, 0.02), COLORS["water"])
        meshcat.SetTransform(
            path, RigidTransform(RotationMatrix.MakeZRotation(w.yaw), [w.x, w.y, -0.011])
        )
    counts: dict[str, int] = {}
    for b in world.boxes:
        k = counts.get(b.kind, 0)
        counts[b.kind] = k + 1
        path = f"/world/{b.kind}/{k}"
        color = (
            FACADES[k % len(FACADES)]
            if b.kind == "building"
            else COLORS.get(b.kind, Rgba(0.6, 0.6, 0.6, 1))
        )
        meshcat.SetObject(path, MeshcatBox(b.lx, b.ly, b.z_max - b.z_min), color)
        centre = [b.x, b.y, (b.z_min + b.z_max) / 2]
        meshcat.SetTransform(path, RigidTransform(RotationMatrix.MakeZRotation(b.yaw), centre))


def look_at(meshcat: Meshcat, target: np.ndarray, distance: float) -> None:
    """Put the camera behind-above ``target`` (a 3-vector) at roughly ``distance`` [m]."""
    eye = np.asarray(target, float) + distance * np.array([-0.75, -0.35, 0.55])
    meshcat.SetCameraPose(eye, np.asarray(target, float))
