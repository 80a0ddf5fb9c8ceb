"""``Environment``: current, wind and waves feeding the plant's ``tau_env`` and ``current``."""

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.vessel.environment_model import EnvironmentConfig, EnvironmentModel
from usvdrake.vessel import VesselParams


class Environment(LeafSystem):
    """Seeded disturbances (see ``environment_model``); the random processes' states (gust
    speed, current speed variation) and their step counter live in the Context.

    .. pydrake_system::

        name: Environment
        input_ports:
        - state
        output_ports:
        - tau_env
        - current

    ``state`` = [x y ψ u v r]; ``tau_env`` [N, N, N m] body frame; ``current`` [m/s] world frame.
    """

    def __init__(self, cfg: EnvironmentConfig, vessel: VesselParams, seed: int):
        super().__init__()
        self._model = EnvironmentModel(cfg, vessel, seed)
        self._state = self.DeclareVectorInputPort("state", 6)
        # [gust speed, current speed variation, step counter]
        self._proc = self.DeclareDiscreteState(BasicVector(np.zeros(3)))
        self.DeclarePeriodicDiscreteUpdateEvent(cfg.update_period, 0.0, self._update)
        self.DeclareVectorOutputPort("tau_env", 3, self._calc_tau_env)
        self.DeclareVectorOutputPort(
            "current", 2, self._calc_current, prerequisites_of_calc={self.xd_ticket()}
        )

    def _update(self, context, discrete_state):
        gust, cvar, k = context.get_discrete_state(self._proc).CopyToVector()
        gust, cvar = self._model.step_processes(gust, cvar, int(k))
        discrete_state.get_mutable_vector(self._proc).SetFromVector([gust, cvar, k + 1])

    def _calc_tau_env(self, context, output):
        gust = context.get_discrete_state(self._proc).GetAtIndex(0)
        q = self._state.Eval(context)
        output.SetFromVector(self._model.tau_env(q, context.get_time(), gust))

    def _calc_current(self, context, output):
        cvar = context.get_discrete_state(self._proc).GetAtIndex(1)
        output.SetFromVector(self._model.current(cvar))
