"""``RouteGuidance``: the own ship's nominal course and speed along its planned route."""

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.colav.route_los import advance_leg, arrived, leg_frame, los_course


class RouteGuidance(LeafSystem):
    """Line-of-sight course on the active leg and that leg's planned speed (``route_los``).

    .. pydrake_system::

        name: RouteGuidance
        input_ports:
        - state
        output_ports:
        - nominal
        - mission_complete
        - path_course
        - distance_to_end

    ``state`` = [x y ψ u v r]; ``nominal`` = [course [rad], speed [m/s]]; ``path_course`` =
    [the active leg's direction [rad]]; ``distance_to_end`` = [straight-line distance to the
    route's last waypoint [m]];
    ``mission_complete`` = [1] within ``arrival_radius`` of the last waypoint. The active leg
    lives in discrete state (advanced every ``period``); the outputs advance it afresh from the
    present position, so they never lag a leg behind.
    """

    def __init__(
        self,
        waypoints,
        leg_speeds,
        lookahead: float,
        switch_radius: float,
        arrival_radius: float,
        period: float = 1.0,
    ):
        super().__init__()
        self._wps = np.asarray(waypoints, float).reshape(-1, 2)
        self._speeds = np.asarray(leg_speeds, float).ravel()
        if len(self._wps) < 2 or len(self._speeds) < 1:
            raise ValueError("RouteGuidance: needs at least two waypoints and one leg speed")
        self._lookahead = float(lookahead)
        self._switch = float(switch_radius)
        self._arrival = float(arrival_radius)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._leg = self.DeclareDiscreteState(BasicVector([0.0]))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        deps = {self.xd_ticket(), self.input_port_ticket(self._state.get_index())}
        self.DeclareVectorOutputPort("nominal", 2, self._calc_nominal, deps)
        self.DeclareVectorOutputPort("mission_complete", 1, self._calc_complete, deps)
        self.DeclareVectorOutputPort("path_course", 1, self._calc_path_course, deps)
        state_dep = {self.input_port_ticket(self._state.get_index())}
        self.DeclareVectorOutputPort("distance_to_end", 1, self._calc_to_end, state_dep)

    def _index(self, context) -> int:
        start = int(context.get_discrete_state(self._leg).GetAtIndex(0))
        pos = self._state.Eval(context)[:2]
        return advance_leg(self._wps, start, pos, self._switch)

    def _update(self, context, discrete_state):
        discrete_state.get_mutable_vector(self._leg).SetAtIndex(0, float(self._index(context)))

    def _calc_nominal(self, context, output):
        idx = self._index(context)
        pos = self._state.Eval(context)[:2]
        speed = self._speeds[min(idx, len(self._speeds) - 1)]  # the leg's planned speed
        output.SetFromVector([los_course(self._wps, idx, pos, self._lookahead), speed])

    def _calc_path_course(self, context, output):
        _, e, _ = leg_frame(self._wps, min(self._index(context), len(self._wps) - 2))
        output.SetFromVector([float(np.arctan2(e[1], e[0]))])

    def _calc_to_end(self, context, output):
        pos = self._state.Eval(context)[:2]
        output.SetFromVector([float(np.hypot(*(pos - self._wps[-1])))])

    def _calc_complete(self, context, output):
        pos = self._state.Eval(context)[:2]
        output.SetFromVector([float(arrived(self._wps, pos, self._arrival))])
