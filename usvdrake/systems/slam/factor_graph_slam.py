"""``FactorGraphSlam``: Roboat II's lidar-IMU-GPS SLAM on iSAM2 (Roboat II §V) as a LeafSystem."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.geodesy import LocalFrame
from usvdrake.sensors.messages import GpsFix, ImuSample, PointCloud
from usvdrake.systems.slam.lidar_inertial import (
    KeyframeMap,
    LidarInertialConfig,
    LidarInertialSlam,
    planar_pose,
    pose_matrix,
)
from usvdrake.systems.slam.slam_summary import summarise_3d

# Offset of the SLAM's tick after the sensors' sample instants: the IMU, GPS and lidar update at
# multiples of their periods, so a tick 1 ms later reads the sample of that same instant.
TICK_DELAY = 1e-3  # [s]
MIN_CLOUD_POINTS = 100  # sweeps with fewer returns are skipped (the empty message before the first)


def mount_matrix(mount) -> np.ndarray:
    """T_body_lidar (4 × 4) of a lidar ``mount`` = [x y z yaw] [m, rad] (``LidarConfig``)."""
    return pose_matrix(*(float(v) for v in mount))


class FactorGraphSlam(LeafSystem):
    """Feeds the station's IMU samples, GPS fixes and lidar sweeps, in time order, to
    :class:`LidarInertialSlam` (kept in the Context) and reports the vessel's pose.

    .. pydrake_system::

        name: FactorGraphSlam
        input_ports:
        - lidar_points
        - imu
        - gps
        output_ports:
        - slam_pose
        - slam_covariance
        - slam_state
        - slam_pose3d
        - slam_map3d

    ``slam_pose`` = [x y ψ] (what the controllers use, Roboat II §V) and ``slam_state`` =
    [x y ψ u v r] (body velocities from the IMU propagation): the last keyframe's estimate
    propagated by the IMU to now. ``slam_covariance`` (9, row-major 3 × 3) of [x y ψ] at the
    last keyframe (iSAM2 marginal). ``slam_pose3d`` = [x y z roll pitch yaw] [m, rad] of the
    full state. ``slam_map3d``: the map, a :class:`KeyframeMap` (every keyframe's features,
    voxel-filtered, with its current estimate; drawn by :class:`usvdrake.viz.point_map_visualizer.
    KeyframeMapVisualizer`).

    One periodic update at the IMU's rate, ``TICK_DELAY`` after each sample, takes whatever is
    new on the three inputs (by message time): IMU first, then GPS, then a lidar sweep — so a
    sweep ending at t is predicted with the IMU up to t and can use the fix of t.
    """

    def __init__(
        self,
        config: LidarInertialConfig,
        initial_state,
        mount,
        imu_rate_hz: float,
        datum: str | None = None,
        height: float = 0.0,
    ):
        super().__init__()
        if imu_rate_hz <= 0:
            raise ValueError(f"FactorGraphSlam: the IMU rate must be positive, got {imu_rate_hz}")
        x, y, psi = (float(v) for v in np.asarray(initial_state, float)[:3])
        frame = LocalFrame(datum) if datum else None
        slam = LidarInertialSlam(config, pose_matrix(x, y, height, psi), mount_matrix(mount), frame)
        self._cloud = self.DeclareAbstractInputPort(
            "lidar_points", AbstractValue.Make(PointCloud())
        )
        self._imu = self.DeclareAbstractInputPort("imu", AbstractValue.Make(ImuSample()))
        self._gps = self.DeclareAbstractInputPort("gps", AbstractValue.Make(GpsFix()))
        self._slam = self.DeclareAbstractState(AbstractValue.Make(slam))
        # time of the last IMU sample, GPS fix and sweep taken
        self._seen = self.DeclareDiscreteState(BasicVector([-1.0, -1.0, -1.0]))
        period = 1.0 / imu_rate_hz
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, TICK_DELAY, self._update)
        deps = {self.abstract_state_ticket(self._slam)}
        self.DeclareVectorOutputPort("slam_pose", 3, self._calc_pose, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort(
            "slam_covariance", 9, self._calc_cov, prerequisites_of_calc=deps
        )
        self.DeclareVectorOutputPort("slam_state", 6, self._calc_state, prerequisites_of_calc=deps)
        self.DeclareVectorOutputPort(
            "slam_pose3d", 6, self._calc_pose3d, prerequisites_of_calc=deps
        )
        self.DeclareAbstractOutputPort(
            "slam_map3d",
            lambda: AbstractValue.Make(KeyframeMap()),
            self._calc_map,
            prerequisites_of_calc=deps,
        )
        # the run's keyframes and counts (what metrics read when the run ends)
        self.DeclareAbstractOutputPort(
            "slam_summary",
            lambda: AbstractValue.Make(summarise_3d(slam)),
            lambda context, value: value.set_value(summarise_3d(self.slam(context))),
            prerequisites_of_calc=deps,
        )

    def slam(self, context) -> LidarInertialSlam:
        return context.get_abstract_state(self._slam).get_value()

    def _update(self, context, state):
        seen = context.get_discrete_state(self._seen).CopyToVector()
        slam = state.get_mutable_abstract_state(self._slam).get_value()
        imu = self._imu.Eval(context)
        if imu.time > seen[0]:
            slam.add_imu(imu)
            seen[0] = imu.time
        fix = self._gps.Eval(context)
        if fix.time > seen[1]:
            slam.add_gps(fix)
            seen[1] = fix.time
        cloud = self._cloud.Eval(context)
        if cloud.time > seen[2] and len(cloud.points) >= MIN_CLOUD_POINTS:
            slam.add_cloud(cloud)
            seen[2] = cloud.time
        state.get_mutable_discrete_state(self._seen).SetFromVector(seen)

    def _calc_pose(self, context, output):
        output.SetFromVector(planar_pose(self.slam(context).pose()))

    def _calc_state(self, context, output):
        output.SetFromVector(self.slam(context).state())

    def _calc_cov(self, context, output):
        output.SetFromVector(self.slam(context).planar_covariance().ravel())

    def _calc_pose3d(self, context, output):
        T = self.slam(context).pose()
        R = T[:3, :3]
        roll = np.arctan2(R[2, 1], R[2, 2])
        pitch = np.arcsin(np.clip(-R[2, 0], -1.0, 1.0))
        yaw = np.arctan2(R[1, 0], R[0, 0])
        output.SetFromVector(np.r_[T[:3, 3], roll, pitch, yaw])

    def _calc_map(self, context, value):
        value.set_value(self.slam(context).keyframe_map())
