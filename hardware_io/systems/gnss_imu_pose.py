"""``GnssImuPose``: the hardware station's ``pose_measurement`` from an RTK GNSS and an AHRS.

In simulation the NMHE of Roboat II reads ``pose_measurement`` = [x y ψ r] from a pose sensor whose
noise is RT of Roboat II eq. (16) (σ ≈ 2.2 cm in position: an RTK-class fix). On the boat the same
vector comes from two devices: the GNSS receiver's fix (NMEA GGA → :class:`GpsFix`) converted to
the world's local ENU frame with pyproj, and the IMU/AHRS's heading and yaw rate
(:class:`ImuSample`: orientation quaternion and gyro z). This system is that conversion; it has
no state, so it adds no delay beyond the devices' own.
"""

from __future__ import annotations

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.geodesy import Datum, LocalFrame
from usvdrake.sensors.messages import GpsFix, ImuSample

__all__ = ["GnssImuPose", "quaternion_yaw"]


def quaternion_yaw(q_xyzw) -> float:
    """Yaw [rad] (rotation about z, ENU, counter-clockwise) of a unit quaternion [x y z w]
    (the z-y-x Euler angle ψ = atan2(2(wz + xy), 1 − 2(y² + z²)))."""
    x, y, z, w = (float(v) for v in q_xyzw)
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class GnssImuPose(LeafSystem):
    """[x y ψ r] from the latest GNSS fix and IMU sample.

    .. pydrake_system::

        name: GnssImuPose
        input_ports:
        - gps
        - imu
        output_ports:
        - pose_measurement

    x, y [m]: the fix in the local ENU frame of ``datum`` (while no valid fix has arrived:
    ``initial_pose``'s x, y, the mission's configured start); ψ [rad]: the yaw of the IMU
    orientation; r [rad/s]: the IMU's angular velocity about body z (before the first IMU sample:
    ``initial_pose``'s ψ and r = 0). An invalid fix keeps the last valid position (as
    :class:`~hardware_io.systems.gps_serial_source.GpsSerialSource` holds it), so x, y freeze
    during an outage and the NMHE's model carries the estimate through short ones.
    """

    def __init__(self, datum: Datum | str, initial_pose=(0.0, 0.0, 0.0)):
        super().__init__()
        self._frame = LocalFrame(datum)
        self._initial = np.asarray(initial_pose, float)[:3]
        self._gps = self.DeclareAbstractInputPort("gps", AbstractValue.Make(GpsFix()))
        self._imu = self.DeclareAbstractInputPort("imu", AbstractValue.Make(ImuSample()))
        self.DeclareVectorOutputPort("pose_measurement", 4, self._calc)

    def _calc(self, context, output: BasicVector):
        fix: GpsFix = self._gps.Eval(context)
        imu: ImuSample = self._imu.Eval(context)
        x, y, psi = self._initial
        r = 0.0
        # Sources start from the messages' default values; a default one means "nothing yet".
        if fix.valid or fix.latitude != 0.0 or fix.longitude != 0.0:
            e, n, _ = self._frame.to_local(fix.latitude, fix.longitude, fix.altitude)
            x, y = float(e), float(n)
        if not imu.is_empty():
            psi = quaternion_yaw(imu.orientation)
            r = float(imu.angular_velocity[2])
        output.SetFromVector([x, y, psi, r])
