"""``build_fleet_diagram``: K boats in one world and the coordinator that dispatches them."""

import dataclasses

from pydrake.geometry import Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Multiplexer

from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.scenario import Scenario
from usvdrake.systems.guidance.coordinator import Coordinator
from usvdrake.systems.guidance.fleet_assignment import DeliveryRequest, GridGraph
from usvdrake.systems.guidance.grid_astar import PlanningGrid
from usvdrake.vessel import VesselParams, load_vessel
from usvdrake.worlds import make_world
from usvdrake.worlds.world import World

PICKUP_COLOR = Rgba(0.1, 0.8, 0.2, 0.9)
DESTINATION_COLOR = Rgba(0.9, 0.15, 0.15, 0.9)


def fleet_requests(scenario: Scenario) -> list[DeliveryRequest]:
    """The scenario's ride requests as the coordinator takes them."""
    return [
        DeliveryRequest(
            float(r.time), tuple(map(float, r.pickup)), tuple(map(float, r.destination))
        )
        for r in scenario.fleet.requests
    ]


def build_fleet_diagram(
    scenario: Scenario,
    meshcat: Meshcat | None = None,
    vessel: VesselParams | None = None,
    world: World | None = None,
) -> Diagram:
    """One diagram for a fleet scenario (controller ``taxi``).

    Subsystems: one vessel diagram per ``fleet.vessels`` entry (named after it, e.g.
    ``roboat_1``: its own station and autonomy, see :func:`build_vessel_diagram`), a
    ``coordinator`` (:class:`Coordinator`) wired to every boat's ``state_estimate``,
    ``taxi_status`` and ``task``, and per boat a multiplexer feeding the other boats' true
    states to its lidar (``other_vessels``: the simulator's stand-in for seeing real hulls).
    Exported: every boat's outputs as ``<boat>.<port>`` (``roboat_1.ground_truth_state``) and
    the coordinator's ``fleet_status`` and ``all_served``. With ``meshcat`` every
    boat is drawn in its colour in one scene, with the pickups (green) and destinations (red).
    """
    fleet = scenario.fleet
    if scenario.controller != "taxi" or not fleet.vessels:
        raise ValueError(f"build_fleet_diagram: scenario {scenario.name!r} has no fleet")
    vessel = vessel if vessel is not None else load_vessel(scenario.vessel)
    world = world if world is not None else make_world(scenario.world, scenario.seed)
    builder = DiagramBuilder()
    names = [v.name for v in fleet.vessels]
    vessels = {}
    for v in fleet.vessels:
        own = dataclasses.replace(scenario, initial_state=list(v.initial_state))
        vessels[v.name] = builder.AddNamedSystem(
            v.name,
            build_vessel_diagram(own, meshcat=meshcat, member=v.name, vessel=vessel, world=world),
        )
    grid = PlanningGrid.from_world(world, fleet.assignment_resolution, fleet.taxi.inflation)
    requests = fleet_requests(scenario)
    coordinator = builder.AddNamedSystem(
        "coordinator", Coordinator(requests, names, GridGraph(grid), fleet.coordinator_period)
    )
    for name, boat in vessels.items():
        builder.Connect(
            boat.GetOutputPort("state_estimate"), coordinator.GetInputPort(f"{name}_state")
        )
        builder.Connect(
            boat.GetOutputPort("taxi_status"), coordinator.GetInputPort(f"{name}_status")
        )
        builder.Connect(coordinator.GetOutputPort(f"{name}_task"), boat.GetInputPort("task"))
        if boat.HasInputPort("other_vessels"):
            others = [o for o in names if o != name]
            mux = builder.AddNamedSystem(f"{name}_sees", Multiplexer([6] * len(others)))
            for i, other in enumerate(others):
                builder.Connect(
                    vessels[other].GetOutputPort("ground_truth_state"), mux.get_input_port(i)
                )
            builder.Connect(mux.get_output_port(), boat.GetInputPort("other_vessels"))
    for name, boat in vessels.items():  # as manipulation's station: "roboat_1.state_estimate"
        for i in range(boat.num_output_ports()):
            port = boat.get_output_port(i)
            builder.ExportOutput(port, f"{name}.{port.get_name()}")
    builder.ExportOutput(coordinator.GetOutputPort("fleet_status"), "fleet_status")
    builder.ExportOutput(coordinator.GetOutputPort("all_served"), "all_served")
    if meshcat is not None:
        draw_requests(meshcat, requests)
    diagram = builder.Build()
    diagram.set_name(scenario.name or "fleet")
    return diagram


def draw_requests(meshcat: Meshcat, requests: list[DeliveryRequest]) -> None:
    """Each request's pickup (green) and destination (red) as a ball under ``/requests/<i>``."""
    for i, r in enumerate(requests):
        for what, xy, color in (
            ("pickup", r.pickup, PICKUP_COLOR),
            ("destination", r.destination, DESTINATION_COLOR),
        ):
            path = f"/requests/{i}/{what}"
            meshcat.SetObject(path, Sphere(0.6), color)
            meshcat.SetTransform(path, RigidTransform([xy[0], xy[1], 0.6]))
