"""Scenarios: typed YAML describing one mission (vessel, world, environment, mission, rates).

``load_scenario("canal_demo")`` reads ``usvdrake/scenarios/canal_demo.yaml``; a path works too.
A bad file stops with a one-line :class:`~usvdrake.typed_yaml.ConfigError` (file, key, expected,
got): every number must be finite and within its range
(:data:`~usvdrake.scenario_ranges.RANGES`: bounds that keep a run from stalling the integrator
or needing more than a few GB). Directions are ENU angles counter-clockwise from
east, pointing where the flow goes.
"""

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_dump_typed

from usvdrake.scenario_ranges import (
    DEFAULT_RANGE,
    MAX_MAP_CELLS,
    NMPC_MAX_STEPS,
    describe_range,
    in_range,
    number_leaves,
    range_of,
)
from usvdrake.sensors.geodesy import DATUMS
from usvdrake.sensors.gps_model import GpsConfig
from usvdrake.sensors.imu_model import ImuConfig
from usvdrake.sensors.lidar_model import LIDAR_PRESETS, LidarConfig
from usvdrake.sensors.pose_sensor import PoseSensorConfig
from usvdrake.sensors.thrust_sensor import ThrustSensorConfig
from usvdrake.systems.colav.situation import resolve_situation
from usvdrake.systems.control.nmpc_problem import NmpcConfig
from usvdrake.systems.control.pd_controller import PdControllerConfig
from usvdrake.systems.control.reference_model import ReferenceModelConfig
from usvdrake.systems.estimation.nmhe_problem import NmheConfig
from usvdrake.systems.guidance.frontier_explorer import ExplorerConfig
from usvdrake.systems.guidance.line_of_sight import ControlConfig, MissionConfig
from usvdrake.systems.guidance.operator import OperatorCommandConfig
from usvdrake.systems.guidance.taxi_pilot import TaxiConfig
from usvdrake.systems.slam.graph_slam import GraphSlamConfig
from usvdrake.systems.slam.hector import HectorConfig
from usvdrake.systems.slam.lidar_inertial import LidarInertialConfig
from usvdrake.systems.vessel.environment_model import (
    CurrentConfig,
    EnvironmentConfig,
    WaveConfig,
    WindConfig,
)
from usvdrake.typed_yaml import ConfigError, get_dotted, is_plain_name, load_typed, resolve_yaml
from usvdrake.vessel import VESSEL_DIR, available_vessels
from usvdrake.worlds import available_worlds, make_world

__all__ = [  # the configs a scenario composes, importable from here too
    "ControlConfig",
    "CurrentConfig",
    "EnvironmentConfig",
    "MissionConfig",
    "WaveConfig",
    "WindConfig",
]

SCENARIO_DIR = Path(__file__).parent / "scenarios"
DEFAULT_SCENARIO = "canal_demo"


@dataclass
class VisualizationConfig:
    rate_hz: float = 10.0  # [Hz] Meshcat update and replay frame rate
    trail_chunk: float = 2.0  # [s] the trail is drawn in pieces of this length
    arrow_length: float = 0.0  # [m] thrust arrow length at full force; 0: half the hull length
    lidar_hits: bool = False  # draw the lidars' returns (live; the replay keeps the last ones)
    gps_denied: bool = True  # draw the world's GPS-denied zones (translucent red)
    occupancy_resolution: float = (
        0.0  # [m] draw the ground-truth occupancy at this cell size; 0: off
    )


@dataclass
class SimulationConfig:
    integrator: str = "runge_kutta3"  # Drake integrator scheme (error-controlled)
    accuracy: float = 1e-4  # [-] integrator target accuracy
    max_step: float = 0.1  # [s] largest integrator step


@dataclass
class SensorsConfig:
    # Which sensors the station carries (exports as ports): any of lidar2d, lidar3d, imu, gps,
    # pose (a noisy [x y ψ r] at 10 Hz standing in for Roboat II's SLAM pose + gyro, for the NMHE).
    # thrust_measured and ground_truth_state are always there.
    enabled: list[str] = field(default_factory=list)
    lidar2d: LidarConfig = field(default_factory=lambda: LidarConfig(preset="rplidar_a1"))
    lidar3d: LidarConfig = field(
        default_factory=lambda: LidarConfig(preset="vlp16", mount=[0.0, 0.0, 1.0, 0.0])
    )
    imu: ImuConfig = field(default_factory=ImuConfig)
    gps: GpsConfig = field(default_factory=GpsConfig)
    thrust: ThrustSensorConfig = field(default_factory=ThrustSensorConfig)
    pose: PoseSensorConfig = field(default_factory=PoseSensorConfig)


@dataclass
class SlamConfig:
    # "none"; "graph": Pham et al.'s sliding-window graph SLAM; "hector": Ueland 2017's Hector-style
    # SLAM; both on lidar_scan (needs lidar2d). "known_poses": the exploration's ground-truth map
    # source — the same scans inserted at the true pose (grid extent and resolution from
    # ``hector``). The SLAM runs in the autonomy half as an observer; metrics score it against
    # ground truth. "factor_graph": Roboat II's lidar-IMU-GPS factor graph on iSAM2 (needs lidar3d,
    # imu and gps).
    method: str = "none"
    graph: GraphSlamConfig = field(default_factory=GraphSlamConfig)
    hector: HectorConfig = field(default_factory=HectorConfig)
    factor_graph: LidarInertialConfig = field(default_factory=LidarInertialConfig)


@dataclass
class ObserverSettings:
    """Ueland 2017's nonlinear passive observer (Fossen 2011 §11.4.1) on the SLAM pose in calm water
    (no wave filter); the gains follow from the cut-offs by
    :func:`usvdrake.systems.estimation.observer_dynamics.fossen_gains`."""

    cutoff: list[float] = field(default_factory=lambda: [2.0, 2.0, 3.0])  # [rad/s] ω_c = K2
    bias_time_constant: float = 1000.0  # [s] T: the bias is a slowly varying force
    rate_hz: float = 20.0  # [Hz] observer update rate (RK4 substeps between updates)


@dataclass
class ExplorationConfig:
    """Ueland 2017's autonomous exploration: frontier explorer + weighted A* + velocity-setpoint law
    + reference model + PD controller + thrust allocation (controller ``explore``)."""

    explorer: ExplorerConfig = field(default_factory=ExplorerConfig)
    setpoint_rate_hz: float = 10.0  # [Hz] the velocity-setpoint law (faster than the planner)
    reference: ReferenceModelConfig = field(
        default_factory=lambda: ReferenceModelConfig(omega=0.45, zeta=1.0, v_max=0.3, a_max=0.1)
    )
    pd: PdControllerConfig = field(default_factory=PdControllerConfig)
    observer: ObserverSettings = field(default_factory=ObserverSettings)
    # Scripted operator actions (Ueland 2017 §Operator Interaction), e.g.
    # [{time: 120, mode: goto, goal: [10, 3]}, {time: 200, mode: explore}]
    commands: list[OperatorCommandConfig] = field(default_factory=list)
    operator_controls: bool = True  # Meshcat buttons and goal sliders when a Meshcat is live


@dataclass
class FleetVesselConfig:
    """One boat of a fleet (controller ``taxi``)."""

    name: str = ""  # its diagram's name, e.g. roboat_1
    initial_state: list[float] = field(default_factory=lambda: [0.0] * 6)  # [x y ψ u v r]
    fail_at: float = -1.0  # [s] the boat reports a fault then (re-assignment); < 0: never


@dataclass
class RequestConfig:
    """A ride request: a passenger at ``pickup`` asks at ``time`` to go to ``destination``."""

    time: float = 0.0  # [s]
    pickup: list[float] = field(default_factory=lambda: [0.0, 0.0])  # [m] world x, y
    destination: list[float] = field(default_factory=lambda: [0.0, 0.0])  # [m] world x, y


@dataclass
class FleetConfig:
    """Roboat's ride service (Roboat II §III): several boats, one coordinator (controller
    ``taxi``)."""

    vessels: list[FleetVesselConfig] = field(default_factory=list)
    requests: list[RequestConfig] = field(default_factory=list)
    taxi: TaxiConfig = field(default_factory=TaxiConfig)
    coordinator_period: float = 1.0  # [s] how often requests are assigned
    assignment_resolution: float = 1.0  # [m] cells of the coordinator's path-cost grid


@dataclass
class SerialDeviceConfig:
    """A device on a serial port (hardware station). An empty ``port`` means not fitted."""

    port: str = ""  # device path, e.g. /dev/serial/by-id/usb-u-blox_GNSS-if00
    baudrate: int = 115200  # [bit/s]
    protocol: str = (
        ""  # lidar2d only: 'rplidar' (Slamtec A1, Ueland 2017) or 'scip' (Hokuyo, Pham et al.)
    )


@dataclass
class UdpDeviceConfig:
    """A device sending UDP datagrams (Velodyne). An empty ``address`` means not fitted."""

    address: str = ""  # local address to bind, e.g. 0.0.0.0
    port: int = 2368  # [-] VLP-16 data port


@dataclass
class HardwareConfig:
    """The hardware station of ``build_vessel_diagram(scenario, hardware=...)``: which devices
    sit on which ports. The station exports the same port names as the simulated one."""

    thrusters: SerialDeviceConfig = field(default_factory=SerialDeviceConfig)
    gps: SerialDeviceConfig = field(default_factory=SerialDeviceConfig)
    imu: SerialDeviceConfig = field(default_factory=SerialDeviceConfig)
    lidar2d: SerialDeviceConfig = field(default_factory=SerialDeviceConfig)
    lidar3d: UdpDeviceConfig = field(default_factory=UdpDeviceConfig)
    command_rate_hz: float = 50.0  # [Hz] command frames to the thruster MCU (keep-alive)
    stale_timeout: float = 0.3  # [s] wall time without a fresh command → neutral frames
    sensor_timeout: float = 0.5  # [s] a required sensor silent this long → zero thrust
    poll_period: float = 0.01  # [s] how often the serial sources read their ports


@dataclass
class TrafficConfig:
    """Target ships from a DNV trafficgen traffic situation (issue 37): the situation's own-ship
    start is placed at the scenario's initial pose, the targets keep their place and course
    relative to it (``colav.scaling.placed``; Froude-scaled first when the situation's own ship
    is not the vessel's length). They sail their waypoints through the world (land is not
    checked), send AIS reports, and the vessel's AIS tracker outputs them as ``tracks``."""

    # a situation JSON file or a shipped name (traffic_situation_01, canal_situation_01);
    # empty: no traffic
    situation: str = ""
    ais_period: float = 1.0  # [s] AIS report and tracker period


@dataclass
class Scenario:
    name: str = ""  # short identifier (defaults to the file name)
    description: str = ""  # one line for humans
    vessel: str = "roboat2"  # a shipped vessel name or a YAML path
    world: str = "canal_demo"  # a world name from usvdrake.worlds
    duration: float = 60.0  # [s] simulated time; the run ends earlier when the mission completes
    seed: int = 0  # seed of every random source (world, environment, later sensors)
    initial_state: list[float] = field(default_factory=lambda: [0.0] * 6)  # [x y ψ u v r]
    # Multiplicative errors on the simulated plant's ξ = [m11 m22 m33 Xu Yv Nr] (the station
    # only; the autonomy's NMPC/NMHE/controllers keep the vessel file's nominal ξ)
    model_error: list[float] = field(default_factory=lambda: [1.0] * 6)
    # "oracle": the autonomy reads ground truth; "nmhe": Roboat II's NMHE on the pose sensor and the
    # measured thrust (needs "pose" in sensors.enabled); "slam": the controllers fly on the 3D
    # SLAM's [x y ψ u v r] (Roboat II §V; needs slam.method factor_graph)
    estimator: str = "oracle"
    nmhe: NmheConfig = field(default_factory=NmheConfig)
    # "baseline": LOS guidance + PD + thrust allocation over the waypoints; "nmpc": the NMPC of
    # Roboat II tracking an A* reference through the waypoints (goals in sequence) at mission.speed
    controller: str = "baseline"
    slam: SlamConfig = field(default_factory=SlamConfig)
    # "explore" (Ueland 2017): the vessel maps the world by itself; needs slam.method hector or
    # graph
    exploration: ExplorationConfig = field(default_factory=ExplorationConfig)
    nmpc: NmpcConfig = field(default_factory=NmpcConfig)
    sensors: SensorsConfig = field(default_factory=SensorsConfig)
    environment: EnvironmentConfig = field(default_factory=EnvironmentConfig)
    mission: MissionConfig = field(default_factory=MissionConfig)
    control: ControlConfig = field(default_factory=ControlConfig)
    visualization: VisualizationConfig = field(default_factory=VisualizationConfig)
    simulation: SimulationConfig = field(default_factory=SimulationConfig)
    hardware: HardwareConfig = field(default_factory=HardwareConfig)
    # controller "taxi": the boats, ride requests and taxi settings of a fleet mission
    fleet: FleetConfig = field(default_factory=FleetConfig)
    # target ships of a traffic situation met on the way (none by default)
    traffic: TrafficConfig = field(default_factory=TrafficConfig)


def check_numbers(s: Scenario, file: str | Path = "scenario") -> None:
    """Every number finite, then within its rule of
    :data:`~usvdrake.scenario_ranges.RANGES` (one ConfigError naming the key, the range and the
    value)."""
    leaves = list(number_leaves(s))
    for key, value in leaves:
        if isinstance(value, (float, np.floating)) and not math.isfinite(value):
            raise ConfigError(file, key, "a finite number", repr(float(value)))
    for key, value in leaves:
        rule = range_of(key) or DEFAULT_RANGE
        if not in_range(value, rule):
            raise ConfigError(file, key, describe_range(rule), repr(value))
    maps = (("hector", s.slam.hector.resolution), ("graph", s.slam.graph.map_resolution))
    for name, resolution in maps:
        size = getattr(s.slam, name).map_size
        cells = size[0] * size[1] / resolution**2
        if cells > MAX_MAP_CELLS:
            raise ConfigError(
                file,
                f"slam.{name}.map_size",
                f"at most {MAX_MAP_CELLS:.0e} cells of {resolution:g} m",
                f"{size} ({cells:.2g} cells)",
            )
    steps = s.nmpc.horizon / s.nmpc.dt
    if steps > NMPC_MAX_STEPS:
        raise ConfigError(
            file,
            "nmpc.horizon",
            f"at most {NMPC_MAX_STEPS} intervals of nmpc.dt ({s.nmpc.dt:g} s)",
            f"{s.nmpc.horizon!r} ({steps:.0f} intervals)",
        )


def available_scenarios() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml"))


def _positive(file, key, value):
    if not value > 0:
        raise ConfigError(file, key, "a positive number", repr(value))


def validate_scenario(s: Scenario, file: str | Path = "scenario") -> Scenario:
    """Check values the types cannot: ranges, names, sizes. Returns ``s`` unchanged.

    What the chosen estimator, controller and SLAM method need of the scenario is their own
    check (:func:`usvdrake.diagrams.check_scenario` runs both)."""
    if len(s.model_error) != 6 or any(f <= 0 for f in s.model_error):  # NaN: check_numbers
        raise ConfigError(
            file, "model_error", "6 positive factors on [m11 m22 m33 Xu Yv Nr]", repr(s.model_error)
        )
    check_numbers(s, file)
    vessel_path = Path(s.vessel)
    if vessel_path.suffix in (".yaml", ".yml"):
        if not vessel_path.is_file():
            raise ConfigError(file, "vessel", "an existing vessel YAML file", repr(s.vessel))
    elif not (is_plain_name(s.vessel) and (VESSEL_DIR / f"{s.vessel}.yaml").is_file()):
        raise ConfigError(
            file, "vessel", "one of " + ", ".join(available_vessels()), repr(s.vessel)
        )
    if s.traffic.situation:
        resolve_situation(s.traffic.situation, file, "traffic.situation")
    if s.world not in available_worlds():
        raise ConfigError(file, "world", "one of " + ", ".join(available_worlds()), repr(s.world))
    if len(s.initial_state) != 6:
        raise ConfigError(
            file, "initial_state", "6 numbers [x y psi u v r]", f"{len(s.initial_state)} numbers"
        )
    if s.nmpc.solver not in ("riccati", "clarabel", "osqp"):
        raise ConfigError(
            file, "nmpc.solver", "'riccati', 'clarabel' or 'osqp'", repr(s.nmpc.solver)
        )
    if s.nmpc.disturbance_source not in ("estimator", "internal"):
        raise ConfigError(
            file,
            "nmpc.disturbance_source",
            "'estimator' or 'internal'",
            repr(s.nmpc.disturbance_source),
        )
    if s.nmpc.mode not in ("rti", "nlp"):
        raise ConfigError(file, "nmpc.mode", "'rti' or 'nlp'", repr(s.nmpc.mode))
    for key, n in (("nmpc.Wq", 6), ("nmpc.WN", 6), ("nmpc.velocity_bounds", 3)):
        if len(get_dotted(s, key)) != n:
            raise ConfigError(file, key, f"{n} numbers", f"{len(get_dotted(s, key))} numbers")
    for i, wp in enumerate(s.mission.waypoints):
        if len(wp) != 2:
            raise ConfigError(file, f"mission.waypoints[{i}]", "[x, y]", f"{len(wp)} numbers")
    integrators = (
        "runge_kutta2",
        "runge_kutta3",
        "runge_kutta5",
        "radau3",
        "implicit_euler",
        "bogacki_shampine3",
    )
    if s.simulation.integrator not in integrators:
        raise ConfigError(
            file,
            "simulation.integrator",
            "one of " + ", ".join(integrators),
            repr(s.simulation.integrator),
        )
    for key, dims in (("lidar2d", 1), ("lidar3d", 2)):
        cfg = getattr(s.sensors, key)
        if cfg.preset not in LIDAR_PRESETS:
            raise ConfigError(
                file,
                f"sensors.{key}.preset",
                "one of " + ", ".join(sorted(LIDAR_PRESETS)),
                repr(cfg.preset),
            )
        if (len(LIDAR_PRESETS[cfg.preset].elevations_deg) > 1) != (dims == 2):
            kind = "a 3D" if dims == 2 else "a 2D"
            raise ConfigError(
                file, f"sensors.{key}.preset", f"{kind} lidar preset", repr(cfg.preset)
            )
        if len(cfg.mount) != 4:
            raise ConfigError(
                file, f"sensors.{key}.mount", "[x, y, z, yaw]", f"{len(cfg.mount)} numbers"
            )
        if not 0.0 <= cfg.dropout < 1.0:
            raise ConfigError(
                file, f"sensors.{key}.dropout", "a probability in [0, 1)", repr(cfg.dropout)
            )
    if s.sensors.gps.datum and s.sensors.gps.datum not in DATUMS:
        raise ConfigError(
            file,
            "sensors.gps.datum",
            "one of " + ", ".join(sorted(DATUMS)),
            repr(s.sensors.gps.datum),
        )
    _check_free_water(s, file, make_world(s.world, s.seed))
    hw = s.hardware
    for key in ("command_rate_hz", "stale_timeout", "sensor_timeout", "poll_period"):
        _positive(file, f"hardware.{key}", getattr(hw, key))
    if hw.lidar2d.port and hw.lidar2d.protocol not in ("rplidar", "scip"):
        raise ConfigError(
            file, "hardware.lidar2d.protocol", "'rplidar' or 'scip'", repr(hw.lidar2d.protocol)
        )
    for key in ("thrusters", "gps", "imu", "lidar2d"):
        if getattr(hw, key).baudrate <= 0:
            raise ConfigError(
                file,
                f"hardware.{key}.baudrate",
                "a positive integer",
                repr(getattr(hw, key).baudrate),
            )
    return s


def validate_fleet(s: Scenario, file) -> None:
    """A taxi scenario: named boats in free water, requests between free-water points."""
    f = s.fleet
    if not f.vessels:
        raise ConfigError(file, "fleet.vessels", "at least one vessel", "none")
    names = [v.name for v in f.vessels]
    if any(not n for n in names) or len(set(names)) != len(names):
        raise ConfigError(file, "fleet.vessels", "unique non-empty names", repr(names))
    if not f.requests:
        raise ConfigError(file, "fleet.requests", "at least one request", "none")
    _positive(file, "fleet.coordinator_period", f.coordinator_period)
    _positive(file, "fleet.assignment_resolution", f.assignment_resolution)
    for key in ("speed", "acceptance_radius", "period", "resolution", "lookahead"):
        _positive(file, f"fleet.taxi.{key}", getattr(f.taxi, key))
    world = make_world(s.world, s.seed)
    points = []
    for i, v in enumerate(f.vessels):
        if len(v.initial_state) != 6:
            raise ConfigError(
                file, f"fleet.vessels[{i}].initial_state", "6 numbers", repr(v.initial_state)
            )
        points.append((f"fleet.vessels[{i}].initial_state", v.initial_state[:2]))
    for i, r in enumerate(f.requests):
        for key in ("pickup", "destination"):
            if len(getattr(r, key)) != 2:
                raise ConfigError(
                    file, f"fleet.requests[{i}].{key}", "[x, y]", repr(getattr(r, key))
                )
            points.append((f"fleet.requests[{i}].{key}", getattr(r, key)))
        if r.time < 0:
            raise ConfigError(file, f"fleet.requests[{i}].time", "a time >= 0", repr(r.time))
    for key, (x, y) in points:
        if not (world.in_water(x, y) and world.clearance(x, y) >= f.taxi.inflation):
            raise ConfigError(
                file,
                key,
                f"a point in free water of '{s.world}', {f.taxi.inflation} m from obstacles",
                f"({x}, {y}), clearance {float(world.clearance(x, y)):.2f} m",
            )


def _check_free_water(s: Scenario, file, world) -> None:
    """The start and every waypoint must lie in the water, clear of quays, boats and buildings,
    and the straight legs between them must not cross a solid or land (LOS guidance follows
    them)."""
    points = [("initial_state", s.initial_state[:2])]
    points += [(f"mission.waypoints[{i}]", wp) for i, wp in enumerate(s.mission.waypoints)]
    for key, (x, y) in points:
        if not (world.in_water(x, y) and world.clearance(x, y) > 0.0):
            where = "inside an obstacle" if world.in_water(x, y) else "on land"
            raise ConfigError(
                file, key, f"a point in free water of world '{s.world}'", f"({x}, {y}), {where}"
            )
    for (key_a, a), (key_b, b) in zip(points[:-1], points[1:], strict=True):
        a, b = np.asarray(a, float), np.asarray(b, float)
        n = max(2, int(np.linalg.norm(b - a) / 0.25) + 1)
        leg = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        blocked = ~world.in_water(leg[:, 0], leg[:, 1]) | (
            world.clearance(leg[:, 0], leg[:, 1]) <= 0.0
        )
        if blocked.any():
            x, y = np.round(leg[np.argmax(blocked)], 1)
            raise ConfigError(
                file,
                key_b,
                f"a straight leg from {key_a} through free water",
                f"one blocked at ({x}, {y})",
            )


def read_scenario(name_or_path: str | Path | None = None) -> Scenario:
    """Read a shipped scenario by name, or a scenario YAML file (None: the demo scenario), and
    check its values (:func:`validate_scenario`); :func:`usvdrake.load_scenario` also checks
    its variants."""
    path = resolve_yaml(
        "scenario", DEFAULT_SCENARIO if name_or_path is None else name_or_path, SCENARIO_DIR
    )
    s = load_typed(Scenario, path)
    if not s.name:
        s = dataclasses.replace(s, name=path.stem)
    return validate_scenario(s, path)


def override(s: Scenario, duration: float | None = None, seed: int | None = None) -> Scenario:
    """A validated copy of ``s`` with command-line overrides (``s`` itself is never modified)."""
    changes = {}
    if duration is not None:
        changes["duration"] = duration
    if seed is not None:
        changes["seed"] = seed
    return validate_scenario(dataclasses.replace(s, **changes), f"{s.name} (command line)")


def scenario_yaml(s: Scenario) -> str:
    """The complete YAML of ``s`` (floats in shortest round-trip form: it reloads exactly)."""
    return yaml_dump_typed(s)
