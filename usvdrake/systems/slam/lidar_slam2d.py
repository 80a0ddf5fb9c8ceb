"""``LidarSlam2D``: the sliding-window graph SLAM of 002 on the station's ``lidar_scan``."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.slam.graph_slam import GraphSlam, GraphSlamConfig, between, compose
from usvdrake.worlds.world import OccupancyGrid


class LidarSlam2D(LeafSystem):
    """Feeds every new scan to :class:`GraphSlam` (kept in the Context as abstract state) and
    reports the vessel's pose: the lidar's pose composed with the inverse of its mount.

    .. pydrake_system::

        name: LidarSlam2D
        input_ports:
        - lidar_scan
        output_ports:
        - slam_pose
        - slam_covariance
        - slam_map

    ``slam_pose`` = [x y ψ] of the vessel in the map frame (the initial pose's frame);
    ``slam_covariance`` (9, row-major 3 × 3) is the Censi covariance of the latest node's
    consecutive constraint; ``slam_map`` an :class:`OccupancyGrid` rendered on demand. The update
    runs at the lidar's period and skips a scan it has already seen (by its time stamp); the
    full-graph optimisation after a loop closure runs in a separate 1 Hz event.
    """

    def __init__(self, cfg: GraphSlamConfig, initial_pose, mount, period: float):
        super().__init__()
        self._mount = np.array([mount[0], mount[1], mount[3]], float)  # x, y, yaw of the lidar
        sensor0 = compose(np.asarray(initial_pose, float), self._mount)
        self._scan = self.DeclareAbstractInputPort("lidar_scan", AbstractValue.Make(LaserScan()))
        self._slam = self.DeclareAbstractState(AbstractValue.Make(GraphSlam(cfg, sensor0)))
        self._last = self.DeclareDiscreteState(BasicVector([-1.0]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        # the heavy work (full-graph optimisation after a loop closure) has its own 1 Hz event
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0, 0.5 * period, self._background)
        deps = {self.abstract_state_ticket(self._slam)}
        self.DeclareVectorOutputPort("slam_pose", 3, self._calc_pose, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort(
            "slam_covariance", 9, self._calc_cov, prerequisites_of_calc=deps
        )
        self.DeclareAbstractOutputPort(
            "slam_map",
            lambda: AbstractValue.Make(OccupancyGrid((0.0, 0.0), 1.0, np.zeros((0, 0), np.int8))),
            self._calc_map,
            prerequisites_of_calc=deps,
        )

    def slam(self, context) -> GraphSlam:
        return context.get_abstract_state(self._slam).get_value()

    def _update(self, context, state):
        scan = self._scan.Eval(context)
        if len(scan.ranges) == 0 or scan.time <= context.get_discrete_state(self._last).GetAtIndex(
            0
        ):
            return
        slam = state.get_mutable_abstract_state(self._slam).get_value()
        a, r = scan.angles, scan.ranges
        v = scan.valid
        pts = np.column_stack([r[v] * np.cos(a[v]), r[v] * np.sin(a[v])])
        slam.process(pts, r, a, scan.time)
        state.get_mutable_discrete_state(self._last).SetAtIndex(0, scan.time)

    def _background(self, context, state):
        state.get_mutable_abstract_state(self._slam).get_value().optimise_pending()

    def _calc_pose(self, context, output):
        sensor = self.slam(context).pose
        output.SetFromVector(compose(sensor, between(self._mount, np.zeros(3))))

    def _calc_cov(self, context, output):
        slam = self.slam(context)
        cons = [c for c in slam.constraints if c.kind == "consecutive"]
        cov = cons[-1].cov if cons else np.diag(np.square(slam.cfg.min_sigma))
        output.SetFromVector(cov.ravel())

    def _calc_map(self, context, value):
        value.set_value(self.slam(context).map.to_occupancy_grid())
