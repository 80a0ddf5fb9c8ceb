"""``LosGuidance``: waypoint line-of-sight guidance, the baseline that moves the demo."""

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.guidance.line_of_sight import (
    ControlConfig,
    MissionConfig,
    advance_index,
    los_reference,
)


class LosGuidance(LeafSystem):
    """Heading and speed references along a waypoint list (see ``line_of_sight``).

    .. pydrake_system::

        name: LosGuidance
        input_ports:
        - state_estimate
        output_ports:
        - reference
        - mission_complete

    ``state_estimate`` = [x y ψ u v r]; ``reference`` = [ψ_d [rad], u_d [m/s], e [m]];
    ``mission_complete`` = [1] once the final waypoint is reached, else [0]. The active waypoint
    index and the path start live in discrete state, advanced at the control rate; the reference
    is computed from the current estimate whenever it is evaluated.
    """

    def __init__(self, mission: MissionConfig, control: ControlConfig, cruise_speed: float):
        super().__init__()
        self._waypoints = np.asarray(mission.waypoints, float)
        self._mission = mission
        self._control = control
        self._speed = mission.speed if mission.speed > 0 else cruise_speed
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        # [index, complete, start_x, start_y, initialised]
        self._disc = self.DeclareDiscreteState(BasicVector(np.zeros(5)))
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / control.rate_hz, 0.0, self._update)
        deps = {self.xd_ticket(), self.input_port_ticket(self._est.get_index())}
        self.DeclareVectorOutputPort("reference", 3, self._calc_reference, deps)
        self.DeclareVectorOutputPort(
            "mission_complete", 1, self._calc_complete, prerequisites_of_calc={self.xd_ticket()}
        )

    def _reference(self, context, index=None, start=None):
        d = context.get_discrete_state(self._disc).CopyToVector()
        q = self._est.Eval(context)
        pos = q[:2]
        if start is None:
            start = d[2:4] if d[4] > 0 else pos
        idx = int(d[0]) if index is None else index
        return los_reference(
            self._waypoints,
            idx,
            pos,
            start,
            self._speed,
            self._control.lookahead,
            self._mission.acceptance_radius,
            self._mission.slowdown_radius,
        )

    def _update(self, context, discrete_state):
        d = context.get_discrete_state(self._disc).CopyToVector()
        pos = self._est.Eval(context)[:2]
        start = d[2:4] if d[4] > 0 else pos
        idx = advance_index(self._waypoints, int(d[0]), pos, self._mission.acceptance_radius)
        ref = self._reference(context, idx, start)
        complete = 1.0 if (d[1] > 0 or ref.complete) else 0.0
        discrete_state.get_mutable_vector(self._disc).SetFromVector(
            [idx, complete, start[0], start[1], 1.0]
        )

    def _calc_reference(self, context, output):
        ref = self._reference(context)
        complete = context.get_discrete_state(self._disc).GetAtIndex(1) > 0
        output.SetFromVector([ref.heading, 0.0 if complete else ref.speed, ref.cross_track])

    def _calc_complete(self, context, output):
        output.SetFromVector([context.get_discrete_state(self._disc).GetAtIndex(1)])
