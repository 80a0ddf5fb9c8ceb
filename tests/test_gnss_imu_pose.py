"""GnssImuPose: GNSS fix + AHRS sample → [x y ψ r] in the world's local frame."""

import math

import numpy as np
import pytest
from pydrake.common.value import AbstractValue

from hardware_io.systems.gnss_imu_pose import GnssImuPose, quaternion_yaw
from usvdrake.sensors.geodesy import LocalFrame
from usvdrake.sensors.imu_model import yaw_quaternion
from usvdrake.sensors.messages import GpsFix, ImuSample


@pytest.mark.parametrize("yaw", [-3.1, -1.0, 0.0, 0.4, 2.0, 3.1])
def test_quaternion_yaw_inverts_yaw_quaternion(yaw):
    assert quaternion_yaw(yaw_quaternion(yaw)) == pytest.approx(yaw, abs=1e-12)


def test_quaternion_yaw_ignores_roll_and_pitch():
    # R = Rz(0.7) Ry(0.1) Rx(-0.2) as a quaternion [x y z w]
    from scipy.spatial.transform import Rotation

    q = Rotation.from_euler("ZYX", [0.7, 0.1, -0.2]).as_quat()
    assert quaternion_yaw(q) == pytest.approx(0.7, abs=1e-12)


def _eval(system, fix, imu):
    context = system.CreateDefaultContext()
    system.GetInputPort("gps").FixValue(context, AbstractValue.Make(fix))
    system.GetInputPort("imu").FixValue(context, AbstractValue.Make(imu))
    return system.GetOutputPort("pose_measurement").Eval(context)


def test_pose_from_fix_and_imu_in_local_frame():
    frame = LocalFrame("charles_river")
    lat, lon, h = frame.to_geodetic(-120.25, 7.5, 0.0)
    fix = GpsFix(time=1.0, valid=True, latitude=float(lat), longitude=float(lon), altitude=float(h))
    imu = ImuSample(
        time=1.0, angular_velocity=np.array([0.0, 0.0, 0.05]), orientation=yaw_quaternion(2.5)
    )
    system = GnssImuPose("charles_river", (0.0, 0.0, 0.0))
    z = _eval(system, fix, imu)
    np.testing.assert_allclose(z, [-120.25, 7.5, 2.5, 0.05], atol=1e-6)


def test_before_any_message_the_initial_pose_is_given():
    system = GnssImuPose("charles_river", (-150.0, -20.0, 0.56))
    z = _eval(system, GpsFix(), ImuSample())
    np.testing.assert_allclose(z, [-150.0, -20.0, 0.56, 0.0])


def test_an_invalid_fix_keeps_its_held_position():
    frame = LocalFrame("charles_river")
    lat, lon, _ = frame.to_geodetic(3.0, 4.0, 0.0)
    held = GpsFix(time=5.0, valid=False, latitude=float(lat), longitude=float(lon))
    z = _eval(GnssImuPose("charles_river"), held, ImuSample())
    assert z[:2] == pytest.approx([3.0, 4.0], abs=0.05)  # height differs: a few mm at most
    assert math.isfinite(z[2])
