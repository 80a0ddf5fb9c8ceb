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
    body frame (the plant's ν̇, Roboat II eq. 2). ``imu``: the last
    :class:`~usvdrake.sensors.messages.ImuSample` (angular velocity, specific force, AHRS
    orientation), body frame x forward, y left, z up.

    A periodic discrete update at the sample rate (first sample at t = 0) steps the bias and
    heading-error processes and stores the sample; both are discrete state ([b_g, b_a, δψ, k] and
    [t, ω̃, f̃, q̃]), and ``imu`` wraps the stored sample in a message when read. (Discrete rather
    than abstract state: at 100 Hz, cloning a Python message on every update costs more than
    building it only when a consumer reads the port.)
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
        # [t, ω̃ (3), f̃ (3), q̃ (4, x y z w)] of the last sample
        self._sample = self.DeclareDiscreteState(BasicVector(_pack(ImuSample())))
        self.DeclarePeriodicDiscreteUpdateEvent(self._model.period, 0.0, self._update)
        self.DeclareAbstractOutputPort(
            "imu",
            lambda: AbstractValue.Make(ImuSample()),
            self._calc_imu,
            prerequisites_of_calc={self.discrete_state_ticket(self._sample)},
        )

    @property
    def model(self) -> ImuModel:
        return self._model

    def _update(self, context, discrete_state):
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
        discrete_state.get_mutable_vector(self._proc).SetFromVector(np.append(processes, k + 1))
        discrete_state.get_mutable_vector(self._sample).SetFromVector(_pack(sample))

    def _calc_imu(self, context, output):
        v = context.get_discrete_state(self._sample).CopyToVector()
        output.set_value(
            ImuSample(
                time=float(v[0]),
                angular_velocity=v[1:4],
                linear_acceleration=v[4:7],
                orientation=v[7:11],
            )
        )


def _pack(sample: ImuSample) -> np.ndarray:
    return np.concatenate(
        [
            [sample.time],
            sample.angular_velocity,
            sample.linear_acceleration,
            sample.orientation,
        ]
    )
