"""``ShipPlant``: the ship-scale own ship (``ship_model``) as a continuous Drake system."""

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.colav.ship_model import ShipParams, ship_derivative


class ShipPlant(LeafSystem):
    """Clarke 1983 manoeuvring model with rudder and shaft dynamics (see ``ship_model``).

    .. pydrake_system::

        name: ShipPlant
        input_ports:
        - actuator_command
        output_ports:
        - full_state
        - state

    ``actuator_command`` = [δ_c [rad], n_c [rev/s]]; continuous state and ``full_state`` =
    [x y ψ u v r δ n]; ``state`` = [x y ψ u v r], usvdrake's vessel-state layout.
    """

    def __init__(self, params: ShipParams, initial_state):
        super().__init__()
        self._p = params
        q0 = np.asarray(initial_state, float)
        if q0.shape != (8,):
            raise ValueError(f"ShipPlant: initial_state needs 8 values, got {q0.shape}")
        self._cmd = self.DeclareVectorInputPort("actuator_command", 2)
        self.DeclareContinuousState(BasicVector(q0))
        self.DeclareVectorOutputPort(
            "full_state", 8, self._calc_full, prerequisites_of_calc={self.xc_ticket()}
        )
        self.DeclareVectorOutputPort(
            "state", 6, self._calc_state, prerequisites_of_calc={self.xc_ticket()}
        )

    @property
    def params(self) -> ShipParams:
        return self._p

    def DoCalcTimeDerivatives(self, context, derivatives):
        q = context.get_continuous_state_vector().CopyToVector()
        u = self._cmd.Eval(context)
        derivatives.get_mutable_vector().SetFromVector(ship_derivative(self._p, q, u))

    def _calc_full(self, context, output):
        output.SetFromVector(context.get_continuous_state_vector().CopyToVector())

    def _calc_state(self, context, output):
        output.SetFromVector(context.get_continuous_state_vector().CopyToVector()[:6])
