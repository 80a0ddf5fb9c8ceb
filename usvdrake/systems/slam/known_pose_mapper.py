"""``KnownPoseMapper``: an occupancy grid from the lidar at a known pose — "mapping with known
poses", the ground-truth map source of the exploration loop (Ueland 2017 before its SLAM is
trusted).

With the pose from the oracle estimator it isolates the exploration and control from the SLAM
errors: the map is what a perfect SLAM would build from the same scans (same log-odds grid,
:class:`LogOddsGrid`, eqs. 15-16 of Pham et al.), not the world's full ground-truth occupancy, which
the vessel would know before looking.
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.slam.graph_slam import compose
from usvdrake.systems.slam.occupancy_mapping import LogOddsGrid
from usvdrake.worlds.world import OccupancyGrid


class KnownPoseMapper(LeafSystem):
    """Inserts every new scan at the ``state_estimate`` pose composed with the lidar mount.

    .. pydrake_system::

        name: KnownPoseMapper
        input_ports:
        - lidar_scan
        - state_estimate
        output_ports:
        - slam_pose
        - slam_covariance
        - slam_map

    Same outputs as the SLAM systems: ``slam_pose`` is the input pose, ``slam_covariance``
    zeros; the grid covers ``map_origin`` + ``map_size`` [m] at ``resolution`` [m].
    """

    def __init__(self, map_origin, map_size, resolution: float, mount, period: float, max_range):
        super().__init__()
        if not resolution > 0 or min(map_size) <= 0:
            raise ValueError("KnownPoseMapper: resolution and map_size must be positive")
        shape = (int(np.ceil(map_size[1] / resolution)), int(np.ceil(map_size[0] / resolution)))
        grid = LogOddsGrid(tuple(map_origin), resolution, shape)
        self._mount = np.array([mount[0], mount[1], mount[3]], float)
        self._max_range = float(max_range)
        self._scan = self.DeclareAbstractInputPort("lidar_scan", AbstractValue.Make(LaserScan()))
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self._grid = self.DeclareAbstractState(AbstractValue.Make(grid))
        self._last = self.DeclareDiscreteState(BasicVector([-1.0]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "slam_pose", 3, lambda c, o: o.SetFromVector(self._est.Eval(c)[:3])
        )
        self.DeclareVectorOutputPort(
            "slam_covariance", 9, lambda c, o: o.SetFromVector(np.zeros(9))
        )
        self.DeclareAbstractOutputPort(
            "slam_map",
            lambda: AbstractValue.Make(OccupancyGrid((0.0, 0.0), 1.0, np.zeros((0, 0), np.int8))),
            lambda c, v: v.set_value(
                c.get_abstract_state(self._grid).get_value().to_occupancy_grid()
            ),
            prerequisites_of_calc={self.abstract_state_ticket(self._grid)},
        )

    def _update(self, context, state):
        scan = self._scan.Eval(context)
        if scan.time <= context.get_discrete_state(self._last).GetAtIndex(0) or not scan.valid.size:
            return
        sensor = compose(np.asarray(self._est.Eval(context)[:3], float), self._mount)
        grid = state.get_mutable_abstract_state(self._grid).get_value()
        grid.insert_laser_scan(sensor, scan, min(self._max_range, scan.range_max))
        state.get_mutable_discrete_state(self._last).SetAtIndex(0, scan.time)
