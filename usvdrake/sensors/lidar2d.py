"""``Lidar2D``: a planar scanning lidar (RPLIDAR A1, Hokuyo UTM-30LX) sampled at its scan rate."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, preset_by_name
from usvdrake.sensors.messages import LaserScan
from usvdrake.sensors.raycast import Scene

STREAM_LIDAR2D = 20


class Lidar2D(LeafSystem):
    """Casts one revolution every 1/rate s against the world and holds it as a ``LaserScan``.

    .. pydrake_system::

        name: Lidar2D
        input_ports:
        - state
        output_ports:
        - lidar_scan

    ``state`` = [x y ψ u v r] of the vessel (ground truth). Beams fire counter-clockwise from
    ``angle_min`` over the sweep that ends at the sample time; with ``motion`` each beam is cast
    from where the sensor was then. The scan and its sequence number live in the Context.
    """

    def __init__(self, cfg: LidarConfig, scene: Scene, seed: int, stream: int = STREAM_LIDAR2D):
        super().__init__()
        preset = preset_by_name(cfg.preset)
        if len(preset.elevations_deg) != 1:
            raise ValueError(f"Lidar2D: preset {cfg.preset!r} is a 3D lidar; use Lidar3D")
        self._model = LidarModel(preset, cfg, scene, seed, stream)
        layout = self._model.layout
        self._template = LaserScan(
            angle_min=layout.az0,
            angle_increment=layout.daz,
            range_min=preset.range_min,
            range_max=self._model.range_max,
            scan_time=self._model.sweep_time,
            ranges=np.full(layout.count, np.inf),
            valid=np.zeros(layout.count, bool),
        )
        self._state = self.DeclareVectorInputPort("state", 6)
        self._scan = self.DeclareAbstractState(AbstractValue.Make(self._template))
        self._seq = self.DeclareDiscreteState(1)
        period = 1.0 / self._model.rate
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, period, self._update)
        self.DeclareStateOutputPort("lidar_scan", self._scan)

    @property
    def period(self) -> float:
        return 1.0 / self._model.rate

    def _update(self, context, state):
        k = int(context.get_discrete_state(self._seq).GetAtIndex(0))
        sweep = self._model.sweep(self._state.Eval(context), k)
        r = sweep.ranges[0]
        t = self._template
        scan = LaserScan(
            time=context.get_time(),
            angle_min=t.angle_min,
            angle_increment=t.angle_increment,
            range_min=t.range_min,
            range_max=t.range_max,
            scan_time=t.scan_time,
            ranges=r,
            valid=np.isfinite(r),
        )
        state.get_mutable_abstract_state(self._scan).set_value(scan)
        state.get_mutable_discrete_state(self._seq).SetAtIndex(0, k + 1)
