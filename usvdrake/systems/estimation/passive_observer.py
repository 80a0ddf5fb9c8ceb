"""``PassiveObserver``: the NTNU explorer's nonlinear passive observer as a LeafSystem (the
model, gains and discrete step are in :mod:`usvdrake.systems.estimation.observer_dynamics`)."""

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.estimation.observer_dynamics import (
    PassiveObserverConfig,
    fossen_gains,
    initial_observer_state,
    observer_step,
    split_state,
)
from usvdrake.vessel import Hydrodynamics


class PassiveObserver(LeafSystem):
    """The passive observer sampled every 1/rate_hz s (discrete state, outputs held).

    .. pydrake_system::

        name: PassiveObserver
        input_ports:
        - pose_measurement
        - tau
        output_ports:
        - state_estimate
        - bias_estimate

    ``pose_measurement`` = [x, y, ψ] [m, m, rad] (e.g. SLAM at ~5 Hz, held between samples);
    ``tau`` [N, N, N m] the body-frame force actually commanded (e.g. ThrustAllocation's
    ``tau_achieved``). ``state_estimate`` = [x̂, ŷ, ψ̂, û, v̂, r̂] (ψ̂ wrapped to (−π, π]);
    ``bias_estimate`` = b̂ [N, N, N m], world frame (an environmental force τ_env acting in
    the body frame appears as R(ψ) τ_env).

    Timing: the update at t_k samples y(t_k), τ(t_k) and integrates the ODE over [t_k, t_k + h]
    with them held, so the value held over [t_k, t_k + h) is the estimate for t_k + h (a
    one-step prediction: what a controller sampling at t_k needs for the force it will apply).
    The first update is at t = 0 from the initial estimate (``initial_pose``, at rest, zero
    bias; ``set_initial_estimate`` changes it in a context). ``config`` None: ``fossen_gains(xi)``.
    """

    def __init__(
        self, xi: Hydrodynamics, config: PassiveObserverConfig | None = None, initial_pose=None
    ):
        super().__init__()
        config = fossen_gains(xi) if config is None else config
        self._xi, self._cfg = xi, config
        self._h = 1.0 / config.rate_hz
        x0 = initial_observer_state(config, np.zeros(3) if initial_pose is None else initial_pose)
        self._x = self.DeclareDiscreteState(BasicVector(x0))
        self._y = self.DeclareVectorInputPort("pose_measurement", 3)
        self._tau = self.DeclareVectorInputPort("tau", 3)
        self.DeclarePeriodicDiscreteUpdateEvent(self._h, 0.0, self._update)
        deps = {self.xd_ticket()}
        self.DeclareVectorOutputPort("state_estimate", 6, self._calc_state, deps)
        self.DeclareVectorOutputPort("bias_estimate", 3, self._calc_bias, deps)

    @property
    def config(self) -> PassiveObserverConfig:
        return self._cfg

    def set_initial_estimate(self, context, pose, velocity=None, bias=None) -> None:
        """Start from η̂ = pose, ν̂ = velocity (default 0), b̂ = bias (default 0), ξ̂ = 0."""
        x0 = initial_observer_state(self._cfg, pose, velocity, bias)
        context.SetDiscreteState(self._x, x0)

    def _state(self, context) -> np.ndarray:
        return context.get_discrete_state(self._x).CopyToVector()

    def _update(self, context, discrete_state):
        y = self._y.Eval(context)
        tau = self._tau.Eval(context)
        x = observer_step(self._cfg, self._xi, self._state(context), y, tau, self._h)
        discrete_state.get_mutable_vector(self._x).SetFromVector(x)

    def _calc_state(self, context, output):
        _, eta, _, nu = split_state(self._cfg, self._state(context))
        output.SetFromVector(np.concatenate([eta, nu]))

    def _calc_bias(self, context, output):
        output.SetFromVector(split_state(self._cfg, self._state(context))[2])
