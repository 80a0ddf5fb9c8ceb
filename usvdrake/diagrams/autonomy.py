"""The autonomy half: estimate → guidance → controller → thruster commands.

Estimators: ``oracle`` passes the station's ``ground_truth_state`` through (the only place the
autonomy may read ground truth); ``nmhe`` is 000's moving-horizon estimator on the station's
``pose_measurement`` and ``thrust_measured``. Controllers: ``baseline`` (LOS guidance, PD
heading/speed law, constrained thrust allocation) or ``nmpc`` (000's NMPC tracking an A*
reference through the mission's goals, thruster forces straight out).
"""

import functools
import math
from dataclasses import replace

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import PassThrough

from usvdrake.scenario import Scenario
from usvdrake.systems.control.heading_speed_controller import HeadingSpeedController
from usvdrake.systems.guidance.los_guidance import LosGuidance
from usvdrake.systems.vessel.thrust_allocation import ThrustAllocation
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World

DEFAULT_NMPC_SPEED = 0.6  # [m/s] 000 §VI-B tracks at u = 0.6 m/s, v = 0


def make_reference(scenario: Scenario, world: World):
    """The timed reference the NMPC tracks: A* through the mission's goals in sequence."""
    from usvdrake.systems.guidance.reference_trajectory import ReferenceTrajectory

    speed = scenario.mission.speed or DEFAULT_NMPC_SPEED
    return ReferenceTrajectory.from_goals(
        world, scenario.initial_state[:2], scenario.mission.waypoints, speed=speed
    )


def _add_oracle(builder: DiagramBuilder):
    """The oracle estimator: ``ground_truth_state`` passed through (the only place the
    autonomy reads ground truth)."""
    oracle = builder.AddNamedSystem("oracle_estimator", PassThrough(6))
    builder.ExportInput(oracle.get_input_port(), "ground_truth_state")
    return oracle


def _add_slam(builder: DiagramBuilder, scenario: Scenario, world: World, pose=None):
    """The 2D SLAM on the exported ``lidar_scan``; its ports exported, the system returned.
    ``known_poses`` maps at ``pose`` (an output port: the oracle's estimate) instead."""
    from usvdrake.sensors.lidar_model import sample_rate
    from usvdrake.systems.slam.known_pose_mapper import KnownPoseMapper
    from usvdrake.systems.slam.lidar_slam2d import HectorSlam, LidarSlam2D

    if scenario.slam.method == "factor_graph":
        return _add_factor_graph_slam(builder, scenario, world.datum)
    lidar = scenario.sensors.lidar2d
    period = 1.0 / sample_rate(lidar)
    start = scenario.initial_state[:3]
    if scenario.slam.method == "known_poses":
        h = scenario.slam.hector  # the grid's extent and resolution
        mapper = KnownPoseMapper(
            h.map_origin, h.map_size, h.resolution, lidar.mount, period, h.max_range
        )
        slam = builder.AddNamedSystem("known_pose_mapper", mapper)
        builder.Connect(pose, slam.GetInputPort("state_estimate"))
    elif scenario.slam.method == "graph":
        slam = LidarSlam2D(scenario.slam.graph, start, lidar.mount, period)
    else:
        slam = HectorSlam(scenario.slam.hector, start, lidar.mount, period)
    if scenario.slam.method != "known_poses":
        slam = builder.AddNamedSystem("lidar_slam_2d", slam)
    builder.ExportInput(slam.GetInputPort("lidar_scan"), "lidar_scan")
    for port in ("slam_pose", "slam_covariance", "slam_map"):
        builder.ExportOutput(slam.GetOutputPort(port), port)
    return slam


def _add_factor_graph_slam(builder: DiagramBuilder, scenario: Scenario, world_datum: str):
    """000 §V's lidar-IMU-GPS factor graph on the exported ``lidar_points``, ``imu`` and
    ``gps``; its ports exported, the system returned."""
    from usvdrake.slam3d import settings_from_scenario
    from usvdrake.systems.slam.factor_graph_slam import FactorGraphSlam

    cfg, mount, datum = settings_from_scenario(scenario, world_datum)
    slam = builder.AddNamedSystem(
        "factor_graph_slam",
        FactorGraphSlam(
            cfg, scenario.initial_state, mount, scenario.sensors.imu.rate_hz, datum=datum
        ),
    )
    for port in ("lidar_points", "imu", "gps"):
        builder.ExportInput(slam.GetInputPort(port), port)
    for port in ("slam_pose", "slam_covariance", "slam_state", "slam_pose3d", "slam_map3d"):
        builder.ExportOutput(slam.GetOutputPort(port), port)
    return slam


def _add_exploration(
    builder, scenario: Scenario, vessel: VesselParams, world: World, slam, meshcat, oracle=None
):
    """003's loop: FrontierExplorer → AStarPlanner → VelocitySetpointLaw → ReferenceModel →
    PdController → ThrustAllocation, on the passive observer's estimate of the SLAM pose."""
    from usvdrake.systems.control.passive_observer import PassiveObserver, fossen_gains
    from usvdrake.systems.control.pd_controller import PdController
    from usvdrake.systems.control.reference_model import ReferenceModel
    from usvdrake.systems.guidance.astar_planner import AStarPlanner
    from usvdrake.systems.guidance.frontier_explorer import FrontierExplorer
    from usvdrake.systems.guidance.operator import OperatorPanel
    from usvdrake.systems.guidance.velocity_setpoint import ExplorationReport, VelocitySetpointLaw

    cfg = scenario.exploration
    xi = vessel.hydrodynamics
    pose0 = np.asarray(scenario.initial_state[:3], float)
    allocation = builder.AddNamedSystem("thrust_allocation", ThrustAllocation(vessel))
    if scenario.estimator == "observer":
        obs_cfg = fossen_gains(
            xi, cfg.observer.cutoff, T=cfg.observer.bias_time_constant, rate_hz=cfg.observer.rate_hz
        )
        observer = builder.AddNamedSystem("passive_observer", PassiveObserver(xi, obs_cfg, pose0))
        builder.Connect(slam.GetOutputPort("slam_pose"), observer.GetInputPort("pose_measurement"))
        builder.Connect(allocation.GetOutputPort("tau_achieved"), observer.GetInputPort("tau"))
        estimate = observer.GetOutputPort("state_estimate")
        bias = observer.GetOutputPort("bias_estimate")
        builder.ExportOutput(bias, "bias_estimate")
    else:
        if oracle is None:
            oracle = _add_oracle(builder)
        estimate, bias = oracle.get_output_port(), None

    ex = cfg.explorer
    explorer = builder.AddNamedSystem("frontier_explorer", FrontierExplorer(ex, pose0[:2]))
    planner = builder.AddNamedSystem(
        "astar_planner",
        AStarPlanner(
            ex.planning_period, ex.start_delay + 1e-3, ex.connection_distance, ex.replan_margin
        ),
    )
    law = builder.AddNamedSystem(
        "velocity_setpoint_law", VelocitySetpointLaw(pose0[2], pose0[:2], cfg.setpoint_rate_hz)
    )
    reference = builder.AddNamedSystem("reference_model", ReferenceModel(cfg.reference, pose0))
    pd = builder.AddNamedSystem("pd_controller", PdController(xi, cfg.pd))
    bounds = world.water.bounds if not world.water.is_empty else world.bounds
    panel = builder.AddNamedSystem(
        "operator_panel",
        OperatorPanel(meshcat if cfg.operator_controls else None, bounds, cfg.commands),
    )
    report = builder.AddNamedSystem("exploration_report", ExplorationReport())

    builder.Connect(slam.GetOutputPort("slam_map"), explorer.GetInputPort("slam_map"))
    builder.Connect(
        panel.GetOutputPort("operator_command"), explorer.GetInputPort("operator_command")
    )
    for system in (explorer, planner, law, pd):
        builder.Connect(estimate, system.GetInputPort("state_estimate"))
    builder.Connect(explorer.GetOutputPort("planning_map"), planner.GetInputPort("planning_map"))
    builder.Connect(explorer.GetOutputPort("goals"), planner.GetInputPort("goals"))
    builder.Connect(planner.GetOutputPort("path"), law.GetInputPort("path"))
    builder.ConnectInput("lidar_scan", law.GetInputPort("lidar_scan"))
    builder.Connect(law.GetOutputPort("setpoint"), reference.GetInputPort("setpoint"))
    builder.Connect(reference.GetOutputPort("reference"), pd.GetInputPort("reference"))
    if bias is not None:
        builder.Connect(bias, pd.GetInputPort("bias_estimate"))
    builder.Connect(pd.GetOutputPort("tau_desired"), allocation.GetInputPort("tau_desired"))
    builder.Connect(reference.GetOutputPort("reference"), report.GetInputPort("reference_model"))
    builder.Connect(law.GetOutputPort("lookahead"), report.GetInputPort("lookahead"))

    for system, port, name in (
        (allocation, "thruster_command", "thruster_command"),
        (allocation, "tau_achieved", "tau_achieved"),
        (pd, "tau_desired", "tau_desired"),
        (explorer, "exploration_finished", "mission_complete"),
        (explorer, "explorer_status", "explorer_status"),
        (explorer, "planning_map", "planning_map"),
        (explorer, "goals", "goals"),
        (planner, "path", "path"),
        (planner, "destination", "destination"),
        (law, "setpoint", "setpoint"),
        (law, "lookahead", "lookahead"),
        (panel, "operator_command", "operator_command"),
        (report, "reference", "reference"),
    ):
        builder.ExportOutput(system.GetOutputPort(port), name)
    builder.ExportOutput(estimate, "state_estimate")


@functools.lru_cache(maxsize=4)
def taxi_grid(world_name: str, seed: int, resolution: float, inflation: float):
    """The taxis' planning grid of a world (built once and shared by the fleet's pilots; a
    PlanningGrid is immutable)."""
    from usvdrake.systems.guidance.grid_astar import PlanningGrid
    from usvdrake.worlds import make_world

    return PlanningGrid.from_world(make_world(world_name, seed), resolution, inflation)


def _add_taxi(builder, scenario: Scenario, vessel: VesselParams, estimate, member: str):
    """A fleet boat (000 §III): ``TaxiPilot`` (rides from the coordinator's ``task``, A*
    around the boats its lidar sees) feeding the NMPC its reference."""
    from usvdrake.sensors.lidar_model import sample_rate
    from usvdrake.systems.control.nmpc_system import Nmpc
    from usvdrake.systems.guidance.taxi_pilot import TaxiPilot

    cfg = scenario.fleet.taxi
    me = next(v for v in scenario.fleet.vessels if v.name == member)
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
    builder.Connect(estimate, pilot.GetInputPort("state_estimate"))
    builder.Connect(estimate, nmpc.GetInputPort("state_estimate"))
    builder.Connect(
        pilot.GetOutputPort("reference_trajectory"), nmpc.GetInputPort("reference_trajectory")
    )
    builder.ExportInput(pilot.GetInputPort("task"), "task")
    if port is not None:
        builder.ExportInput(pilot.GetInputPort(port), port)
    builder.ExportOutput(nmpc.GetOutputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(nmpc.GetOutputPort("predicted_trajectory"), "predicted_trajectory")
    builder.ExportOutput(nmpc.GetOutputPort("nmpc_failures"), "nmpc_failures")
    builder.ExportOutput(pilot.GetOutputPort("taxi_status"), "taxi_status")
    builder.ExportOutput(pilot.GetOutputPort("reference"), "reference")


def make_autonomy(
    scenario: Scenario, vessel: VesselParams, world: World, meshcat=None, member: str = ""
) -> Diagram:
    """The autonomy diagram of ``scenario``. ``meshcat``: where the operator's controls go
    (exploration only); without it the operator is the scenario's command script. ``member``:
    which of the fleet's boats this is (controller ``taxi``)."""
    builder = DiagramBuilder()
    if scenario.controller == "explore":
        oracle = _add_oracle(builder) if scenario.slam.method == "known_poses" else None
        slam = _add_slam(builder, scenario, world, oracle.get_output_port() if oracle else None)
        _add_exploration(builder, scenario, vessel, world, slam, meshcat, oracle)
        autonomy = builder.Build()
        autonomy.set_name("autonomy")
        return autonomy
    if scenario.estimator == "nmhe":
        from usvdrake.systems.estimation.nmhe_system import Nmhe

        nmhe_cfg = scenario.nmhe
        with_imu = "imu" in scenario.sensors.enabled
        if with_imu:  # the NMHE's IMU model where the IMU sits
            nmhe_cfg = replace(nmhe_cfg, imu_lever_arm=list(scenario.sensors.imu.lever_arm))
        nmhe = builder.AddNamedSystem(
            "nmhe", Nmhe(vessel, nmhe_cfg, initial_state=scenario.initial_state)
        )
        builder.ExportInput(nmhe.GetInputPort("pose_measurement"), "pose_measurement")
        builder.ExportInput(nmhe.GetInputPort("thrust_measured"), "thrust_measured")
        if with_imu:  # 000's NMHE with the IMU's interval means
            from usvdrake.sensors.imu_interval import ImuIntervalMean

            imu_mean = builder.AddNamedSystem(
                "imu_interval_mean",
                ImuIntervalMean(
                    1.0 / nmhe_cfg.rate_hz,
                    1.0 / scenario.sensors.imu.rate_hz,
                    offset=0.5 * nmhe_cfg.update_offset,
                ),
            )
            builder.ExportInput(imu_mean.GetInputPort("imu"), "imu")
            builder.Connect(imu_mean.GetOutputPort("imu_mean"), nmhe.GetInputPort("imu_mean"))
        builder.ExportOutput(nmhe.GetOutputPort("nmhe_failures"), "nmhe_failures")
        builder.ExportOutput(nmhe.GetOutputPort("nmhe_solve_ms"), "nmhe_solve_ms")
        builder.ExportOutput(nmhe.GetOutputPort("estimate_time"), "estimate_time")
        estimate = nmhe.GetOutputPort("state_estimate")
        nmhe_force = nmhe.GetOutputPort("tau_env_estimate")
    elif scenario.estimator == "slam":  # 000 §V: the controllers use the SLAM's [x y ψ]
        estimate = _add_slam(builder, scenario, world).GetOutputPort("slam_state")
    else:
        estimate = _add_oracle(builder).get_output_port()

    if scenario.controller == "taxi":
        if not member:
            raise ValueError("make_autonomy: controller 'taxi' needs the fleet member's name")
        _add_taxi(builder, scenario, vessel, estimate, member)
    elif scenario.controller == "nmpc":
        from usvdrake.systems.control.nmpc_system import Nmpc
        from usvdrake.systems.guidance.reference_monitor import ReferenceMonitor

        reference = make_reference(scenario, world)
        nmpc = builder.AddNamedSystem("nmpc", Nmpc(vessel, scenario.nmpc, reference))
        monitor = builder.AddNamedSystem(
            "reference_monitor", ReferenceMonitor(reference, scenario.mission.acceptance_radius)
        )
        builder.Connect(estimate, nmpc.GetInputPort("state_estimate"))
        if scenario.estimator == "nmhe" and scenario.nmpc.disturbance_source == "estimator":
            builder.Connect(nmhe_force, nmpc.GetInputPort("disturbance_estimate"))
        builder.Connect(estimate, monitor.GetInputPort("state_estimate"))
        builder.ExportOutput(nmpc.GetOutputPort("thruster_command"), "thruster_command")
        builder.ExportOutput(nmpc.GetOutputPort("predicted_trajectory"), "predicted_trajectory")
        builder.ExportOutput(nmpc.GetOutputPort("nmpc_failures"), "nmpc_failures")
        builder.ExportOutput(monitor.GetOutputPort("mission_complete"), "mission_complete")
        builder.ExportOutput(monitor.GetOutputPort("reference"), "reference")
    else:
        guidance = builder.AddNamedSystem(
            "los_guidance", LosGuidance(scenario.mission, scenario.control, vessel.cruise_speed)
        )
        controller = builder.AddNamedSystem(
            "heading_speed_controller",
            HeadingSpeedController(vessel.hydrodynamics, scenario.control),
        )
        allocation = builder.AddNamedSystem("thrust_allocation", ThrustAllocation(vessel))
        builder.Connect(estimate, guidance.GetInputPort("state_estimate"))
        builder.Connect(estimate, controller.GetInputPort("state_estimate"))
        builder.Connect(guidance.GetOutputPort("reference"), controller.GetInputPort("reference"))
        builder.Connect(
            controller.GetOutputPort("tau_desired"), allocation.GetInputPort("tau_desired")
        )
        builder.ExportOutput(allocation.GetOutputPort("thruster_command"), "thruster_command")
        builder.ExportOutput(guidance.GetOutputPort("mission_complete"), "mission_complete")
        builder.ExportOutput(guidance.GetOutputPort("reference"), "reference")
        builder.ExportOutput(controller.GetOutputPort("tau_desired"), "tau_desired")
        builder.ExportOutput(allocation.GetOutputPort("tau_achieved"), "tau_achieved")
    builder.ExportOutput(estimate, "state_estimate")
    if scenario.slam.method != "none" and scenario.estimator != "slam":
        _add_slam(builder, scenario, world)
    autonomy = builder.Build()
    autonomy.set_name("autonomy")
    return autonomy
