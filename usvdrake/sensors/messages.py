"""Sensor messages carried on the station's abstract output ports (DESIGN.md).

Plain dataclasses with numpy arrays; every message says when it was measured (``time`` [s],
simulation or host clock) so estimators can align them.
"""

from dataclasses import dataclass, field

import numpy as np


@dataclass
class LaserScan:
    """A 2D scan (``lidar_scan``), like ROS sensor_msgs/LaserScan. Beam i points at
    ``angle_min + i * angle_increment`` [rad] in the sensor frame (x forward, y left).
    No-return beams have ``valid[i] = False`` and ``ranges[i] = inf`` — never 0."""

    time: float = 0.0  # [s] time of the last beam
    angle_min: float = 0.0  # [rad]
    angle_increment: float = 0.0  # [rad]
    range_min: float = 0.0  # [m]
    range_max: float = 0.0  # [m]
    scan_time: float = 0.0  # [s] duration of one revolution
    # [s] between beams (ROS); beam i fired (n − 1 − i)·time_increment before ``time``; 0: all
    # beams of one instant (nothing to de-skew, e.g. CARMEN logs or motion-free simulation)
    time_increment: float = 0.0
    ranges: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [m]
    valid: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    @property
    def angles(self) -> np.ndarray:
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges))

    def points(self) -> np.ndarray:
        """Valid returns as (n × 2) points in the sensor frame [m]."""
        a, r = self.angles[self.valid], self.ranges[self.valid]
        return np.column_stack([r * np.cos(a), r * np.sin(a)])


@dataclass
class PointCloud:
    """A 3D sweep (``lidar_points``): an organised range image (ring × azimuth column) and
    the valid returns as points in the sensor frame at the end of the sweep."""

    time: float = 0.0  # [s] end of the sweep
    elevations: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [rad] per ring
    azimuths: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [rad] per column
    range_image: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # [m], inf = none
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # [m] valid returns
    ring: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # ring of each point
    column: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # column of each point
    point_time: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [s] offset from start
    sweep_time: float = 0.0  # [s] duration of the sweep
    motion_applied: bool = False  # True: each column was measured from where the sensor was


@dataclass
class GpsFix:
    """A GNSS fix (``gps``). When ``valid`` is False the position fields are meaningless."""

    time: float = 0.0  # [s]
    valid: bool = False
    latitude: float = 0.0  # [deg] WGS84
    longitude: float = 0.0  # [deg]
    altitude: float = 0.0  # [m] ellipsoidal height
    covariance_enu: np.ndarray = field(default_factory=lambda: np.eye(3))  # [m^2] E, N, U
    hdop: float = 99.0  # [-]
    satellites: int = 0
    speed: float = 0.0  # [m/s] over ground
    course: float = 0.0  # [rad] ENU, counter-clockwise from east


@dataclass
class ImuSample:
    """One IMU sample (``imu``) in the body frame (x forward, y left, z up)."""

    time: float = 0.0  # [s]
    angular_velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))  # [rad/s]
    linear_acceleration: np.ndarray = field(
        default_factory=lambda: np.zeros(3)
    )  # [m/s^2] specific force
    orientation: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))  # xyzw

    def is_empty(self) -> bool:
        """True for the default value, which ports hold before the first sample arrives (a
        real sample senses gravity, so its specific force is never all zero)."""
        return (
            self.time == 0.0
            and not np.any(self.angular_velocity)
            and not np.any(self.linear_acceleration)
            and np.array_equal(self.orientation, [0.0, 0.0, 0.0, 1.0])
        )
