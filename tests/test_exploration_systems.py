"""The exploration LeafSystems of Ueland 2017 wired on a known map: explorer → planner → setpoint
law, the operator's modes, and the scenario's checks."""

import dataclasses

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantValueSource, ConstantVectorSource

from usvdrake.diagrams import check_scenario, load_scenario
from usvdrake.scenario import ConfigError
from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.guidance.astar_planner import AStarPlanner
from usvdrake.systems.guidance.frontier_explorer import ExplorerConfig, FrontierExplorer
from usvdrake.systems.guidance.operator import OperatorCommandConfig, OperatorMode, OperatorPanel
from usvdrake.systems.guidance.velocity_setpoint import VelocitySetpointLaw, lookahead_distance
from usvdrake.worlds.world import OccupancyGrid

RES = 0.1


def room(unknown_east: bool) -> OccupancyGrid:
    """A 6 m × 4 m walled room at 0.1 m; optionally its east half unexplored."""
    data = np.zeros((40, 60), np.int8)
    data[[0, -1], :] = OccupancyGrid.OCCUPIED
    data[:, [0, -1]] = OccupancyGrid.OCCUPIED
    data[10:30, 30] = OccupancyGrid.OCCUPIED  # a wall in the middle, open at both ends
    if unknown_east:
        data[1:-1, 40:-1] = OccupancyGrid.UNKNOWN
    return OccupancyGrid((0.0, 0.0), RES, data)


def build(grid, pose, command=None, ranges=2.0):
    """explorer + planner + law on a fixed map, pose and scan; returns (simulator, systems)."""
    b = DiagramBuilder()
    cfg = ExplorerConfig(resolution=RES, inflation=0.3, planning_period=1.0, start_delay=0.1)
    explorer = b.AddSystem(FrontierExplorer(cfg, pose[:2]))
    planner = b.AddSystem(AStarPlanner(1.0, 0.101, 4))
    law = b.AddSystem(VelocitySetpointLaw(0.0, pose[:2], 10.0))
    grid_src = b.AddSystem(ConstantValueSource(AbstractValue.Make(grid)))
    est = b.AddSystem(ConstantVectorSource(np.array([*pose, 0.0, 0.0, 0.0])))
    scan = LaserScan(
        angle_increment=0.1, ranges=np.full(63, ranges), valid=np.ones(63, bool), time=1.0
    )
    scan_src = b.AddSystem(ConstantValueSource(AbstractValue.Make(scan)))
    b.Connect(grid_src.get_output_port(), explorer.GetInputPort("slam_map"))
    for s in (explorer, planner, law):
        b.Connect(est.get_output_port(), s.GetInputPort("state_estimate"))
    if command is not None:
        cmd = b.AddSystem(ConstantVectorSource(np.asarray(command, float)))
        b.Connect(cmd.get_output_port(), explorer.GetInputPort("operator_command"))
    b.Connect(explorer.GetOutputPort("planning_map"), planner.GetInputPort("planning_map"))
    b.Connect(explorer.GetOutputPort("goals"), planner.GetInputPort("goals"))
    b.Connect(planner.GetOutputPort("path"), law.GetInputPort("path"))
    b.Connect(scan_src.get_output_port(), law.GetInputPort("lidar_scan"))
    sim = Simulator(b.Build())
    return sim, explorer, planner, law


def outputs(sim, *systems_ports):
    ctx = sim.get_context()
    return [s.GetOutputPort(p).Eval(s.GetMyContextFromRoot(ctx)) for s, p in systems_ports]


def test_explore_plans_to_the_cheapest_frontier_and_sets_the_setpoint_ahead():
    pose = np.array([1.0, 2.0, 0.0])
    sim, explorer, planner, law = build(room(unknown_east=True), pose)
    sim.AdvanceTo(1.5)
    goals, pmap, path, dest, finished = outputs(
        sim,
        (explorer, "goals"),
        (explorer, "planning_map"),
        (planner, "path"),
        (planner, "destination"),
        (explorer, "exploration_finished"),
    )
    assert len(goals) > 10 and finished[0] == 0.0
    # every frontier cell is traversable and next to the unexplored east part
    assert pmap.traversable[goals[:, 0], goals[:, 1]].all()
    assert set(goals[:, 1].tolist()) == {39}
    # the path starts at the vessel and ends on a frontier cell, the destination
    assert np.linalg.norm(path[0] - pose[:2]) < RES
    end = pmap.to_cell(path[-1])
    assert any((goals == end).all(axis=1)) and dest[2] == 1.0
    np.testing.assert_allclose(dest[:2], path[-1])
    # Ueland 2017 eqs. 2-4: the setpoint is r_s(d_min = 2 m) = 2.8 m along the path from the vessel
    setpoint = outputs(sim, (law, "setpoint"))[0]
    travelled = np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))
    k = np.searchsorted(travelled, lookahead_distance(2.0))
    assert np.linalg.norm(setpoint[:2] - path[k]) < 0.6


def test_a_fully_known_room_is_finished_and_the_setpoint_holds():
    pose = np.array([1.0, 2.0, 0.0])
    sim, explorer, planner, law = build(room(unknown_east=False), pose)
    sim.AdvanceTo(3.5)
    finished, path, setpoint, status = outputs(
        sim,
        (explorer, "exploration_finished"),
        (planner, "path"),
        (law, "setpoint"),
        (explorer, "explorer_status"),
    )
    assert finished[0] == 1.0 and status[1] == 0 and status[3] == 4
    assert len(path) == 0
    np.testing.assert_allclose(setpoint, pose)


def test_goto_goes_round_the_wall_to_the_nearest_reachable_cell():
    pose = np.array([1.0, 2.0, 0.0])
    goal = (3.3, 2.0)  # east of the middle wall, inside its inflation: go round the wall
    sim, explorer, planner, _ = build(
        room(unknown_east=True), pose, [OperatorMode.GOTO, *goal], ranges=0.2
    )
    sim.AdvanceTo(1.5)
    goals, path, pmap = outputs(
        sim, (explorer, "goals"), (planner, "path"), (explorer, "planning_map")
    )
    assert len(goals) == 1
    target = pmap.cell_centres(goals)[0]
    assert np.linalg.norm(target - goal) < 0.5 and pmap.clearance[tuple(goals[0])] > 0.3
    np.testing.assert_allclose(path[-1], target)
    # the straight line crosses the wall: the path must be longer than it
    length = np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))
    assert length > np.linalg.norm(target - pose[:2]) + 0.3


def test_stop_empties_the_path():
    pose = np.array([1.0, 2.0, 0.0])
    sim, _, planner, law = build(room(unknown_east=True), pose, [OperatorMode.STOP, 0, 0])
    sim.AdvanceTo(1.5)
    path, setpoint = outputs(sim, (planner, "path"), (law, "setpoint"))
    assert len(path) == 0
    np.testing.assert_allclose(setpoint, pose)


def test_operator_script_switches_modes_on_time():
    script = [
        OperatorCommandConfig(time=1.0, mode="goto", goal=[4.0, 1.0]),
        OperatorCommandConfig(time=2.0, mode="stop"),
    ]
    panel = OperatorPanel(None, (0, 0, 6, 4), script)
    sim = Simulator(panel)
    port = panel.get_output_port()
    values = {}
    for t in (0.5, 1.1, 2.1):
        sim.AdvanceTo(t)
        values[t] = port.Eval(sim.get_context()).copy()
    np.testing.assert_allclose(values[0.5], [OperatorMode.EXPLORE, 3.0, 2.0])
    np.testing.assert_allclose(values[1.1], [OperatorMode.GOTO, 4.0, 1.0])
    np.testing.assert_allclose(values[2.1], [OperatorMode.STOP, 4.0, 1.0])
    with pytest.raises(ValueError, match="unknown operator mode"):
        OperatorPanel(None, script=[OperatorCommandConfig(mode="hover")])


@pytest.mark.parametrize(
    "change,key",
    [
        (
            lambda s: dataclasses.replace(s, slam=dataclasses.replace(s.slam, method="none")),
            "slam.method",
        ),
        (lambda s: dataclasses.replace(s, estimator="nmhe"), "estimator"),
        (
            lambda s: s.exploration.explorer.__setattr__("connection_distance", 5) or s,
            "exploration.explorer.connection_distance",
        ),
        (
            lambda s: s.exploration.commands.append(OperatorCommandConfig(mode="hover")) or s,
            "exploration.commands[0].mode",
        ),
        (
            lambda s: s.exploration.pd.__setattr__("omega_n", [0.5, 0.5]) or s,
            "exploration.pd.omega_n",
        ),
    ],
)
def test_bad_exploration_scenarios_fail_with_the_key(change, key):
    s = change(load_scenario("basin_explore"))
    with pytest.raises(ConfigError, match=key.replace("[", r"\[").replace("]", r"\]")):
        check_scenario(s)


def test_known_poses_maps_the_scans_at_the_true_pose():
    """The ground-truth map source: every occupied cell of a short exploration's map lies on a
    solid of the world (no SLAM error), and the metrics say which source was used."""
    from usvdrake import run_mission
    from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
    from usvdrake.worlds import make_world

    s = load_scenario("basin_explore")
    s = dataclasses.replace(
        s, duration=6.0, estimator="oracle", slam=dataclasses.replace(s.slam, method="known_poses")
    )
    check_scenario(s)
    with pytest.raises(ConfigError, match="slam.method"):
        check_scenario(dataclasses.replace(s, estimator="observer"))
    m = run_mission(s, record=False).metrics
    assert m["map_source"] == "slam:known_poses" and m["pose_source"].startswith("ground_truth")
    assert 0.2 < m["explored_fraction"] < 1.0

    diagram = build_vessel_diagram(s)
    sim = Simulator(diagram)
    sim.AdvanceTo(6.0)
    grid = diagram.GetOutputPort("slam_map").Eval(sim.get_context())
    rows, cols = np.nonzero(grid.data == OccupancyGrid.OCCUPIED)
    assert len(rows) > 100
    x = grid.origin[0] + (cols + 0.5) * grid.resolution
    y = grid.origin[1] + (rows + 0.5) * grid.resolution
    world = make_world(s.world, s.seed)
    # within a cell's half-diagonal (+ the RPLIDAR's range noise) of a solid
    assert np.percentile(world.clearance(x, y, 0.25), 99) < 0.06
