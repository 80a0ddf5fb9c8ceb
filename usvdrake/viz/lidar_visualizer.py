"""``LidarVisualizer``: a lidar's returns drawn in Meshcat in the world frame (live view)."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat, Rgba
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.framework import LeafSystem

from usvdrake.sensors.lidar_model import sensor_to_world
from usvdrake.sensors.messages import LaserScan
from usvdrake.sensors.messages import PointCloud as LidarCloud

HIT_COLOR = Rgba(1.0, 0.2, 0.6, 1.0)


def to_drake_cloud(points_world: np.ndarray) -> PointCloud:
    cloud = PointCloud(len(points_world), Fields(BaseField.kXYZs))
    cloud.mutable_xyzs()[:] = points_world.T
    return cloud


class LidarVisualizer(LeafSystem):
    """Transforms the latest scan/sweep with the vessel's pose and the mount, and draws it under
    ``/lidar/<name>`` at ``rate_hz``. Meshcat recordings animate transforms, not geometry, so
    the HTML replay holds the last returns only; watch live (``usvdrake run --meshcat``).

    .. pydrake_system::

        name: LidarVisualizer
        input_ports:
        - state
        - lidar
    """

    def __init__(
        self, meshcat: Meshcat, name: str, mount: list[float], three_d: bool, rate_hz: float = 5.0
    ):
        super().__init__()
        self._meshcat, self._path, self._mount, self._3d = meshcat, f"/lidar/{name}", mount, three_d
        self._state = self.DeclareVectorInputPort("state", 6)
        model = LidarCloud() if three_d else LaserScan()
        self._lidar = self.DeclareAbstractInputPort("lidar", AbstractValue.Make(model))
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._draw)

    def _draw(self, context):
        msg = self._lidar.Eval(context)
        if self._3d:
            pts = msg.points
        else:
            xy = msg.points()
            pts = np.column_stack([xy, np.zeros(len(xy))])
        if len(pts) == 0:
            return
        world = sensor_to_world(pts, self._mount, self._state.Eval(context))
        self._meshcat.SetObject(self._path, to_drake_cloud(world), point_size=0.08, rgba=HIT_COLOR)
