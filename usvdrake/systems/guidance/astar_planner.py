"""``AStarPlanner``: Ueland 2017's weighted multi-goal A* on the processed map, as a LeafSystem."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.guidance.velocity_setpoint import PATH_POINTS
from usvdrake.systems.guidance.weighted_astar import weighted_astar

NO_PATH = np.zeros((0, 2))


class AStarPlanner(LeafSystem):
    """Plans from the vessel to the cheapest of the explorer's goals every ``period`` seconds,
    ``offset`` after the explorer's cycle so it sees that cycle's map and goals.

    .. pydrake_system::

        name: AStarPlanner
        input_ports:
        - planning_map
        - goals
        - state_estimate
        output_ports:
        - path
        - destination

    ``path``: the first 128 cell centres [m] (n × 2) of the path (Ueland 2017 hands 128 points to
    the setpoint law per cycle), empty with no goal or no path; ``destination`` = [x, y, valid,
    cost] of the chosen goal (cost [m] weighted by Ueland 2017 eq. 1). Goal hysteresis: the previous
    destination is kept while it is still a goal and no other is cheaper by more than
    ``replan_margin`` (a fraction), so two nearly equal frontiers do not make the vessel dither
    between them as the map grows.
    """

    def __init__(
        self,
        period: float,
        offset: float,
        connection_distance: int = 4,
        replan_margin: float = 0.2,
    ):
        super().__init__()
        if replan_margin < 0:
            raise ValueError(f"AStarPlanner: replan_margin must be ≥ 0, got {replan_margin}")
        self._distance, self._margin = int(connection_distance), float(replan_margin)
        self._map = self.DeclareAbstractInputPort("planning_map", AbstractValue.Make(None))
        self._goals = self.DeclareAbstractInputPort(
            "goals", AbstractValue.Make(np.zeros((0, 2), dtype=int))
        )
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self._path = self.DeclareAbstractState(AbstractValue.Make(NO_PATH.copy()))
        # [x, y, valid, cost, row, col, expanded]
        self._dest = self.DeclareDiscreteState(BasicVector([0.0, 0.0, 0.0, 0.0, -1, -1, 0.0]))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, offset, self._update)
        self.DeclareAbstractOutputPort(
            "path",
            lambda: AbstractValue.Make(NO_PATH.copy()),
            lambda c, v: v.set_value(c.get_abstract_state(self._path).get_value()),
            prerequisites_of_calc={self.abstract_state_ticket(self._path)},
        )
        self.DeclareVectorOutputPort(
            "destination",
            4,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._dest).value()[:4]),
            prerequisites_of_calc={self.discrete_state_ticket(self._dest)},
        )

    def _update(self, context, state):
        pmap = self._map.Eval(context)
        goals = np.asarray(self._goals.Eval(context), dtype=int).reshape(-1, 2)
        dest = context.get_discrete_state(self._dest).value().copy()
        result = None
        if pmap is not None and len(goals):
            result = weighted_astar(
                pmap.traversable, pmap.weights, pmap.start, goals, self._distance
            )
            previous = (int(dest[4]), int(dest[5]))
            if (
                result is not None
                and dest[2] > 0
                and previous != tuple(result.cells[-1])
                and ((goals[:, 0] == previous[0]) & (goals[:, 1] == previous[1])).any()
            ):
                keep = weighted_astar(
                    pmap.traversable,
                    pmap.weights,
                    pmap.start,
                    np.array([previous]),
                    self._distance,
                )
                if keep is not None and keep.cost <= (1.0 + self._margin) * result.cost:
                    result = keep
        if result is None:
            state.get_mutable_abstract_state(self._path).set_value(NO_PATH.copy())
            dest[2] = 0.0
        else:
            points = pmap.cell_centres(result.cells)
            state.get_mutable_abstract_state(self._path).set_value(points[:PATH_POINTS])
            r, c = result.cells[-1]
            dest[:] = [*points[-1], 1.0, result.cost * pmap.resolution, r, c, result.expanded]
        state.get_mutable_discrete_state(self._dest).SetFromVector(dest)
