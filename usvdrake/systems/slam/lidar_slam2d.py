"""``LidarSlam2D`` (Pham et al.'s sliding-window graph SLAM) and ``HectorSlam`` (Ueland 2017's
Hector-style SLAM) on the station's ``lidar_scan``: one LeafSystem shell over interchangeable
backends."""

import dataclasses

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.slam.graph_slam import GraphSlam, GraphSlamConfig, body_pose, compose
from usvdrake.systems.slam.hector import HectorConfig, make_hector
from usvdrake.systems.slam.scan_checks import usable_scan
from usvdrake.systems.slam.slam_summary import Slam2DSummary, summarise_2d
from usvdrake.worlds.world import OccupancyGrid


class LidarSlam2D(LeafSystem):
    """Feeds every new scan to a SLAM backend kept in the Context (abstract state) and reports
    the vessel's pose: the lidar's pose composed with the inverse of its mount.

    .. pydrake_system::

        name: LidarSlam2D
        input_ports:
        - lidar_scan
        - odometry (optional)
        output_ports:
        - slam_pose
        - slam_covariance
        - slam_map
        - slam_summary

    ``slam_pose`` = [x y ψ] of the vessel in the map frame (the initial pose's frame);
    ``slam_covariance`` (9, row-major 3 × 3) the backend's pose covariance; ``slam_map`` an
    :class:`OccupancyGrid` rendered on demand; ``slam_summary`` the run's
    :class:`~usvdrake.systems.slam.slam_summary.Slam2DSummary` (final estimate, counts,
    timings: what metrics read when the run ends). The update runs at the lidar's period and skips a
    scan it has already seen (by its time stamp); the backend's deferred heavy work (the graph's
    full optimisation after a loop closure) is started by a separate 1 Hz event in a worker
    process (``GraphSlamConfig.full_in_worker``) and merged by the next one, never in a scan
    update: the scans are tracked while it solves, and the result lands one event after it
    started however fast the machine is (a solve still running then is waited for), so a
    simulation stays deterministic.

    ``odometry`` (graph backend only; leave it unconnected for scan-only SLAM, as Pham et al.): the
    vessel's [x y ψ] by dead reckoning (wheel odometry, a DVL's integrated velocity) in its own
    frame; its steps, calibrated by the scans, tie the graph's nodes where the scans cannot
    measure the motion (``GraphSlamConfig.odometry_sigma``), and are left out where they
    contradict the scans (``odometry_gate``).

    A backend offers ``process_scan(scan)``, ``sensor_pose``, ``pose_covariance()``,
    ``occupancy()`` and ``background()``: :class:`GraphSlam` (here) or the Hector mapper
    (:class:`HectorSlam`).
    """

    def __init__(self, cfg: GraphSlamConfig, initial_pose, mount, period: float, backend=None):
        super().__init__()
        self._mount = np.array([mount[0], mount[1], mount[3]], float)  # x, y, yaw of the lidar
        sensor0 = compose(np.asarray(initial_pose, float), self._mount)
        graph = backend is None
        backend = GraphSlam(cfg, sensor0) if graph else backend(sensor0)
        self._scan = self.DeclareAbstractInputPort("lidar_scan", AbstractValue.Make(LaserScan()))
        # (GraphSlam only: the Hector backend has no odometry, Kohlbrecher 2011)
        self._odometry = self.DeclareVectorInputPort("odometry", 3) if graph else None
        self._slam = self.DeclareAbstractState(AbstractValue.Make(backend))
        # [time of the last scan taken [s], scans refused as insane]
        self._last = self.DeclareDiscreteState(BasicVector([-1.0, 0.0]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
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
        self.DeclareAbstractOutputPort(
            "slam_summary",
            lambda: AbstractValue.Make(Slam2DSummary()),
            self._calc_summary,
            prerequisites_of_calc=deps,
        )

    @property
    def mount(self) -> np.ndarray:
        """[x y ψ] of the lidar in the body frame: the backend's poses are the lidar's."""
        return self._mount.copy()

    def slam(self, context):
        return context.get_abstract_state(self._slam).get_value()

    def _update(self, context, state):
        raw = self._scan.Eval(context)
        last = context.get_discrete_state(self._last)
        if not raw.time > last.GetAtIndex(0):
            return  # already seen (a NaN stamp never counts as new)
        scan = usable_scan(raw)
        if scan is None:  # insane (a broken driver, a corrupted log): refused and counted
            state.get_mutable_discrete_state(self._last).SetAtIndex(1, last.GetAtIndex(1) + 1)
            state.get_mutable_discrete_state(self._last).SetAtIndex(0, raw.time)
            return
        if scan.valid.sum() < 10:
            return  # the sensor's empty message before its first sweep
        slam = state.get_mutable_abstract_state(self._slam).get_value()
        if self._odometry is not None and self._odometry.HasValue(context):
            # the lidar's pose by odometry: the backend's poses are the lidar's
            odometry = compose(np.asarray(self._odometry.Eval(context), float), self._mount)
            slam.process_scan(scan, odometry=odometry)
        else:
            slam.process_scan(scan)
        state.get_mutable_discrete_state(self._last).SetAtIndex(0, scan.time)

    def _background(self, context, state):
        state.get_mutable_abstract_state(self._slam).get_value().background()

    def _calc_pose(self, context, output):
        output.SetFromVector(body_pose(self.slam(context).sensor_pose, self._mount))

    def _calc_cov(self, context, output):
        output.SetFromVector(np.asarray(self.slam(context).pose_covariance(), float).ravel())

    def _calc_map(self, context, value):
        value.set_value(self.slam(context).occupancy())

    def _calc_summary(self, context, value):
        rejected = int(context.get_discrete_state(self._last).GetAtIndex(1))
        summary = summarise_2d(self.slam(context), self._mount)
        value.set_value(dataclasses.replace(summary, rejected_scans=rejected))


class HectorSlam(LidarSlam2D):
    """The Hector-style SLAM of Ueland 2017 (Kohlbrecher et al. 2011: multi-resolution scan-to-map
    Gauss-Newton, no odometry) behind the same ports as :class:`LidarSlam2D`."""

    def __init__(self, cfg: HectorConfig, initial_pose, mount, period: float):
        super().__init__(
            GraphSlamConfig(),
            initial_pose,
            mount,
            period,
            backend=lambda pose: make_hector(cfg, pose),
        )
