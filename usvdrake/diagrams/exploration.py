"""The NTNU explorer as a controller (``controller: explore``).

FrontierExplorer → AStarPlanner → VelocitySetpointLaw → ReferenceModel → PdController →
ThrustAllocation, on the estimator's view of the SLAM pose (the passive observer, or the
oracle). The vessel maps the world by itself; the mission is complete when no reachable
frontier is left.
"""

import numpy as np

from usvdrake.diagrams.variants import CONTROLLERS, ESTIMATORS, AutonomyParts, Variant
from usvdrake.errors import ConfigError
from usvdrake.scenario import Scenario
from usvdrake.systems.control.pd_controller import PdController
from usvdrake.systems.control.reference_model import ReferenceModel
from usvdrake.systems.guidance.astar_planner import AStarPlanner
from usvdrake.systems.guidance.frontier_explorer import FrontierExplorer
from usvdrake.systems.guidance.operator import OperatorPanel, parse_mode
from usvdrake.systems.guidance.velocity_setpoint import ExplorationReport, VelocitySetpointLaw
from usvdrake.systems.vessel.thrust_allocation import ThrustAllocation
from usvdrake.typed_yaml import get_dotted

EXPLORATION_OUTPUTS = (  # (system, port, exported name)
    ("allocation", "thruster_command", "thruster_command"),
    ("allocation", "tau_achieved", "tau_achieved"),
    ("pd", "tau_desired", "tau_desired"),
    ("explorer", "exploration_finished", "mission_complete"),
    ("explorer", "explorer_status", "explorer_status"),
    ("explorer", "planning_map", "planning_map"),
    ("explorer", "goals", "goals"),
    ("planner", "path", "path"),
    ("planner", "destination", "destination"),
    ("law", "setpoint", "setpoint"),
    ("law", "lookahead", "lookahead"),
    ("panel", "operator_command", "operator_command"),
    ("report", "reference", "reference"),
)


def add_exploration(parts: AutonomyParts) -> None:
    builder, scenario, world = parts.builder, parts.scenario, parts.world
    cfg = scenario.exploration
    pose0 = np.asarray(scenario.initial_state[:3], float)
    slam = parts.slam()
    allocation = builder.AddNamedSystem("thrust_allocation", ThrustAllocation(parts.vessel))
    parts.tau_achieved = allocation.GetOutputPort("tau_achieved")
    estimate = parts.estimate = ESTIMATORS.get(scenario.estimator).add(parts)
    bias = parts.disturbance_estimate

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
    pd = builder.AddNamedSystem("pd_controller", PdController(parts.vessel.hydrodynamics, cfg.pd))
    bounds = world.water.bounds if not world.water.is_empty else world.bounds
    panel = builder.AddNamedSystem(
        "operator_panel",
        OperatorPanel(parts.meshcat if cfg.operator_controls else None, bounds, cfg.commands),
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

    systems = dict(
        allocation=allocation, pd=pd, explorer=explorer, planner=planner, law=law,
        panel=panel, report=report,
    )  # fmt: skip
    for system, port, name in EXPLORATION_OUTPUTS:
        builder.ExportOutput(systems[system].GetOutputPort(port), name)


def check_exploration(s: Scenario, file: str) -> None:
    """The exploration's own settings and what it needs of the rest of the scenario."""
    if s.slam.method == "none":
        raise ConfigError(
            file, "slam.method", "'hector' or 'graph' (exploration maps as it goes)", "'none'"
        )
    if s.estimator not in ("observer", "oracle"):
        raise ConfigError(
            file, "estimator", "'observer' or 'oracle' with controller explore", repr(s.estimator)
        )
    e = s.exploration
    for key in (
        "explorer.resolution",
        "explorer.planning_period",
        "setpoint_rate_hz",
        "observer.rate_hz",
        "observer.bias_time_constant",
        "pd.rate_hz",
    ):
        if not get_dotted(e, key) > 0:
            raise ConfigError(
                file, f"exploration.{key}", "a positive number", repr(get_dotted(e, key))
            )
    for key in ("observer.cutoff", "pd.omega_n", "pd.zeta"):
        v = get_dotted(e, key)
        if len(v) != 3 or min(v) <= 0:
            raise ConfigError(file, f"exploration.{key}", "3 positive numbers", repr(v))
    for key in ("explorer.inflation", "explorer.near_free_radius", "explorer.visited_radius"):
        if get_dotted(e, key) < 0:
            raise ConfigError(file, f"exploration.{key}", "a number >= 0", repr(get_dotted(e, key)))
    if e.explorer.connection_distance not in (1, 2, 3, 4):
        raise ConfigError(
            file,
            "exploration.explorer.connection_distance",
            "1, 2, 3 or 4",
            repr(e.explorer.connection_distance),
        )
    for i, c in enumerate(e.commands):
        key = f"exploration.commands[{i}]"
        try:
            mode = parse_mode(c.mode)
        except ValueError:
            raise ConfigError(file, f"{key}.mode", "explore, goto or stop", repr(c.mode)) from None
        if mode.name == "GOTO" and len(c.goal) != 2:
            raise ConfigError(file, f"{key}.goal", "[x, y] for goto", f"{len(c.goal)} numbers")
    if s.fleet.vessels:
        raise ConfigError(file, "controller", "'taxi' (the scenario has a fleet)", s.controller)


CONTROLLERS.register(
    "explore",
    Variant(
        add_exploration,
        "NTNU autonomous exploration: frontiers, weighted A*, velocity law, PD",
        check_exploration,
        adds_estimator=True,
        needs_waypoints=False,
    ),
)
