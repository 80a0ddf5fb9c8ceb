"""``ImuIntervalMean``: an IMU's samples averaged over an estimator's sample intervals.

A 10 Hz estimator (the NMHE of Roboat II §IV-C) cannot read a 100 Hz IMU sample by sample; what it
needs per interval [t_k, t_{k+1}) is the mean level-frame specific force and yaw rate over it,
the quantities :func:`usvdrake.systems.estimation.nmhe_model.imu_interval_model` predicts
from the states at both ends. Averaging also divides the white noise by √(samples).
"""

import math

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.messages import ImuSample

# discrete state: [∫f_x, ∫f_y, ∫ω_z, covered time, last t, last f_x, f_y, ω_z,
#                  mean f_x, f_y, ω_z, interval end]
_INT, _COVER, _LAST_T, _LAST, _OUT = slice(0, 3), 3, 4, slice(5, 8), slice(8, 12)
NAN_MEAN = [np.nan, np.nan, np.nan, np.nan]


def level_imu(sample: ImuSample) -> np.ndarray:
    """[f_x, f_y, ω_z] of one sample in the level frame that shares the body's heading
    [m/s², m/s², rad/s]: the AHRS's roll and pitch taken out (on a rolling boat a 1° tilt
    would leak 0.17 m/s² of gravity into f_x, f_y); an upright sample is unchanged.

    That is ``level_rotation(I, q)`` applied to the readings, written in scalars (one call
    per IMU sample, 100 a second): the AHRS rotation R_a, its yaw ψ_a, and Rz(ψ_a)ᵀ R_a."""
    x, y, z, w = np.asarray(sample.orientation, dtype=float).tolist()
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    r0 = (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w))
    r1 = (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w))
    r2 = (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y))
    yaw = math.atan2(r1[0], r0[0])
    c, s = math.cos(yaw), math.sin(yaw)
    t0 = [c * r0[j] + s * r1[j] for j in range(3)]  # rows of Rz(ψ_a)ᵀ R_a
    t1 = [-s * r0[j] + c * r1[j] for j in range(3)]
    f = np.asarray(sample.linear_acceleration, dtype=float).tolist()
    g = np.asarray(sample.angular_velocity, dtype=float).tolist()
    return np.array(
        [
            t0[0] * f[0] + t0[1] * f[1] + t0[2] * f[2],
            t1[0] * f[0] + t1[1] * f[1] + t1[2] * f[2],
            r2[0] * g[0] + r2[1] * g[1] + r2[2] * g[2],
        ]
    )


class ImuIntervalMean(LeafSystem):
    """Means of the IMU's readings over the intervals [k T, (k + 1) T) (T = ``interval`` [s]).

    .. pydrake_system::

        name: ImuIntervalMean
        input_ports:
        - imu
        output_ports:
        - imu_mean

    ``imu``: :class:`~usvdrake.sensors.messages.ImuSample` (the station's ``imu`` port);
    ``imu_mean`` = [f̄_x f̄_y ω̄_z t_end] [m/s², m/s², rad/s, s]: the time average of
    :func:`level_imu` over the last closed interval, which ends at t_end; all NaN before the
    first one closes.

    **Mean.** Readings are joined by straight lines between their time stamps and the lines
    integrated (the trapezoid rule), split at the interval's ends. A plain average of the
    samples stamped in [t_k, t_{k+1}) would lag by half a sample period: 0.005 rad/s on a yaw
    rate changing by 0.1 rad/s per 0.1 s, more than the gyro's noise on an interval. An
    interval closes when the first reading at or after its end arrives. A gap between two
    readings longer than ``max_gap`` [s] (default 2.5 sample periods) is not bridged, and an
    interval not covered completely is reported with NaN means (missing).

    **Timing.** A periodic update every ``sample_period`` [s] (the IMU's) at ``offset`` [s]
    reads the held reading. With a small offset (after the IMU's update, before the
    estimator's: the autonomy uses half the NMHE's) the interval [t_k, t_{k+1}) closes right
    after the IMU samples t_{k+1}, and the estimator updating just after reads it with the pose
    sample of t_{k+1}, the interval's end. At offset 0 the updates coincide with the IMU's and
    read the reading one period old, and the interval closes a period later. t_end tells the
    reader which interval it got.
    """

    def __init__(
        self,
        interval: float,
        sample_period: float,
        offset: float = 0.0,
        max_gap: float | None = None,
    ):
        super().__init__()
        if not (interval > 0 and sample_period > 0 and sample_period < interval):
            raise ValueError(
                f"ImuIntervalMean: need 0 < sample_period < interval, got {sample_period}, "
                f"{interval}"
            )
        self._interval = float(interval)
        self._max_gap = 2.5 * sample_period if max_gap is None else float(max_gap)
        self._imu = self.DeclareAbstractInputPort("imu", AbstractValue.Make(ImuSample()))
        init = np.zeros(12)
        init[_LAST_T] = np.nan  # no reading yet
        init[_OUT] = NAN_MEAN
        self._state = self.DeclareDiscreteState(BasicVector(init))
        self.DeclarePeriodicDiscreteUpdateEvent(sample_period, offset, self._update)
        self.DeclareVectorOutputPort(
            "imu_mean",
            4,
            lambda context, out: out.SetFromVector(
                context.get_discrete_state(self._state).CopyToVector()[_OUT]
            ),
            prerequisites_of_calc={self.discrete_state_ticket(self._state)},
        )

    def _update(self, context, discrete_state):
        sample: ImuSample = self._imu.Eval(context)
        s = context.get_discrete_state(self._state).CopyToVector()
        t1 = float(sample.time)
        if sample.is_empty() or not (np.isnan(s[_LAST_T]) or t1 > s[_LAST_T]):
            return  # nothing new
        m1 = level_imu(sample)
        if not np.all(np.isfinite(m1)):
            return
        s = interval_mean_step(s, t1, m1, self._interval, self._max_gap)
        discrete_state.get_mutable_vector(self._state).SetFromVector(s)


def interval_mean_step(
    s: np.ndarray, t1: float, m1: np.ndarray, interval: float, max_gap: float
) -> np.ndarray:
    """``ImuIntervalMean``'s state s (layout: ``_INT`` …) after reading m1 [f_x f_y ω_z] at
    time t1 [s] (later than the last one): the segment from the last reading integrated into
    the intervals it crosses, each interval it completes moved to the output."""
    s = s.copy()
    t0 = s[_LAST_T]
    tol = 1e-6 * interval  # stamps k·period and k·interval differ in the last bits
    if np.isfinite(t0):
        m0 = s[_LAST].copy()
        gap_ok = t1 - t0 <= max_gap
        a = t0
        while True:
            end = (np.floor((a + tol) / interval) + 1.0) * interval  # end of a's interval
            b = min(t1, end)
            if gap_ok and b > a:
                mid = m0 + (m1 - m0) * ((0.5 * (a + b) - t0) / (t1 - t0))
                s[_INT] += mid * (b - a)
                s[_COVER] += b - a
            if t1 < end - tol:
                break
            ok = s[_COVER] >= interval - tol
            s[_OUT] = np.append(s[_INT] / interval, end) if ok else [*NAN_MEAN[:3], end]
            s[_INT], s[_COVER] = 0.0, 0.0
            a = end
            if a >= t1 - tol:
                break
    s[_LAST_T] = t1
    s[_LAST] = m1
    return s
