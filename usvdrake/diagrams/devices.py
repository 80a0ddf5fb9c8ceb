"""The device table: one row per sensor device the hardware station can build.

A row is keyed by the sensor's one name -- the name of its row in the sensor table
(:data:`usvdrake.diagrams.sensors.SENSORS`), its slot in the scenario's ``hardware`` section
(``hardware.gps``) and its system's name in both stations (``gps``). It says which station output
port the device feeds (for a device that is also a simulated sensor, the port of that sensor's
row, so the name → port mapping lives in one table), whether a :class:`HardwareConfig` fits it,
and how to build its source system. The hardware station
(:mod:`usvdrake.diagrams.hardware_station`) builds every fitted row; the thruster MCU and the
watchdog are fixed parts of it, not rows. A new device is a LeafSystem (transport → codec →
port, as :class:`~hardware_io.systems.gps_serial_source.GpsSerialSource` does) plus one
``DEVICES.register`` call (``docs/extending.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pydrake.systems.framework import LeafSystem

from hardware_io.systems.gps_serial_source import GpsSerialSource
from hardware_io.systems.imu_serial_source import ImuSerialSource
from hardware_io.systems.lidar_serial_source import LidarSerialSource
from hardware_io.systems.velodyne_udp_source import VelodyneUdpSource
from usvdrake.diagrams.sensors import SENSORS
from usvdrake.registry import Registry
from usvdrake.scenario import HardwareConfig, Scenario
from usvdrake.worlds.world import World

__all__ = ["DEVICES", "Device"]


@dataclass(frozen=True)
class Device:
    """A real device behind the hardware station. ``make(hw, scenario, world)`` returns a
    LeafSystem with an output named ``port`` (and, optionally, a ``diagnostics`` output: a flat
    dict of its counters, which the station exports as ``<name>_diagnostics``); it may open its
    serial port or socket, and then has a ``close()`` method that releases it."""

    port: str  # the station output port it feeds (the sensor table's port for the same name)
    fitted: Callable[[HardwareConfig], bool]  # does this hardware section have the device?
    make: Callable[[HardwareConfig, Scenario, World], LeafSystem]
    description: str = ""


DEVICES: Registry[Device] = Registry("hardware device", key="hardware")


DEVICES.register(
    "gps",
    Device(
        SENSORS.get("gps").port,
        lambda hw: bool(hw.gps.port),
        lambda hw, s, w: GpsSerialSource(
            hw.gps.port, hw.gps.baudrate, w.datum, period=hw.poll_period
        ),
        "NMEA 0183 GNSS receiver on a serial port: GpsFix",
    ),
)
DEVICES.register(
    "imu",
    Device(
        SENSORS.get("imu").port,
        lambda hw: bool(hw.imu.port),
        lambda hw, s, w: ImuSerialSource(hw.imu.port, hw.imu.baudrate, period=hw.poll_period),
        "Xsens MTi (Xbus MTData2) on a serial port: ImuSample",
    ),
)
DEVICES.register(
    "lidar2d",
    Device(
        SENSORS.get("lidar2d").port,
        lambda hw: bool(hw.lidar2d.port),
        lambda hw, s, w: LidarSerialSource(
            hw.lidar2d.port, hw.lidar2d.baudrate, hw.lidar2d.protocol, period=hw.poll_period
        ),
        "RPLIDAR A1 or Hokuyo (SCIP 2.0) on a serial port: LaserScan",
    ),
)
DEVICES.register(
    "lidar3d",
    Device(
        SENSORS.get("lidar3d").port,
        lambda hw: bool(hw.lidar3d.address),
        lambda hw, s, w: VelodyneUdpSource(
            hw.lidar3d.address, hw.lidar3d.port, period=hw.poll_period
        ),
        "Velodyne VLP-16 data packets over UDP: PointCloud",
    ),
)
