"""``Lidar3D``: a spinning multi-ring lidar (Velodyne VLP-16) sampled at its rotation rate."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, preset_by_name
from usvdrake.sensors.messages import PointCloud
from usvdrake.sensors.raycast import Scene

STREAM_LIDAR3D = 30


def sweep_to_cloud(
    ranges: np.ndarray, azimuths: np.ndarray, elevations: np.ndarray, column_time: np.ndarray
):
    """Valid returns of a range image as sensor-frame points, with ring, column and time."""
    ring, col = np.nonzero(np.isfinite(ranges))
    r = ranges[ring, col]
    e, a = elevations[ring], azimuths[col]
    pts = np.column_stack([r * np.cos(e) * np.cos(a), r * np.cos(e) * np.sin(a), r * np.sin(e)])
    return pts, ring, col, column_time[col]


class Lidar3D(LeafSystem):
    """Casts one full sweep every 1/rate s and holds it as a ``PointCloud``: the organised
    range image (ring × column) and the valid points in the sensor frame of their firing time.

    .. pydrake_system::

        name: Lidar3D
        input_ports:
        - state
        output_ports:
        - lidar_points
    """

    def __init__(self, cfg: LidarConfig, scene: Scene, seed: int, stream: int = STREAM_LIDAR3D):
        super().__init__()
        preset = preset_by_name(cfg.preset)
        if len(preset.elevations_deg) < 2:
            raise ValueError(f"Lidar3D: preset {cfg.preset!r} is a 2D lidar; use Lidar2D")
        self._model = LidarModel(preset, cfg, scene, seed, stream)
        self._elev = np.deg2rad(np.asarray(preset.elevations_deg))
        self._az = self._model.layout.azimuths
        empty = PointCloud(
            elevations=self._elev,
            azimuths=self._az,
            range_image=np.full((len(self._elev), len(self._az)), np.inf),
        )
        self._state = self.DeclareVectorInputPort("state", 6)
        self._cloud = self.DeclareAbstractState(AbstractValue.Make(empty))
        self._seq = self.DeclareDiscreteState(1)
        period = 1.0 / self._model.rate
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, period, self._update)
        self.DeclareStateOutputPort("lidar_points", self._cloud)

    @property
    def period(self) -> float:
        return 1.0 / self._model.rate

    def _update(self, context, state):
        k = int(context.get_discrete_state(self._seq).GetAtIndex(0))
        sweep = self._model.sweep(self._state.Eval(context), k)
        pts, ring, col, t = sweep_to_cloud(sweep.ranges, self._az, self._elev, sweep.column_time)
        cloud = PointCloud(
            time=context.get_time(),
            elevations=self._elev,
            azimuths=self._az,
            range_image=sweep.ranges,
            points=pts,
            ring=ring,
            column=col,
            point_time=t,
            sweep_time=sweep.sweep_time,
            motion_applied=self._model.cfg.motion,
        )
        state.get_mutable_abstract_state(self._cloud).set_value(cloud)
        state.get_mutable_discrete_state(self._seq).SetAtIndex(0, k + 1)
