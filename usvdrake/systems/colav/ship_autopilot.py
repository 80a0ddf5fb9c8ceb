"""``ShipAutopilot``: the ship's course and speed autopilot (``ship_model.autopilot``), ZOH."""

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.colav.ship_model import (
    AutopilotGains,
    ShipParams,
    autopilot,
    steady_shaft_speed,
)


class ShipAutopilot(LeafSystem):
    """Heading PD on the Nomoto model and shaft-speed feed-forward + P, sampled every ``period``
    seconds and held (a bridge autopilot's rudder and telegraph orders change in steps).

    .. pydrake_system::

        name: ShipAutopilot
        input_ports:
        - full_state
        - command
        output_ports:
        - actuator_command

    ``full_state`` = [x y ψ u v r δ n]; ``command`` = [course [rad], speed [m/s]];
    ``actuator_command`` = [δ_c [rad], n_c [rev/s]] held between samples.
    """

    def __init__(
        self,
        params: ShipParams,
        period: float = 1.0,
        initial_speed: float | None = None,
        gains: AutopilotGains | None = None,
    ):
        super().__init__()
        if not period > 0.0:
            raise ValueError(f"ShipAutopilot: period must be positive, got {period}")
        self._p = params
        self._gains = gains
        self._state = self.DeclareVectorInputPort("full_state", 8)
        self._command = self.DeclareVectorInputPort("command", 2)
        speed = params.design_speed if initial_speed is None else initial_speed
        # Until the first sample: rudder amidships, the shaft at its trim for the initial speed.
        held = self.DeclareDiscreteState(BasicVector([0.0, steady_shaft_speed(params, speed)]))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareStateOutputPort("actuator_command", held)

    def _update(self, context, discrete_state):
        q = self._state.Eval(context)
        course, speed = self._command.Eval(context)
        cmd = autopilot(self._p, q, float(course), float(speed), self._gains)
        discrete_state.get_mutable_vector().SetFromVector(np.asarray(cmd, float))
