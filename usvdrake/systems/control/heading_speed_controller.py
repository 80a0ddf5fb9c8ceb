"""``HeadingSpeedController``: the baseline PD law sampled at the control rate (ZOH)."""

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.control.heading_speed_law import heading_speed_tau
from usvdrake.systems.guidance.line_of_sight import ControlConfig
from usvdrake.vessel import Hydrodynamics


class HeadingSpeedController(LeafSystem):
    """Samples the estimate and reference every 1/rate_hz s and holds τ_desired in between.

    .. pydrake_system::

        name: HeadingSpeedController
        input_ports:
        - state_estimate
        - reference
        output_ports:
        - tau_desired

    ``reference`` = [ψ_d, u_d, ...]; ``tau_desired`` [N, N, N m] body frame (discrete state).
    """

    def __init__(self, xi: Hydrodynamics, gains: ControlConfig):
        super().__init__()
        self._xi, self._gains = xi, gains
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self._ref = self.DeclareVectorInputPort("reference", 3)
        self._tau = self.DeclareDiscreteState(BasicVector(np.zeros(3)))
        self.DeclarePeriodicDiscreteUpdateEvent(1.0 / gains.rate_hz, 0.0, self._update)
        self.DeclareStateOutputPort("tau_desired", self._tau)

    def _update(self, context, discrete_state):
        ref = self._ref.Eval(context)
        tau = heading_speed_tau(self._xi, self._gains, self._est.Eval(context), ref[0], ref[1])
        discrete_state.get_mutable_vector(self._tau).SetFromVector(tau)
