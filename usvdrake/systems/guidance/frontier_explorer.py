"""``FrontierExplorer``: Ueland 2017's exploration strategy (Yamauchi 1997) over a SLAM map.

Every planning period (Ueland 2017: the planner "only updates the chosen path every few seconds") it
processes the map (:func:`process_map`: inflation, near-vessel cells free, reachability),
finds the frontier cells (traversable cells next to unexplored ones, small clusters dropped)
and hands them as goals to the :class:`~usvdrake.systems.guidance.astar_planner.AStarPlanner`,
whose multi-goal A* picks the cheapest (Ueland 2017 §Exploration Strategy steps 1-3). Frontier cells
within ``visited_radius`` of the vessel's track are dropped: the vessel has been there and the
lidar still cannot see them (water under a low plank, a corner behind a board), so they are
not worth another trip. When no frontier is left the exploration is finished (latched).

The operator (Ueland 2017 §Operator Interaction) switches modes through ``operator_command``: in
``goto`` the goal is the reachable cell nearest the operator's location, in ``stop`` there is
none (the setpoint law then holds position).
"""

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.guidance.map_processing import (
    PlanningMap,
    VesselOffMapError,
    coarsen,
    disc_mask,
    frontier_cells,
    process_map,
)
from usvdrake.systems.guidance.operator import OperatorMode
from usvdrake.worlds.world import OccupancyGrid

NO_GOALS = np.zeros((0, 2), dtype=int)


@dataclass
class ExplorerConfig:
    resolution: float = 0.2  # [m] planning grid (the SLAM map is coarsened to it)
    inflation: float = 0.4  # [m] Ueland 2017 §Map Processing
    near_free_radius: float = 0.6  # [m] unknown cells this close to the vessel count as free
    planning_period: float = 2.0  # [s] map processing + frontiers + A* every this often
    min_frontier_cells: int = 3  # [cells] smaller frontier clusters are ignored
    visited_radius: float = 0.5  # [m] frontier cells this close to the track are dropped
    connection_distance: int = (
        4  # Ueland 2017: 1-4 (8/16/32/48 directions); 4 in Ueland 2017's experiments
    )
    replan_margin: float = 0.2  # [-] keep the current frontier unless another is this much cheaper
    start_delay: float = 1.0  # [s] first planning cycle (the SLAM needs a few scans)


@dataclass
class ExplorerMemory:
    """The explorer's abstract state: the last processed map and goals and the track."""

    planning_map: PlanningMap | None = None
    goals: np.ndarray = field(default_factory=lambda: NO_GOALS.copy())
    track: list = field(default_factory=list)  # [(x, y)] sampled along the vessel's path
    status: str = "waiting for the map"


def _goto_goal(pmap: PlanningMap, goal_xy) -> np.ndarray:
    """The traversable cell nearest the operator's location (the location itself when it is
    traversable): the operator may point at a wall or at unexplored water."""
    cells = np.argwhere(pmap.traversable)
    if len(cells) == 0:
        return NO_GOALS.copy()
    centres = pmap.cell_centres(cells)
    best = int(np.argmin(((centres - np.asarray(goal_xy, float)[:2]) ** 2).sum(axis=1)))
    return cells[best : best + 1].copy()


class FrontierExplorer(LeafSystem):
    """Frontier goals for the planner, from the SLAM map, the pose and the operator.

    .. pydrake_system::

        name: FrontierExplorer
        input_ports:
        - slam_map
        - state_estimate
        - operator_command
        output_ports:
        - planning_map
        - goals
        - exploration_finished
        - explorer_status

    ``goals`` is an (n × 2) array of (row, col) cells of ``planning_map``;
    ``explorer_status`` = [mode, frontier cells, finished, planning cycles].
    ``operator_command`` may stay unconnected (exploration).
    """

    def __init__(self, cfg: ExplorerConfig, initial_xy):
        super().__init__()
        for name in ("resolution", "planning_period"):
            if not getattr(cfg, name) > 0:
                raise ValueError(f"FrontierExplorer: {name} must be positive")
        self._cfg = cfg
        empty = OccupancyGrid((0.0, 0.0), 1.0, np.zeros((0, 0), np.int8))
        self._map = self.DeclareAbstractInputPort("slam_map", AbstractValue.Make(empty))
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self._cmd = self.DeclareVectorInputPort("operator_command", 3)
        memory = ExplorerMemory(track=[tuple(np.asarray(initial_xy, float)[:2])])
        self._memory = self.DeclareAbstractState(AbstractValue.Make(memory))
        # [mode, frontier cells, finished, cycles]
        self._status = self.DeclareDiscreteState(BasicVector([0.0, 0.0, 0.0, 0.0]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(
            cfg.planning_period, cfg.start_delay, self._update
        )
        deps = {self.abstract_state_ticket(self._memory)}
        self.DeclareAbstractOutputPort(
            "planning_map",
            lambda: AbstractValue.Make(None),
            lambda c, v: v.set_value(self.memory(c).planning_map),
            prerequisites_of_calc=deps,
        )
        self.DeclareAbstractOutputPort(
            "goals",
            lambda: AbstractValue.Make(NO_GOALS.copy()),
            lambda c, v: v.set_value(self.memory(c).goals),
            prerequisites_of_calc=deps,
        )
        self.DeclareVectorOutputPort(
            "exploration_finished",
            1,
            lambda c, o: o.SetAtIndex(0, c.get_discrete_state(self._status).GetAtIndex(2)),
            prerequisites_of_calc={self.discrete_state_ticket(self._status)},
        )
        self.DeclareStateOutputPort("explorer_status", self._status)

    def memory(self, context) -> ExplorerMemory:
        return context.get_abstract_state(self._memory).get_value()

    def _mode(self, context) -> tuple[OperatorMode, np.ndarray]:
        if not self._cmd.HasValue(context):
            return OperatorMode.EXPLORE, np.zeros(2)
        cmd = self._cmd.Eval(context)
        return OperatorMode(int(round(cmd[0]))), np.asarray(cmd[1:3])

    def _update(self, context, state):
        cfg = self._cfg
        memory = state.get_mutable_abstract_state(self._memory).get_value()
        status = context.get_discrete_state(self._status).value().copy()
        est = self._est.Eval(context)
        mode, goal_xy = self._mode(context)
        status[0], status[3] = float(mode), status[3] + 1
        # The track, sampled every half cell since the last cycle.
        last = np.asarray(memory.track[-1])
        n = int(np.ceil(np.linalg.norm(est[:2] - last) / (0.5 * cfg.resolution)))
        for k in range(1, n + 1):
            memory.track.append(tuple(last + (est[:2] - last) * k / n))

        grid = self._map.Eval(context)
        memory.goals = NO_GOALS.copy()
        if grid.data.size == 0 or not (grid.data != OccupancyGrid.UNKNOWN).any():
            memory.planning_map, memory.status = None, "waiting for the map"
        else:
            try:
                pmap = process_map(
                    coarsen(grid, cfg.resolution),
                    est[:2],
                    cfg.inflation,
                    cfg.near_free_radius,
                )
            except VesselOffMapError as err:
                pmap, memory.status = None, str(err)
            memory.planning_map = pmap
            if pmap is not None:
                if mode == OperatorMode.EXPLORE:
                    frontier = frontier_cells(pmap, cfg.min_frontier_cells)
                    if len(frontier):
                        track_cells = np.array([pmap.to_cell(p) for p in memory.track])
                        seen = disc_mask(
                            pmap.shape, track_cells, cfg.visited_radius / cfg.resolution
                        )
                        frontier = frontier[~seen[frontier[:, 0], frontier[:, 1]]]
                    memory.goals = frontier
                    status[1] = len(frontier)
                    if len(frontier) == 0:
                        status[2] = 1.0  # finished: latched
                    memory.status = "finished" if status[2] else f"{len(frontier)} frontier cells"
                elif mode == OperatorMode.GOTO:
                    memory.goals = _goto_goal(pmap, goal_xy)
                    memory.status = f"going to ({goal_xy[0]:.1f}, {goal_xy[1]:.1f})"
                else:
                    memory.status = "stopped by the operator"
        if mode == OperatorMode.EXPLORE and status[2]:
            memory.goals = NO_GOALS.copy()
        state.get_mutable_discrete_state(self._status).SetFromVector(status)
