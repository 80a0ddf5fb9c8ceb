"""``Imu``: a simulated IMU/AHRS behind the station's ``imu`` port."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.imu_model import ImuConfig, ImuModel
from usvdrake.sensors.messages import ImuSample


class Imu(LeafSystem):
    """Seeded IMU samples at ``cfg.rate_hz`` (see ``imu_model`` for the error model).

    .. pydrake_system::

        name: Imu
        input_ports:
        - state
        - acceleration
        output_ports:
        - imu

    ``state`` = [x y ψ u v r] [m, rad, m/s, rad/s]; ``acceleration`` = [u̇ v̇ ṙ] [m/s², rad/s²],
    body frame (the plant's ν̇, 000 eq. 2). ``imu``: the last
    :class:`~usvdrake.sensors.messages.ImuSample` (angular velocity, specific force, AHRS
    orientation), body frame x forward, y left, z up.

    A periodic unrestricted update at the sample rate (first sample at t = 0) steps the bias and
    heading-error processes and stores the sample: the processes [b_g, b_a, δψ] and the sample
    counter are discrete state, the sample is abstract state, and ``imu`` reads the state.
    """

    def __init__(self, cfg: ImuConfig, seed: int):
        super().__init__()
        self._model = ImuModel(cfg, seed)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._accel = self.DeclareVectorInputPort("acceleration", 3)
        # [b_g (3), b_a (3), δψ, sample counter k]
        self._proc = self.DeclareDiscreteState(
            BasicVector(np.append(self._model.initial_processes(), 0.0))
        )
        self._sample = self.DeclareAbstractState(AbstractValue.Make(ImuSample()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._model.period, 0.0, self._update)
        self.DeclareStateOutputPort("imu", self._sample)

    @property
    def model(self) -> ImuModel:
        return self._model

    def _update(self, context, state):
        d = context.get_discrete_state(self._proc).CopyToVector()
        k = int(d[7])
        processes, noise = self._model.step(d[:7], k)
        sample = self._model.sample(
            self._state.Eval(context),
            self._accel.Eval(context),
            processes,
            noise,
            k * self._model.period,
        )
        state.get_mutable_discrete_state(self._proc).SetFromVector(np.append(processes, k + 1))
        state.get_mutable_abstract_state(self._sample).set_value(sample)
