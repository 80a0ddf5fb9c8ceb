"""``TargetShips``: the target ships of a traffic situation, on their waypoints (world side)."""

import numpy as np
from pydrake.systems.framework import LeafSystem


class TargetShips(LeafSystem):
    """The TRUE states of the targets, each following its waypoints at its leg speeds from t = 0
    (``situation.Ship.state_at``; past the last waypoint it keeps its last course and speed).

    .. pydrake_system::

        name: TargetShips
        output_ports:
        - target_states

    ``target_states`` = [x y ψ speed] per target, in the order of ``ships`` (4 n values). This is
    ground truth: only world-side systems (AIS transponders, evaluation, logging) may read it.
    """

    def __init__(self, ships):
        super().__init__()
        self._ships = tuple(ships)
        self.DeclareVectorOutputPort(
            "target_states",
            4 * len(self._ships),
            self._calc,
            prerequisites_of_calc={self.time_ticket()},
        )

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(s.id for s in self._ships)

    def _calc(self, context, output):
        t = context.get_time()
        rows = [np.concatenate(s.state_at(t)) for s in self._ships]
        output.SetFromVector(np.concatenate(rows) if rows else np.zeros(0))
