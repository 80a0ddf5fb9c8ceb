"""``ReferenceMonitor``: where the timed reference is now, how far the vessel is from it, and
whether the mission is over (the reference has ended and the last goal is reached)."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.angles import wrap_angle


def reference_row(reference, t: float, q) -> list[float]:
    """[ψ_ref [rad], u_ref [m/s], e [m]] of ``reference`` at time ``t`` for a vessel at ``q``
    (e: distance to the reference position): the ``reference`` port layout the LOS guidance,
    the reference monitor and the taxi pilot share."""
    q_ref, _ = reference.sample(np.array([t]))
    e = float(np.hypot(q[0] - q_ref[0, 0], q[1] - q_ref[0, 1]))
    return [wrap_angle(q_ref[0, 2]), q_ref[0, 3], e]


class ReferenceMonitor(LeafSystem):
    """.. pydrake_system::

        name: ReferenceMonitor
        input_ports:
        - state_estimate
        output_ports:
        - reference
        - mission_complete
        - reference_track

    ``reference`` = [ψ_ref [rad], u_ref [m/s], e [m]] with e the distance from the estimate to
    the reference position now (the same layout the LOS guidance logs); ``mission_complete`` =
    [1] once the reference has ended and the estimate is within ``acceptance_radius`` [m] of its
    final position. ``reference_track`` is the timed reference itself (constant; metrics
    score the tracking against it).
    """

    def __init__(self, reference, acceptance_radius: float):
        super().__init__()
        self._ref, self._radius = reference, acceptance_radius
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self.DeclareVectorOutputPort("reference", 3, self._calc_reference)
        self.DeclareVectorOutputPort("mission_complete", 1, self._calc_complete)
        self.DeclareAbstractOutputPort(
            "reference_track",
            lambda: AbstractValue.Make(reference),
            lambda context, value: value.set_value(self._ref),
            prerequisites_of_calc={self.nothing_ticket()},
        )

    def _calc_reference(self, context, output):
        output.SetFromVector(reference_row(self._ref, context.get_time(), self._est.Eval(context)))

    def _calc_complete(self, context, output):
        done = False
        if context.get_time() >= self._ref.duration:
            q_end, _ = self._ref.sample(np.array([self._ref.duration]))
            q = self._est.Eval(context)
            done = np.hypot(q[0] - q_end[0, 0], q[1] - q_end[0, 1]) <= self._radius
        output.SetFromVector([1.0 if done else 0.0])
