"""``Lidar2D``: a planar scanning lidar (RPLIDAR A1, Hokuyo UTM-30LX) sampled at its scan rate."""

import numpy as np

from usvdrake.sensors.lidar_model import LidarConfig, Sweep
from usvdrake.sensors.messages import LaserScan
from usvdrake.sensors.sampled_lidar import OtherVessels, SampledLidar
from usvdrake.worlds.raycast import Scene

STREAM_LIDAR2D = 20


class Lidar2D(SampledLidar):
    """Casts one revolution every 1/rate s against the world and holds it as a ``LaserScan``.

    .. pydrake_system::

        name: Lidar2D
        input_ports:
        - state
        output_ports:
        - lidar_scan

    ``state`` = [x y ψ u v r] of the vessel (ground truth). Beams fire counter-clockwise from
    ``angle_min`` over the sweep that ends at the sample time; with ``motion`` each beam is cast
    from where the sensor was then. No-return beams are flagged invalid with range inf.
    """

    def __init__(
        self,
        cfg: LidarConfig,
        scene: Scene,
        seed: int,
        stream: int = STREAM_LIDAR2D,
        others: OtherVessels | None = None,
    ):
        super().__init__(
            cfg,
            scene,
            seed,
            stream,
            three_d=False,
            port_name="lidar_scan",
            empty_message=type(self).empty_message,
            make_message=type(self).make_message,
            others=others,
        )

    def empty_message(self) -> LaserScan:
        m = self._model
        return LaserScan(
            angle_min=m.layout.az0,
            angle_increment=m.layout.daz,
            range_min=m.preset.range_min,
            range_max=m.range_max,
            scan_time=m.sweep_time,
            # the beams fire along the sweep only when the sweep's own motion is simulated
            time_increment=float(m.column_time[1] - m.column_time[0])
            if m.cfg.motion and len(m.column_time) > 1
            else 0.0,
            ranges=np.full(m.layout.count, np.inf),
            valid=np.zeros(m.layout.count, bool),
        )

    def make_message(self, sweep: Sweep, time: float) -> LaserScan:
        scan = self.empty_message()
        scan.time, scan.ranges, scan.valid = time, sweep.ranges[0], np.isfinite(sweep.ranges[0])
        return scan
