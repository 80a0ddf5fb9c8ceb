"""The built-in waypoint and fleet controllers (``controller``).

``baseline``: LOS guidance (Fossen 2011 §10.3.2) → heading/speed law → constrained thrust
allocation; ``nmpc``: Roboat II's NMPC tracking an A* reference through the mission's goals,
thruster forces straight out; ``taxi``: a fleet boat of Roboat's ride service (Roboat II §III),
its pilot feeding the NMPC. The NTNU explorer's ``explore`` lives in
:mod:`~usvdrake.diagrams.exploration`.
"""

import functools
import math

import numpy as np

from usvdrake.diagrams.variants import CONTROLLERS, AutonomyParts, Variant
from usvdrake.errors import ConfigError
from usvdrake.scenario import Scenario, validate_fleet
from usvdrake.sensors.lidar_model import sample_rate
from usvdrake.systems.control.heading_speed_controller import HeadingSpeedController
from usvdrake.systems.control.nmpc_system import Nmpc
from usvdrake.systems.guidance.grid_astar import PlanningGrid
from usvdrake.systems.guidance.los_guidance import LosGuidance
from usvdrake.systems.guidance.reference_monitor import ReferenceMonitor
from usvdrake.systems.guidance.reference_trajectory import ReferenceTrajectory
from usvdrake.systems.guidance.taxi_pilot import TaxiPilot
from usvdrake.systems.vessel.thrust_allocation import ThrustAllocation
from usvdrake.worlds import make_world
from usvdrake.worlds.world import World

DEFAULT_NMPC_SPEED = 0.6  # [m/s] Roboat II §VI-B tracks at u = 0.6 m/s, v = 0


def make_reference(scenario: Scenario, world: World) -> ReferenceTrajectory:
    """The timed reference the NMPC tracks: A* through the mission's goals in sequence."""
    speed = scenario.mission.speed or DEFAULT_NMPC_SPEED
    return ReferenceTrajectory.from_goals(
        world, scenario.initial_state[:2], scenario.mission.waypoints, speed=speed
    )


def add_baseline(parts: AutonomyParts) -> None:
    builder, scenario, vessel = parts.builder, parts.scenario, parts.vessel
    guidance = builder.AddNamedSystem(
        "los_guidance", LosGuidance(scenario.mission, scenario.control, vessel.cruise_speed)
    )
    controller = builder.AddNamedSystem(
        "heading_speed_controller", HeadingSpeedController(vessel.hydrodynamics, scenario.control)
    )
    allocation = builder.AddNamedSystem("thrust_allocation", ThrustAllocation(vessel))
    builder.Connect(parts.estimate, guidance.GetInputPort("state_estimate"))
    builder.Connect(parts.estimate, controller.GetInputPort("state_estimate"))
    builder.Connect(guidance.GetOutputPort("reference"), controller.GetInputPort("reference"))
    builder.Connect(controller.GetOutputPort("tau_desired"), allocation.GetInputPort("tau_desired"))
    builder.ExportOutput(allocation.GetOutputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(guidance.GetOutputPort("mission_complete"), "mission_complete")
    builder.ExportOutput(guidance.GetOutputPort("reference"), "reference")
    builder.ExportOutput(controller.GetOutputPort("tau_desired"), "tau_desired")
    builder.ExportOutput(allocation.GetOutputPort("tau_achieved"), "tau_achieved")


def add_nmpc(parts: AutonomyParts) -> None:
    builder, scenario = parts.builder, parts.scenario
    reference = make_reference(scenario, parts.world)
    nmpc = builder.AddNamedSystem("nmpc", Nmpc(parts.vessel, scenario.nmpc, reference))
    monitor = builder.AddNamedSystem(
        "reference_monitor", ReferenceMonitor(reference, scenario.mission.acceptance_radius)
    )
    builder.Connect(parts.estimate, nmpc.GetInputPort("state_estimate"))
    if parts.disturbance_estimate is not None and scenario.nmpc.disturbance_source == "estimator":
        builder.Connect(parts.disturbance_estimate, nmpc.GetInputPort("disturbance_estimate"))
    builder.Connect(parts.estimate, monitor.GetInputPort("state_estimate"))
    for port in ("thruster_command", "predicted_trajectory", "nmpc_failures", "nmpc_diagnostics"):
        builder.ExportOutput(nmpc.GetOutputPort(port), port)
    builder.ExportOutput(monitor.GetOutputPort("mission_complete"), "mission_complete")
    builder.ExportOutput(monitor.GetOutputPort("reference"), "reference")
    builder.ExportOutput(monitor.GetOutputPort("reference_track"), "reference_track")


@functools.lru_cache(maxsize=4)
def taxi_grid(world_name: str, seed: int, resolution: float, inflation: float) -> PlanningGrid:
    """The taxis' planning grid of a world (built once and shared by the fleet's pilots; a
    PlanningGrid is immutable)."""
    return PlanningGrid.from_world(make_world(world_name, seed), resolution, inflation)


def add_taxi(parts: AutonomyParts) -> None:
    """A fleet boat: ``TaxiPilot`` (rides from the coordinator's ``task``, A* around the boats
    its lidar sees) feeding the NMPC its reference."""
    builder, scenario, vessel = parts.builder, parts.scenario, parts.vessel
    if not parts.member:
        raise ValueError("make_autonomy: controller 'taxi' needs the fleet member's name")
    cfg = scenario.fleet.taxi
    me = next(v for v in scenario.fleet.vessels if v.name == parts.member)
    enabled = scenario.sensors.enabled
    kind, lidar, port = None, None, None
    if "lidar3d" in enabled:
        kind, lidar, port = "3d", scenario.sensors.lidar3d, "lidar_points"
    elif "lidar2d" in enabled:
        kind, lidar, port = "2d", scenario.sensors.lidar2d, "lidar_scan"
    pilot = builder.AddNamedSystem(
        "taxi_pilot",
        TaxiPilot(
            cfg,
            taxi_grid(scenario.world, scenario.seed, cfg.resolution, cfg.inflation),
            me.initial_state,
            lidar_mount=lidar.mount if lidar else None,
            lidar_kind=kind,
            lidar_period=1.0 / sample_rate(lidar) if lidar else 0.1,
            hull_radius=float(np.hypot(vessel.hull.length, vessel.hull.beam) / 2),
            fail_at=me.fail_at if me.fail_at >= 0 else math.inf,
        ),
    )
    nmpc = builder.AddNamedSystem("nmpc", Nmpc(vessel, scenario.nmpc, None))
    builder.Connect(parts.estimate, pilot.GetInputPort("state_estimate"))
    builder.Connect(parts.estimate, nmpc.GetInputPort("state_estimate"))
    builder.Connect(
        pilot.GetOutputPort("reference_trajectory"), nmpc.GetInputPort("reference_trajectory")
    )
    builder.ExportInput(pilot.GetInputPort("task"), "task")
    if port is not None:
        builder.ExportInput(pilot.GetInputPort(port), port)
    for out in ("thruster_command", "predicted_trajectory", "nmpc_failures", "nmpc_diagnostics"):
        builder.ExportOutput(nmpc.GetOutputPort(out), out)
    builder.ExportOutput(pilot.GetOutputPort("taxi_status"), "taxi_status")
    builder.ExportOutput(pilot.GetOutputPort("reference"), "reference")


def check_taxi(s: Scenario, file: str) -> None:
    validate_fleet(s, file)


def check_not_fleet(s: Scenario, file: str) -> None:
    if s.fleet.vessels:
        raise ConfigError(file, "controller", "'taxi' (the scenario has a fleet)", s.controller)


CONTROLLERS.register(
    "baseline",
    Variant(add_baseline, "LOS guidance + heading/speed law + thrust allocation", check_not_fleet),
)
CONTROLLERS.register(
    "nmpc", Variant(add_nmpc, "Roboat II NMPC tracking an A* reference", check_not_fleet)
)
CONTROLLERS.register(
    "taxi", Variant(add_taxi, "a fleet boat: taxi pilot + NMPC", check_taxi, needs_waypoints=False)
)
