"""``build_vessel_diagram``: one vessel = station (sim | hardware) + autonomy, wired by name."""

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram, DiagramBuilder

from usvdrake.diagrams.autonomy import make_autonomy
from usvdrake.diagrams.encounter_diagram import add_traffic, mission_traffic
from usvdrake.diagrams.hardware_station import make_hardware_station
from usvdrake.diagrams.station import make_sim_station
from usvdrake.scenario import Scenario
from usvdrake.vessel import VesselParams, load_vessel
from usvdrake.viz.exploration_visualizer import ExplorationVisualizer
from usvdrake.viz.lidar_visualizer import LidarVisualizer
from usvdrake.viz.meshcat_world import (
    draw_occupancy,
    draw_world,
    frame_view,
    light_scene,
    view_bounds,
)
from usvdrake.viz.occupancy_visualizer import OccupancyVisualizer
from usvdrake.viz.point_map_visualizer import KeyframeMapVisualizer
from usvdrake.viz.trajectory_visualizer import TrajectoryVisualizer, draw_reference
from usvdrake.viz.vessel_visualizer import FLEET_COLORS, VesselVisualizer
from usvdrake.worlds import make_world
from usvdrake.worlds.world import World

# Inputs a vessel diagram takes from outside the vessel (the fleet): the coordinator's ride
# (``task``, to the autonomy) and the other boats' states (``other_vessels``, to the lidars).
FLEET_INPUTS = ("task", "other_vessels")


def build_vessel_diagram(
    scenario: Scenario,
    meshcat: Meshcat | None = None,
    hardware=None,
    member: str = "",
    vessel: VesselParams | None = None,
    world: World | None = None,
) -> Diagram:
    """The named vessel diagram of ``scenario``.

    Exports the station's ports (``thrust_measured``, ``ground_truth_state``) and the autonomy's
    (``thruster_command``, ``mission_complete``, ``reference``, ``tau_desired``, ``tau_achieved``,
    ``state_estimate``) at the top level. With ``meshcat``, a ``VesselVisualizer`` draws the hull,
    thrust arrows and trail, and the world is drawn once.

    ``hardware``: None simulates the station (plant, environment, simulated sensors). True (the
    scenario's ``hardware`` section) or a :class:`~usvdrake.scenario.HardwareConfig` builds the
    hardware station instead (:mod:`usvdrake.diagrams.hardware_station`: serial/UDP devices
    with the same port names, a watchdog, no ``ground_truth_state``); the autonomy half is the
    same. Meshcat then draws the vessel at its *estimated* state.

    ``member``: the fleet boat this is (controller ``taxi``): the diagram is named after it,
    also exports the inputs ``task`` and ``other_vessels`` (wired by ``build_fleet_diagram``),
    and draws under ``/vessels/<member>`` in the boat's colour; the world is drawn by the first.

    ``vessel`` and ``world``: the scenario's nominal vessel and its world when the caller has
    resolved them already (a runner does so once per run); None loads and builds them here.
    """
    # nominal: the station applies scenario.model_error
    vessel = vessel if vessel is not None else load_vessel(scenario.vessel)
    world = world if world is not None else make_world(scenario.world, scenario.seed)
    builder = DiagramBuilder()
    autonomy_system = make_autonomy(scenario, vessel, world, meshcat=meshcat, member=member)
    needs = [
        autonomy_system.get_input_port(i).get_name()
        for i in range(autonomy_system.num_input_ports())
    ]
    if hardware is None:
        station_system = make_sim_station(scenario, vessel, world)
    else:
        hw = scenario.hardware if hardware is True else hardware
        station_system = make_hardware_station(scenario, vessel, world, hw, needs)
    station = builder.AddNamedSystem("station", station_system)
    autonomy = builder.AddNamedSystem("autonomy", autonomy_system)
    builder.Connect(
        autonomy.GetOutputPort("thruster_command"), station.GetInputPort("thruster_command")
    )
    # The autonomy's inputs are station outputs of the same name (ports are the contract).
    for i in range(station.num_input_ports()):
        name = station.get_input_port(i).get_name()
        if name in FLEET_INPUTS:
            builder.ExportInput(station.get_input_port(i), name)
    for i in range(autonomy.num_input_ports()):
        name = autonomy.get_input_port(i).get_name()
        if name in FLEET_INPUTS:
            builder.ExportInput(autonomy.get_input_port(i), name)
            continue
        if not station.HasOutputPort(name):
            raise ValueError(
                f"the autonomy needs station output {name!r}; enable its sensor in the scenario"
            )
        builder.Connect(station.GetOutputPort(name), autonomy.get_input_port(i))

    for i in range(station.num_output_ports()):
        name = station.get_output_port(i).get_name()
        builder.ExportOutput(station.get_output_port(i), name)
    for i in range(autonomy.num_output_ports()):
        name = autonomy.get_output_port(i).get_name()
        builder.ExportOutput(autonomy.get_output_port(i), name)
    if scenario.traffic.situation:  # target ships, their AIS and our tracker (issue 37)
        traffic = mission_traffic(scenario.traffic.situation, vessel, scenario.initial_state)
        add_traffic(
            builder, traffic, vessel.hull.length, scenario.seed, scenario.traffic.ais_period
        )

    if meshcat is not None:
        # the drawn pose: the truth in simulation, the estimate on the water
        drawn_state = (
            station.GetOutputPort("ground_truth_state")
            if station.HasOutputPort("ground_truth_state")
            else autonomy.GetOutputPort("state_estimate")
        )
        viz_cfg = scenario.visualization
        index = [v.name for v in scenario.fleet.vessels].index(member) if member else 0
        if index == 0:
            draw_world(meshcat, world, show_gps_denied=viz_cfg.gps_denied)
            if viz_cfg.occupancy_resolution > 0:
                draw_occupancy(meshcat, world.occupancy(viz_cfg.occupancy_resolution))
        if autonomy.HasOutputPort("predicted_trajectory"):
            nmpc = autonomy.GetSubsystemByName("nmpc")
            if nmpc.reference is not None:
                draw_reference(meshcat, nmpc.reference)
            path = f"/{member}/nmpc/prediction" if member else "/nmpc/prediction"
            pred = builder.AddNamedSystem(
                "prediction_visualizer", TrajectoryVisualizer(meshcat, path)
            )
            builder.Connect(
                autonomy.GetOutputPort("predicted_trajectory"), pred.GetInputPort("trajectory")
            )
        if autonomy.HasOutputPort("slam_map"):
            slam_map = builder.AddNamedSystem("slam_map_visualizer", OccupancyVisualizer(meshcat))
            builder.Connect(autonomy.GetOutputPort("slam_map"), slam_map.GetInputPort("map"))
        if autonomy.HasOutputPort("slam_map3d"):
            map3d = builder.AddNamedSystem("slam_map3d_visualizer", KeyframeMapVisualizer(meshcat))
            builder.Connect(autonomy.GetOutputPort("slam_map3d"), map3d.GetInputPort("map"))
        if autonomy.HasOutputPort("path"):
            ex_viz = builder.AddNamedSystem(
                "exploration_visualizer", ExplorationVisualizer(meshcat)
            )
            for port in ("path", "destination", "planning_map", "goals", "setpoint"):
                builder.Connect(autonomy.GetOutputPort(port), ex_viz.GetInputPort(port))
        if viz_cfg.lidar_hits:
            for port, name, cfg, three_d in (
                ("lidar_scan", "lidar2d", scenario.sensors.lidar2d, False),
                ("lidar_points", "lidar3d", scenario.sensors.lidar3d, True),
            ):
                if station.HasOutputPort(port):
                    hits = builder.AddNamedSystem(
                        f"{name}_visualizer", LidarVisualizer(meshcat, name, cfg.mount, three_d)
                    )
                    builder.Connect(drawn_state, hits.GetInputPort("state"))
                    builder.Connect(station.GetOutputPort(port), hits.GetInputPort("lidar"))
        # the view: the planned route (start and waypoints), or the water for open-ended runs
        route = [scenario.initial_state[:2], *scenario.mission.waypoints]
        if len(route) > 1:
            bounds = view_bounds(route)
        elif not world.water.is_empty:
            bounds = world.water.bounds
        else:
            bounds = view_bounds([np.add(route[0], d) for d in ((-20, -20), (20, 20))])
        if index == 0:
            light_scene(meshcat)
            frame_view(meshcat, bounds)
        # a 2 m boat in a 200 m view: a halo ~3 % of the view across makes it findable
        span = max(bounds[2] - bounds[0], bounds[3] - bounds[1])
        marker = max(0.8 * vessel.hull.length, 0.015 * span)
        viz = builder.AddNamedSystem(
            "vessel_visualizer",
            VesselVisualizer(
                meshcat,
                vessel,
                scenario.visualization,
                scenario.mission.waypoints,
                prefix=f"/vessels/{member}" if member else None,
                color=FLEET_COLORS[index % len(FLEET_COLORS)] if member else None,
                marker_radius=marker,
            ),
        )
        builder.Connect(drawn_state, viz.GetInputPort("state"))
        builder.Connect(
            station.GetOutputPort("thrust_measured"), viz.GetInputPort("thrust_applied")
        )

    diagram = builder.Build()
    diagram.set_name(member or f"{scenario.vessel}_vessel")
    return diagram
