"""``KeyframeMapVisualizer``: the 3D SLAM's map (:class:`KeyframeMap`) drawn in Meshcat."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat
from pydrake.math import RigidTransform
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.framework import LeafSystem

from usvdrake.systems.slam.lidar_inertial import KeyframeMap


def height_colors(z: np.ndarray, low: float = -1.0, high: float = 8.0) -> np.ndarray:
    """RGB (3 × N, uint8) of heights z [m]: blue at ``low`` through green to yellow at ``high``
    (the quay, the façades and the bridges tell apart at a glance)."""
    u = np.clip((np.asarray(z, dtype=float) - low) / (high - low), 0.0, 1.0)
    r = np.clip(2.0 * u - 1.0, 0.0, 1.0)
    g = np.clip(2.0 * u, 0.0, 1.0)
    b = np.clip(1.0 - 2.0 * u, 0.0, 1.0)
    return (255 * np.vstack([r, g, b])).astype(np.uint8)


class KeyframeMapVisualizer(LeafSystem):
    """Draws a :class:`KeyframeMap` under ``path`` at ``rate_hz``: one point cloud per keyframe,
    in its own frame, created once; each publish only moves the keyframes whose estimate changed
    by more than ``tolerance`` [m] or [rad] (loop closures and GPS factors bend the map and the
    drawing follows). Meshcat recordings animate transforms, so the HTML replay shows the map
    settling too; geometry appears in it as first drawn.

    .. pydrake_system::

        name: KeyframeMapVisualizer
        input_ports:
        - map
    """

    def __init__(
        self,
        meshcat: Meshcat,
        path: str = "/slam/map3d",
        rate_hz: float = 1.0,
        point_size: float = 0.1,
        tolerance: float = 0.01,
    ):
        super().__init__()
        if rate_hz <= 0:
            raise ValueError(f"KeyframeMapVisualizer: rate_hz must be positive, got {rate_hz}")
        self._meshcat, self._path = meshcat, path
        self._point_size, self._tolerance = point_size, tolerance
        self._map = self.DeclareAbstractInputPort("map", AbstractValue.Make(KeyframeMap()))
        self._drawn = np.zeros((0, 4, 4))  # poses the keyframes are drawn at
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._draw)
        self.DeclareForcedPublishEvent(self._draw)  # ForcedPublish draws now (notebooks)

    def _draw(self, context):
        m = self._map.Eval(context)
        n_old = len(self._drawn)
        for i in range(n_old, len(m)):  # new keyframes: their geometry, once
            pts = m.clouds[i]
            cloud = PointCloud(len(pts), Fields(BaseField.kXYZs | BaseField.kRGBs))
            cloud.mutable_xyzs()[:] = pts.T
            cloud.mutable_rgbs()[:] = height_colors(pts[:, 2] + m.poses[i][2, 3])
            self._meshcat.SetObject(f"{self._path}/{i}", cloud, point_size=self._point_size)
        old = m.poses[: min(n_old, len(m))]
        moved = np.abs(old - self._drawn[: len(old)]).reshape(len(old), 16).max(axis=1, initial=0)
        for i in [*np.flatnonzero(moved > self._tolerance), *range(n_old, len(m))]:
            self._meshcat.SetTransform(f"{self._path}/{i}", RigidTransform(m.poses[i]))
        self._drawn = m.poses.copy()
