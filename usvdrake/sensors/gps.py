"""``Gps``: a simulated GNSS receiver behind the station's ``gps`` port."""

from collections.abc import Callable

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.gps_model import GpsConfig, GpsModel, world_velocity
from usvdrake.sensors.messages import GpsFix


class Gps(LeafSystem):
    """Seeded GNSS fixes at ``cfg.rate_hz`` (see ``gps_model`` for the error model).

    .. pydrake_system::

        name: Gps
        input_ports:
        - state
        output_ports:
        - gps

    ``state`` = [x y ψ u v r]: world ENU position [m], heading [rad], body velocities [m/s,
    rad/s]. ``gps``: the last :class:`~usvdrake.sensors.messages.GpsFix` (WGS84 about the
    datum ``cfg.datum``), invalid before the first fix and wherever ``denied(x, y)`` is true.
    ``sky_blocked(x, y)`` ∈ [0, 1] is the fraction of the sky above 30° hidden by buildings at
    the true position (0: open sky); the world model supplies both.

    A periodic unrestricted update at the fix rate (first fix at t = 0) advances the error
    processes and stores the new fix: the errors [ε_E, ε_N, ε_U, b] and the fix counter are
    discrete state, the fix is abstract state, and ``gps`` reads the state.
    """

    def __init__(
        self,
        cfg: GpsConfig,
        seed: int,
        denied: Callable[[float, float], bool] = lambda x, y: False,
        sky_blocked: Callable[[float, float], float] = lambda x, y: 0.0,
    ):
        super().__init__()
        self._model = GpsModel(cfg, seed)
        self._denied, self._sky_blocked = denied, sky_blocked
        self._state = self.DeclareVectorInputPort("state", 6)
        # [ε_E, ε_N, ε_U, altitude bias, fix counter k]
        self._errors = self.DeclareDiscreteState(
            BasicVector(np.append(self._model.initial_errors(), 0.0))
        )
        self._fix = self.DeclareAbstractState(AbstractValue.Make(GpsFix()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._model.period, 0.0, self._update)
        self.DeclareStateOutputPort("gps", self._fix)

    @property
    def model(self) -> GpsModel:
        return self._model

    def _update(self, context, state):
        d = context.get_discrete_state(self._errors).CopyToVector()
        k = int(d[4])
        errors = self._model.step_errors(d[:4], k)
        q = self._state.Eval(context)
        x, y = float(q[0]), float(q[1])
        fix = self._model.fix(
            errors,
            q[:2],
            world_velocity(q),
            k,
            denied=bool(self._denied(x, y)),
            sky_blocked=float(self._sky_blocked(x, y)),
        )
        state.get_mutable_discrete_state(self._errors).SetFromVector(np.append(errors, k + 1))
        state.get_mutable_abstract_state(self._fix).set_value(fix)
