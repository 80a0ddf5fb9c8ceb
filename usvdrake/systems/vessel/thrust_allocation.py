"""``ThrustAllocation``: desired generalised force → thruster commands within their limits."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem, ValueProducer

from usvdrake.systems.vessel.thrust_allocation_problem import AllocationResult, ThrustAllocator
from usvdrake.systems.vessel.thrusters import command_size
from usvdrake.vessel import VesselParams


class ThrustAllocation(LeafSystem):
    """Constrained allocation (see ``thrust_allocation_problem``) as a feedthrough system.

    .. pydrake_system::

        name: ThrustAllocation
        input_ports:
        - tau_desired
        output_ports:
        - thruster_command
        - tau_achieved

    ``tau_desired`` [N, N, N m] body frame; ``thruster_command`` per thruster [f] or [f, α];
    ``tau_achieved`` = B u, equal to ``tau_desired`` whenever it is attainable and otherwise the
    W-weighted closest attainable force. The solve is cached: it reruns only when the input
    changes (with a zero-order-hold controller upstream, once per control period).
    """

    def __init__(self, vessel: VesselParams):
        super().__init__()
        self._allocator = ThrustAllocator(vessel.thrusters, vessel.allocation_weight)
        n = command_size(vessel.thrusters)
        self._tau = self.DeclareVectorInputPort("tau_desired", 3)
        empty = AllocationResult(np.zeros(n), np.zeros(3), 0.0, True)
        self._cache = self.DeclareCacheEntry(
            description="allocation",
            value_producer=ValueProducer(
                allocate=AbstractValue.Make(empty).Clone, calc=self._calc_allocation
            ),
            prerequisites_of_calc={self.input_port_ticket(self._tau.get_index())},
        )
        deps = {self._cache.ticket()}
        self.DeclareVectorOutputPort("thruster_command", n, self._calc_cmd, deps)
        self.DeclareVectorOutputPort("tau_achieved", 3, self._calc_achieved, deps)

    def _calc_allocation(self, context, value):
        value.set_value(self._allocator.allocate(self._tau.Eval(context)))

    def _result(self, context) -> AllocationResult:
        return self._cache.Eval(context)

    def _calc_cmd(self, context, output):
        output.SetFromVector(self._result(context).command)

    def _calc_achieved(self, context, output):
        output.SetFromVector(self._result(context).tau_achieved)
