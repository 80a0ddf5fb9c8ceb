"""The sensor table: one row per sensor a scenario can enable (``sensors.enabled``).

The row's name is the scenario's name for the sensor; it says which station output port the
sensor feeds (the signal the autonomy reads, the same in simulation and on the water), the name
of the simulated system in the station (the row's name), and how to build that system. The
hardware devices (:data:`usvdrake.diagrams.devices.DEVICES`) are keyed, and their systems in the
hardware station named, by the same names, and take their ports from these rows. A new sensor
is a LeafSystem with a ``state`` input plus one ``SENSORS.register`` call
(``docs/extending.md``).
"""

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from pydrake.systems.framework import LeafSystem

from usvdrake.registry import Registry
from usvdrake.scenario import Scenario
from usvdrake.sensors.gps import Gps
from usvdrake.sensors.imu import Imu
from usvdrake.sensors.lidar2d import Lidar2D
from usvdrake.sensors.lidar3d import Lidar3D
from usvdrake.sensors.pose_sensor import PoseSensor
from usvdrake.sensors.sampled_lidar import OtherVessels
from usvdrake.worlds.world import World


@dataclass(frozen=True)
class Sensor:
    """A simulated sensor. ``make(scenario, world, others)`` returns a LeafSystem with a
    ``state`` input ([x y ψ u v r] of the plant; an ``acceleration`` input and an
    ``other_vessels`` input are connected when it has them) and an output named ``port``.
    ``others``: the fleet's other boats as lidars see them, or None."""

    port: str  # the station output port (and mission-log topic) it feeds
    system: str  # the simulated system's name inside the station
    make: Callable[[Scenario, World, OtherVessels | None], LeafSystem]
    description: str = ""


SENSORS: Registry[Sensor] = Registry("sensor", key="sensors.enabled")


def _gps(scenario: Scenario, world: World, others) -> Gps:
    cfg = scenario.sensors.gps
    cfg = cfg if cfg.datum else dataclasses.replace(cfg, datum=world.datum)
    antenna = cfg.antenna_height
    return Gps(
        cfg,
        scenario.seed,
        denied=lambda x, y: bool(world.gps_denied_at(x, y)),
        sky_blocked=lambda x, y: world.sky_blocked(x, y, antenna),
    )


SENSORS.register(
    "lidar2d",
    Sensor(
        "lidar_scan",
        "lidar2d",
        lambda s, w, o: Lidar2D(s.sensors.lidar2d, w.scene, s.seed, others=o),
        "2D scanning lidar (RPLIDAR A1, Hokuyo UTM-30LX presets): LaserScan",
    ),
)
SENSORS.register(
    "lidar3d",
    Sensor(
        "lidar_points",
        "lidar3d",
        lambda s, w, o: Lidar3D(s.sensors.lidar3d, w.scene, s.seed, others=o),
        "3D lidar (VLP-16 preset): PointCloud with per-point times",
    ),
)
SENSORS.register(
    "imu",
    Sensor("imu", "imu", lambda s, w, o: Imu(s.sensors.imu, s.seed), "IMU with AHRS: ImuSample"),
)
SENSORS.register("gps", Sensor("gps", "gps", _gps, "GNSS receiver: GpsFix (WGS84)"))
SENSORS.register(
    "pose",
    Sensor(
        "pose_measurement",
        "pose",
        lambda s, w, o: PoseSensor(s.sensors.pose, s.seed),
        "noisy [x y ψ r] standing in for Roboat II's SLAM pose + gyro (for the NMHE)",
    ),
)
