"""The fleet (Roboat II §III): assignment by path cost, the request ledger, seeing and avoiding
other boats, the coordinator and the fleet diagram."""

import dataclasses
import json

import numpy as np
import pytest
import shapely
from pydrake.systems.analysis import Simulator

from usvdrake.diagrams import load_scenario
from usvdrake.diagrams.fleet_diagram import build_fleet_diagram
from usvdrake.scenario import FleetVesselConfig, RequestConfig
from usvdrake.sensors.lidar3d import Lidar3D
from usvdrake.sensors.lidar_model import LidarConfig, sensor_to_world
from usvdrake.sensors.sampled_lidar import OtherVessels
from usvdrake.systems.guidance.coordinator import Coordinator
from usvdrake.systems.guidance.fleet_assignment import (
    DeliveryRequest,
    Dispatch,
    GridGraph,
    closest_vessel,
)
from usvdrake.systems.guidance.grid_astar import PlanningGrid, grid_astar, path_cost
from usvdrake.systems.guidance.taxi_pilot import IDLE, STATUS
from usvdrake.systems.guidance.taxi_planning import (
    Blob,
    detect_vessels,
    grid_around,
    path_conflicts,
)
from usvdrake.worlds import make_world
from usvdrake.worlds.raycast import Scene
from usvdrake.worlds.solids import box
from usvdrake.worlds.world import OccupancyGrid


@pytest.fixture(scope="module")
def canals():
    world = make_world("amsterdam_canals", 0)
    grid = PlanningGrid.from_world(world, 1.0, 1.6)
    return world, grid, GridGraph(grid)


def brute_force_cost(grid: PlanningGrid, a, b) -> float:
    """One A* per pair: the independent check of the Dijkstra costs."""
    sa, _ = grid.snap(np.asarray(a, float), "a", 2.0)
    sb, _ = grid.snap(np.asarray(b, float), "b", 2.0)
    cells = grid_astar(grid.blocked, sa, sb)
    return np.inf if cells is None else path_cost(cells) * grid.resolution


def free_water_points(world, grid, n, rng):
    lo, hi = np.array(world.bounds[:2]), np.array(world.bounds[2:])
    pts = []
    while len(pts) < n:
        p = lo + rng.random(2) * (hi - lo)
        if grid.clearance_at(p)[0] > 2.0:
            pts.append(p)
    return np.array(pts)


def test_path_costs_equal_one_astar_per_vessel_and_the_closest_is_the_brute_force_argmin(canals):
    world, grid, graph = canals
    rng = np.random.default_rng(3)
    for trial in range(4):
        pickup, *boats = free_water_points(world, grid, 4, rng)
        vessels = {f"boat{k}": xy for k, xy in enumerate(boats)}
        name, costs = closest_vessel(graph, pickup, vessels)
        brute = {n: brute_force_cost(grid, xy, pickup) for n, xy in vessels.items()}
        for n in vessels:
            assert costs[n] == pytest.approx(brute[n], abs=1e-6), (trial, n)
        assert name == min(brute, key=brute.get)
        # a path is never shorter than the straight line (to the snap and a cell's rounding)
        straight = {n: np.hypot(*(xy - pickup)) for n, xy in vessels.items()}
        assert all(costs[n] >= straight[n] - 1.5 for n in vessels)


def test_the_closest_by_path_is_not_the_closest_by_straight_line_across_the_ring(canals):
    _, _, graph = canals
    pickup = (-152.1, -194.6)  # inner ring
    across = np.array([-187.6, -267.9])  # outer ring, 75 m away in a straight line
    along = np.array([-35.2, -250.5])  # inner ring, 130 m away
    name, costs = closest_vessel(graph, pickup, {"across": across, "along": along})
    assert np.hypot(*(across - pickup)) < np.hypot(*(along - pickup))
    assert name == "along" and costs["across"] > costs["along"]


def dispatch_with(requests, vessels=("a", "b")):
    return Dispatch([DeliveryRequest(*r) for r in requests], list(vessels))


def test_dispatch_queues_until_a_vessel_is_released_then_serves_oldest_first(canals):
    _, _, graph = canals
    d = dispatch_with(
        [
            (0.0, (-152.1, -194.6), (-35.2, -250.5)),
            (5.0, (-207.2, -145.1), (-152.1, -194.6)),
            (6.0, (145.1, -207.2), (34.4, -244.6)),
        ],
        vessels=("a",),
    )
    pos = {"a": np.array([-176.8, -176.8])}
    assert d.assign(0.0, graph, pos) == [0]
    assert d.assign(10.0, graph, pos) == []  # a is busy: 1 and 2 wait
    assert d.waiting(10.0) == [1, 2]
    d.mark(0, "picked_up", 50.0)
    d.mark(0, "delivered", 150.0)
    assert d.assign(151.0, graph, pos) == []  # delivered but not yet released (alighting)
    d.mark(0, "released", 170.0)
    assert d.assign(171.0, graph, pos) == [1]  # the older request first
    m = d.metrics()
    assert m["requests_served"] == 1 and m["mean_wait_s"] == pytest.approx(50.0)
    assert m["mean_trip_s"] == pytest.approx(100.0)
    with pytest.raises(ValueError, match="unknown event"):
        d.mark(0, "teleported", 1.0)


def test_a_failed_vessel_gives_back_a_ride_it_has_not_picked_up_and_strands_one_it_has(canals):
    _, _, graph = canals
    d = dispatch_with(
        [(0.0, (-152.1, -194.6), (-35.2, -250.5)), (0.0, (145.1, -207.2), (34.4, -244.6))]
    )
    pos = {"a": np.array([-176.8, -176.8]), "b": np.array([125.0, -216.5])}
    assert d.assign(0.0, graph, pos) == [0, 1]
    assert d.rides[0].vessel == "a" and d.rides[1].vessel == "b"
    d.mark(1, "picked_up", 30.0)
    d.vessel_failed("a", 40.0)  # before its pickup: back in the queue
    d.vessel_failed("b", 41.0)  # passenger aboard: stranded
    assert d.rides[0].vessel is None and d.waiting(41.0) == [0]
    assert d.rides[1].stranded
    assert d.assign(42.0, graph, {"a": pos["a"], "b": pos["b"]}) == []  # nobody healthy left
    assert d.metrics()["reassignments"] == 2 and d.metrics()["requests_stranded"] == 1


# --- seeing and avoiding ------------------------------------------------------------------------
def straight_canal_grid(width=20.0, length=120.0, res=0.5):
    """A straight east-west canal (|y| < width/2) with quays as occupied cells."""
    cols, rows = int(length / res), int((width + 8.0) / res)
    origin = (-length / 2, -(width + 8.0) / 2)
    ys = origin[1] + (np.arange(rows) + 0.5) * res
    data = np.where(np.abs(ys)[:, None] < width / 2, 0, 100).astype(np.int8)
    data = np.broadcast_to(data, (rows, cols)).copy()
    return PlanningGrid.from_occupancy(OccupancyGrid(origin, res, data), 1.6)


def hull_returns(x, y, psi, length=2.0, beam=1.0, n=40):
    """Points on the outline of a hull at mid height."""
    poly = shapely.Polygon(box("boat", x, y, length, beam, psi, 0.0, 1.0).polygon)
    s = np.linspace(0.0, poly.exterior.length, n, endpoint=False)
    xy = np.array([poly.exterior.interpolate(v).coords[0] for v in s])
    return np.column_stack([xy, np.full(n, 0.5)])


def test_detect_vessels_finds_a_hull_in_the_water_and_ignores_quays_and_bridge_decks():
    grid = straight_canal_grid()
    boat = hull_returns(10.0, 2.0, 0.3)
    quay = np.column_stack([np.linspace(-50, 50, 200), np.full(200, 10.05), np.full(200, 0.5)])
    deck = np.column_stack([np.linspace(-5, 5, 50), np.zeros(50), np.full(50, 2.4)])
    blobs = detect_vessels(np.vstack([boat, quay, deck]), grid)
    assert len(blobs) == 1
    assert np.hypot(*(blobs[0].centre - (10.0, 2.0))) < 0.3
    assert 0.5 <= blobs[0].radius <= 1.2  # half the 2 m hull's diagonal is 1.12 m


def test_planning_around_a_boat_ahead_passes_it_on_the_starboard_side():
    grid = straight_canal_grid()
    start, goal = np.array([-40.0, 0.0, 0.0]), np.array([40.0, 0.0])
    blob = Blob(np.array([0.0, 0.0]), 1.1)
    # heading east, starboard is south (y < 0); the other boat heading west passes the same way
    for pose, side in ((start, -1.0), (np.array([40.0, 0.0, np.pi]), 1.0)):
        g = grid_around(grid, [blob], pose, separation=1.5, port_shift=1.5)
        a, b = (pose[:2], goal) if side < 0 else (pose[:2], start[:2])
        path = g.plan(a, b)
        dense = np.vstack([np.linspace(p, q, 50) for p, q in zip(path[:-1], path[1:], strict=True)])
        at_blob = dense[np.argmin(np.abs(dense[:, 0]))]
        assert np.sign(at_blob[1]) == side, path
        assert not path_conflicts(dense, [blob], own_radius=1.12, separation=1.0)
    assert path_conflicts(np.array([[-1.0, 0.5]]), [blob], 1.12, 1.5)


def test_a_lidar_sees_the_other_vessels_hulls():
    scene = Scene.from_solids([box("wall", 0.0, 60.0, 2.0, 2.0, 0.0, 0.0, 1.0)])  # far away
    others = OtherVessels(count=2, length=2.0, beam=1.0, z_min=-0.1, z_max=1.5)
    cfg = LidarConfig(preset="vlp16", mount=[0.0, 0.0, 1.0, 0.0], noise=False)
    lidar = Lidar3D(cfg, scene, 0, others=others)
    assert lidar.HasInputPort("other_vessels")
    context = lidar.CreateDefaultContext()
    lidar.GetInputPort("state").FixValue(context, np.zeros(6))
    states = np.array([[10.0, 0.0, np.pi / 2, 0, 0, 0], [0.0, -6.0, 0.0, 0, 0, 0]])
    lidar.GetInputPort("other_vessels").FixValue(context, states.ravel())
    Simulator(lidar, context).AdvanceTo(lidar.period + 1e-6)  # one sweep
    msg = lidar.GetOutputPort("lidar_points").Eval(context)
    world = sensor_to_world(msg.points, cfg.mount, [0.0, 0.0, 0.0])
    near_first = np.abs(world[:, 1]) < 0.3
    assert np.min(world[near_first & (world[:, 0] > 0), 0]) == pytest.approx(9.5, abs=0.05)
    assert np.max(world[(np.abs(world[:, 0]) < 0.3) & (world[:, 1] < 0), 1]) == pytest.approx(
        -5.5, abs=0.05
    )


# --- coordinator and fleet diagram ---------------------------------------------------------------
def test_coordinator_assigns_at_arrival_to_the_brute_force_closest_free_vessel(canals):
    world, grid, graph = canals
    requests = [
        DeliveryRequest(0.0, (-152.1, -194.6), (-35.2, -250.5)),
        DeliveryRequest(2.0, (145.1, -207.2), (34.4, -244.6)),
    ]
    names = ["r1", "r2", "r3"]
    where = {
        "r1": [-176.8, -176.8],
        "r2": [-112.9, -310.1],
        "r3": [125.0, -216.5],
    }
    coordinator = Coordinator(requests, names, graph, period=1.0)
    context = coordinator.CreateDefaultContext()
    idle = np.full(len(STATUS), -1.0)
    idle[0], idle[4], idle[5], idle[6] = IDLE, 0.0, 0.0, 0.0
    for n in names:
        coordinator.GetInputPort(f"{n}_state").FixValue(context, [*where[n], 0, 0, 0, 0])
        coordinator.GetInputPort(f"{n}_status").FixValue(context, idle)
    simulator = Simulator(coordinator, context)
    simulator.AdvanceTo(2.5)
    ledger = coordinator.dispatch(simulator.get_context())
    for i, r in enumerate(requests):
        free = [n for n in names if n not in {ledger.rides[j].vessel for j in range(i)}]
        brute = {n: brute_force_cost(grid, where[n], r.pickup) for n in free}
        assert ledger.rides[i].vessel == min(brute, key=brute.get)
        assert ledger.rides[i].assigned == pytest.approx(r.time)
        task = coordinator.GetOutputPort(f"{ledger.rides[i].vessel}_task").Eval(context)
        np.testing.assert_allclose(task, [i, *r.pickup, *r.destination])


def small_fleet(**changes):
    s = load_scenario("canal_taxi")
    fleet = dataclasses.replace(s.fleet, **changes)
    return dataclasses.replace(s, fleet=fleet)


def test_fleet_diagram_has_a_boat_per_vessel_and_the_coordinator_in_one_scene():
    s = load_scenario("canal_taxi")
    diagram = build_fleet_diagram(s)
    names = [v.name for v in s.fleet.vessels]
    assert names == ["roboat_1", "roboat_2", "roboat_3"]
    for n in names:
        boat = diagram.GetSubsystemByName(n)
        assert boat.HasInputPort("task") and boat.HasInputPort("other_vessels")
        for port in ("ground_truth_state", "state_estimate", "taxi_status", "thruster_command"):
            assert diagram.HasOutputPort(f"{n}.{port}")
    assert diagram.HasSubsystemNamed("coordinator") and diagram.HasOutputPort("all_served")


def test_a_vessel_that_fails_before_its_pickup_has_its_ride_reassigned(tmp_path):
    from usvdrake.run.fleet import run_fleet_mission

    s = small_fleet(
        vessels=[
            FleetVesselConfig("roboat_1", [-176.8, -176.8, 5.498, 0, 0, 0], fail_at=4.0),
            FleetVesselConfig("roboat_2", [-35.2, -250.5, 6.0, 0, 0, 0]),
        ],
        requests=[RequestConfig(0.0, [-152.1, -194.6], [-207.2, -145.1])],
    )
    s = dataclasses.replace(s, duration=8.0)
    m = run_fleet_mission(s, tmp_path, record=False).metrics
    rides = json.loads((tmp_path / "rides.json").read_text())
    events = [(e, v) for _, e, v in rides[0]["history"]]
    assert events[:3] == [
        ("assigned", "roboat_1"),
        ("vessel_failed", "roboat_1"),
        ("assigned", "roboat_2"),
    ]
    assert m["failed_vessels"] == ["roboat_1"] and m["reassignments"] == 1
    assert (tmp_path / "fleet.png").stat().st_size > 10_000


@pytest.mark.slow
def test_canal_taxi_serves_every_request_apart_and_clear_with_optimal_assignments(tmp_path):
    from usvdrake.run.fleet import run_fleet_mission

    # the first three requests (three free boats, then two: real choices); the whole ten-request
    # mission is minutes of this suite's time on one core; `usvdrake run canal_taxi` runs it
    s = load_scenario("canal_taxi")
    s = dataclasses.replace(s, fleet=dataclasses.replace(s.fleet, requests=s.fleet.requests[:3]))
    m = run_fleet_mission(s, tmp_path, record=False).metrics
    assert m["requests_served"] == 3 and m["all_served"], m
    assert m["min_separation_m"] >= 1.0, m
    assert m["collision_samples"] == 0 and m["nmpc_failures"] == 0, m
    world = make_world(s.world, s.seed)
    grid = PlanningGrid.from_world(world, s.fleet.assignment_resolution, s.fleet.taxi.inflation)
    for ride in json.loads((tmp_path / "rides.json").read_text()):
        free = ride["free_vessel_positions"]
        brute = {n: brute_force_cost(grid, xy, ride["pickup"]) for n, xy in free.items()}
        assert ride["vessel"] == min(brute, key=brute.get), ride
        assert ride["path_costs_m"][ride["vessel"]] == pytest.approx(min(brute.values()))


def test_taxi_pilot_goes_to_the_pickup_boards_then_delivers_and_reports_each_step():
    from usvdrake.systems.guidance.taxi_pilot import (
        ALIGHTING,
        BOARDING,
        TO_DESTINATION,
        TO_PICKUP,
        TaxiConfig,
        TaxiPilot,
    )

    grid = straight_canal_grid()
    cfg = TaxiConfig(dwell=5.0)
    pilot = TaxiPilot(cfg, grid, [-40.0, 0.0, 0.0])
    context = pilot.CreateDefaultContext()
    pickup, destination = np.array([-10.0, 2.0]), np.array([30.0, -2.0])
    pilot.GetInputPort("task").FixValue(context, [3, *pickup, *destination])
    est = pilot.GetInputPort("state_estimate")
    est.FixValue(context, [-40.0, 0.0, 0.0, 0, 0, 0])
    simulator = Simulator(pilot, context)
    simulator.AdvanceTo(0.6)
    mem = pilot.memory(context)
    assert mem.phase == TO_PICKUP and mem.ride == 3
    q_end, _ = mem.reference.sample(mem.reference.t_end)
    np.testing.assert_allclose(q_end[0, :2], pickup, atol=1e-9)
    # the boat is where the reference says (a perfect tracker) until it has arrived
    est.FixValue(context, [*pickup, q_end[0, 2], 0, 0, 0])
    simulator.AdvanceTo(mem.reference.t_end + 1.0)
    status = pilot.GetOutputPort("taxi_status").Eval(context)
    assert pilot.memory(context).phase == BOARDING and status[2] == 3  # picked up ride 3
    simulator.AdvanceTo(context.get_time() + cfg.dwell + 1.0)
    mem = pilot.memory(context)
    assert mem.phase == TO_DESTINATION
    est.FixValue(context, [*destination, 0.0, 0, 0, 0])
    simulator.AdvanceTo(mem.reference.t_end + 1.0)
    status = pilot.GetOutputPort("taxi_status").Eval(context)
    assert pilot.memory(context).phase == ALIGHTING and status[3] == 3  # delivered ride 3
    simulator.AdvanceTo(context.get_time() + cfg.dwell + 1.0)
    status = pilot.GetOutputPort("taxi_status").Eval(context)
    assert status[0] == IDLE and status[4] == 0 and status[6] == 0  # no fault, never held
