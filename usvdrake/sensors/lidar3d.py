"""``Lidar3D``: a spinning multi-ring lidar (Velodyne VLP-16) sampled at its rotation rate."""

import numpy as np

from usvdrake.sensors.lidar_model import LidarConfig, Sweep
from usvdrake.sensors.messages import PointCloud
from usvdrake.sensors.sampled_lidar import OtherVessels, SampledLidar
from usvdrake.worlds.raycast import Scene

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


def range_image_to_cloud(
    ranges: np.ndarray,
    azimuths: np.ndarray,
    elevations: np.ndarray,
    column_time: np.ndarray | None = None,
    time: float = 0.0,
    sweep_time: float = 0.0,
    motion_applied: bool = False,
) -> PointCloud:
    """A ``PointCloud`` message from a range image (rings × columns [m], inf = no return) with
    its beams' ``azimuths`` and ``elevations`` [rad]; ``column_time`` [s] per column (zeros if
    None)."""
    if column_time is None:
        column_time = np.zeros(len(azimuths))
    pts, ring, col, t = sweep_to_cloud(ranges, azimuths, elevations, column_time)
    return PointCloud(
        time=time,
        elevations=np.asarray(elevations, float),
        azimuths=np.asarray(azimuths, float),
        range_image=ranges,
        points=pts,
        ring=ring,
        column=col,
        point_time=t,
        sweep_time=sweep_time,
        motion_applied=motion_applied,
    )


class Lidar3D(SampledLidar):
    """Casts one full sweep every 1/rate s and holds it as a ``PointCloud``: the organised
    range image (ring × column) and the valid points in the sensor frame of their firing time,
    each with its ring, column and time offset (for de-skewing).

    .. pydrake_system::

        name: Lidar3D
        input_ports:
        - state
        output_ports:
        - lidar_points
    """

    def __init__(
        self,
        cfg: LidarConfig,
        scene: Scene,
        seed: int,
        stream: int = STREAM_LIDAR3D,
        others: OtherVessels | None = None,
    ):
        super().__init__(
            cfg,
            scene,
            seed,
            stream,
            three_d=True,
            port_name="lidar_points",
            empty_message=type(self).empty_message,
            make_message=type(self).make_message,
            others=others,
        )

    def empty_message(self) -> PointCloud:
        m = self._model
        elev = np.deg2rad(np.asarray(m.preset.elevations_deg))
        return PointCloud(
            elevations=elev,
            azimuths=m.layout.azimuths,
            range_image=np.full((len(elev), m.layout.count), np.inf),
            sweep_time=m.sweep_time,
            motion_applied=m.cfg.motion,
        )

    def make_message(self, sweep: Sweep, time: float) -> PointCloud:
        empty = self.empty_message()
        return range_image_to_cloud(
            sweep.ranges,
            empty.azimuths,
            empty.elevations,
            sweep.column_time,
            time,
            empty.sweep_time,
            empty.motion_applied,
        )
