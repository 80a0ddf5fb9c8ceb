"""The built-in SLAM methods of the autonomy (``slam.method``).

``graph``: the sliding-window 2D lidar SLAM (Pham et al.: PLICP + Censi covariance + Barron
kernel) on ``lidar_scan``; ``hector``: the NTNU explorer's Hector-style SLAM (Kohlbrecher 2011)
on ``lidar_scan``; ``known_poses``: the exploration's ground-truth map source, the same scans
inserted at the oracle's pose; ``factor_graph``: Roboat II's lidar-IMU-GPS factor graph on
iSAM2 on ``lidar_points``, ``imu`` and ``gps``. Each exports ``slam_pose``,
``slam_covariance`` and its map; the SLAM runs as an observer unless the estimator is
``slam``.
"""

from dataclasses import replace

from usvdrake.diagrams.variants import SLAM_METHODS, AutonomyParts, Variant, require_sensors
from usvdrake.errors import ConfigError
from usvdrake.scenario import Scenario
from usvdrake.sensors.lidar_model import sample_rate
from usvdrake.systems.slam.factor_graph_slam import FactorGraphSlam
from usvdrake.systems.slam.known_pose_mapper import KnownPoseMapper
from usvdrake.systems.slam.lidar_inertial import LidarInertialConfig
from usvdrake.systems.slam.lidar_slam2d import HectorSlam, LidarSlam2D
from usvdrake.worlds import make_world

SLAM2D_OUTPUTS = ("slam_pose", "slam_covariance", "slam_map")


def _export_2d(parts: AutonomyParts, slam):
    parts.builder.ExportInput(slam.GetInputPort("lidar_scan"), "lidar_scan")
    for port in SLAM2D_OUTPUTS:
        parts.builder.ExportOutput(slam.GetOutputPort(port), port)
    if slam.HasOutputPort("slam_summary"):  # the known-pose mapper has nothing to score
        parts.builder.ExportOutput(slam.GetOutputPort("slam_summary"), "slam_summary")
    return slam


def _lidar_period(parts: AutonomyParts) -> float:
    return 1.0 / sample_rate(parts.scenario.sensors.lidar2d)


def add_graph(parts: AutonomyParts):
    s = parts.scenario
    slam = LidarSlam2D(
        s.slam.graph, s.initial_state[:3], s.sensors.lidar2d.mount, _lidar_period(parts)
    )
    return _export_2d(parts, parts.builder.AddNamedSystem("lidar_slam_2d", slam))


def add_hector(parts: AutonomyParts):
    s = parts.scenario
    slam = HectorSlam(
        s.slam.hector, s.initial_state[:3], s.sensors.lidar2d.mount, _lidar_period(parts)
    )
    return _export_2d(parts, parts.builder.AddNamedSystem("lidar_slam_2d", slam))


def add_known_poses(parts: AutonomyParts):
    """The scans inserted at the oracle's pose (grid extent and resolution from ``hector``)."""
    pose = parts.oracle().get_output_port()
    h, lidar = parts.scenario.slam.hector, parts.scenario.sensors.lidar2d
    mapper = KnownPoseMapper(
        h.map_origin, h.map_size, h.resolution, lidar.mount, _lidar_period(parts), h.max_range
    )
    slam = parts.builder.AddNamedSystem("known_pose_mapper", mapper)
    parts.builder.Connect(pose, slam.GetInputPort("state_estimate"))
    return _export_2d(parts, slam)


def check_lidar2d(s: Scenario, file: str) -> None:
    require_sensors(s, file, ("lidar2d",), "the SLAM reads it")


def check_known_poses(s: Scenario, file: str) -> None:
    check_lidar2d(s, file)
    if s.controller != "explore" or s.estimator != "oracle":
        raise ConfigError(
            file,
            "slam.method",
            "'known_poses' only with controller explore and estimator oracle",
            repr(s.slam.method),
        )


def settings_from_scenario(
    scenario: Scenario, world_datum: str | None = None
) -> tuple[LidarInertialConfig, list, str]:
    """(config, mount [x y z yaw], datum) of ``scenario``'s 3D SLAM, live and offline:
    ``slam.factor_graph`` with the GPS antenna height, the 3D lidar's mount, and
    ``sensors.gps.datum`` or the world's datum (``world_datum``, or the scenario's world built
    to read it)."""
    sensors = scenario.sensors
    config = replace(scenario.slam.factor_graph, gps_antenna_height=sensors.gps.antenna_height)
    datum = sensors.gps.datum or world_datum or make_world(scenario.world, scenario.seed).datum
    return config, list(sensors.lidar3d.mount), datum


def add_factor_graph(parts: AutonomyParts):
    """Roboat II §V's lidar-IMU-GPS factor graph on ``lidar_points``, ``imu`` and ``gps``."""
    s = parts.scenario
    cfg, mount, datum = settings_from_scenario(s, parts.world.datum)
    slam = parts.builder.AddNamedSystem(
        "factor_graph_slam",
        FactorGraphSlam(cfg, s.initial_state, mount, s.sensors.imu.rate_hz, datum=datum),
    )
    for port in ("lidar_points", "imu", "gps"):
        parts.builder.ExportInput(slam.GetInputPort(port), port)
    for port in (
        "slam_pose",
        "slam_covariance",
        "slam_state",
        "slam_pose3d",
        "slam_map3d",
        "slam_summary",
    ):
        parts.builder.ExportOutput(slam.GetOutputPort(port), port)
    return slam


def check_factor_graph(s: Scenario, file: str) -> None:
    require_sensors(s, file, ("lidar3d", "imu", "gps"), "the factor graph reads them")


def add_none(parts: AutonomyParts):
    return None


SLAM_METHODS.register("none", Variant(add_none, "no SLAM"))
SLAM_METHODS.register(
    "graph", Variant(add_graph, "sliding-window 2D graph SLAM on lidar_scan", check_lidar2d)
)
SLAM_METHODS.register(
    "hector", Variant(add_hector, "Hector-style 2D SLAM on lidar_scan", check_lidar2d)
)
SLAM_METHODS.register(
    "known_poses",
    Variant(add_known_poses, "scans mapped at the true pose (exploration)", check_known_poses),
)
SLAM_METHODS.register(
    "factor_graph",
    Variant(add_factor_graph, "lidar-IMU-GPS factor graph on iSAM2", check_factor_graph),
)
