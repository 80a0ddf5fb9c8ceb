"""``Nmhe``: the moving-horizon estimator of Roboat II §IV-C (eqs. 15-17) as a 10 Hz LeafSystem."""

import time

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.estimation.nmhe_model import NmheConfig, NmheWindow, screen_sample
from usvdrake.systems.estimation.nmhe_problem import NmheProblem
from usvdrake.vessel import VesselParams

# Diagnostics: [failures, solves, last solve [ms], max solve [ms], total solve time [ms], events,
# samples with a missing, non-finite or impossible pose / thrust value (screen_sample)]
DIAG_FAILURES, DIAG_SOLVES, DIAG_LAST_MS, DIAG_MAX_MS, DIAG_TOTAL_MS, DIAG_EVENTS = range(6)
DIAG_SCREENED = 6


class Nmhe(LeafSystem):
    """Estimates the full state q = [x y ψ u v r] from pose and thrust measurements (see
    ``nmhe_problem`` for the formulation, one Gauss-Newton QP per sample).

    .. pydrake_system::

        name: Nmhe
        input_ports:
        - pose_measurement
        - thrust_measured
        - imu_mean (optional)
        output_ports:
        - state_estimate
        - tau_env_estimate
        - nmhe_failures
        - nmhe_solve_ms
        - estimate_time

    ``pose_measurement`` = [x y ψ r] [m, m, rad, rad/s] (``PoseSensor``; ψ may be wrapped);
    ``thrust_measured``: the thruster command layout [N, rad] (``ThrustSensor``).
    ``imu_mean`` = [f̄_x f̄_y ω̄_z t_end] (``ImuIntervalMean`` at ``cfg.rate_hz``): when
    connected, the IMU's mean over the interval that ends at the newest pose sample enters the
    window (see "IMU" in ``nmhe_problem``); a mean of another interval, or NaN, is missing.
    ``state_estimate`` = q̂ [m, m, rad, m/s, m/s, rad/s], held (see Timing; ψ̂ continuous,
    unwrapped); ``tau_env_estimate`` = b̂ [N, N, N m], the slow unmodelled body force
    the estimator has learnt (wind, current drag, model error); ``nmhe_failures``: failed solves
    so far; ``nmhe_solve_ms``: wall time of the last update [ms] (log it for statistics).

    **Timing.** The sensors sample at t_k = k dt (dt = 1 / ``cfg.rate_hz``; their rates must
    equal it). A periodic discrete update every dt at ``cfg.update_offset`` (default 1 ms, the
    estimator's compute slot) reads the samples just taken at t_k, and a controller updating
    at its own offset after that (the NMPC's 2 ms) reads this estimate: the loop's latency is
    the compute slots, as on the boat, not whole periods. With update_offset 0 the update is
    simultaneous with the sensors' and Drake gives it the samples of t_{k−1} (simultaneous
    discrete updates read the old state; the first event only starts the clock). The output
    ``state_estimate`` is the newest sample's estimate propagated ``cfg.output_lead`` [s] (to
    when its consumer reads it) by RK4 of eq. (7) with the newest thrust reading held and b̂;
    ``estimate_time`` [s] is the instant it refers to (newest sample + lead), for scoring it
    against the truth. Before the first solve the output is ``initial_state`` (or zero) at
    t = 0.

    **State.** The window (poses, thrust readings, last trajectory, arrival prior, b̂, sample
    count), the estimate and the diagnostics are discrete state in the Context; the
    ``NmheProblem`` inside is a workspace that every update overwrites completely. Until the
    window is full the estimator uses the samples it has (prior: ``initial_state``, else the
    first pose with zero velocity). A failed QP keeps the previous trajectory propagated by one
    sample and counts a failure; an exception in the solver additionally restarts the window
    from the next sample. Pose or thrust values that are non-finite or impossible never reach
    the QP (:func:`~usvdrake.systems.estimation.nmhe_model.screen_sample`: a missing pose value,
    the last thrust reading); such samples are counted (``nmhe_diagnostics[6]``). The estimator
    never stops the simulation.
    """

    def __init__(
        self,
        vessel: VesselParams,
        cfg: NmheConfig | None = None,
        initial_state: np.ndarray | None = None,
    ):
        super().__init__()
        self._problem = NmheProblem(vessel.hydrodynamics, vessel.thrusters, cfg)
        p = self._problem
        self._initial_state = None if initial_state is None else np.array(initial_state, float)
        if self._initial_state is not None and self._initial_state.shape != (6,):
            raise ValueError(f"Nmhe: initial_state needs 6 values, got {self._initial_state}")
        empty = p.empty_window()
        self._pose = self.DeclareVectorInputPort("pose_measurement", 4)
        self._thrust = self.DeclareVectorInputPort("thrust_measured", p.n_u)
        self._imu_mean = self.DeclareVectorInputPort("imu_mean", 4)
        self._z = self.DeclareDiscreteState(BasicVector(empty.z.ravel()))
        self._u = self.DeclareDiscreteState(BasicVector(empty.u.ravel()))
        self._traj = self.DeclareDiscreteState(BasicVector(empty.trajectory.ravel()))
        self._imu = self.DeclareDiscreteState(BasicVector(empty.imu.ravel()))
        # [prior q̄ (6), b̂ (3), sample count, b̂_a (2)]
        self._mem = self.DeclareDiscreteState(BasicVector(np.zeros(12)))
        q0 = np.zeros(6) if self._initial_state is None else self._initial_state
        self._est = self.DeclareDiscreteState(BasicVector(q0))
        self._diag = self.DeclareDiscreteState(BasicVector(np.zeros(7)))
        self._est_time = self.DeclareDiscreteState(BasicVector([0.0]))
        self._lead = p.cfg.output_lead
        # at offset 0 the samples read are one period old (see Timing)
        self._sample_age = p.cfg.update_offset if p.cfg.update_offset > 0 else p.dt
        self.DeclarePeriodicDiscreteUpdateEvent(p.dt, p.cfg.update_offset, self._update)
        self.DeclareStateOutputPort("state_estimate", self._est)
        mem_ticket = {self.discrete_state_ticket(self._mem)}
        diag_ticket = {self.discrete_state_ticket(self._diag)}
        self.DeclareVectorOutputPort(
            "tau_env_estimate", 3, self._calc_bias, prerequisites_of_calc=mem_ticket
        )
        self.DeclareVectorOutputPort(
            "nmhe_failures", 1, self._calc_failures, prerequisites_of_calc=diag_ticket
        )
        self.DeclareVectorOutputPort(
            "nmhe_solve_ms", 1, self._calc_solve_ms, prerequisites_of_calc=diag_ticket
        )
        self.DeclareStateOutputPort("estimate_time", self._est_time)
        # [failures, solves, last ms, max ms, total ms, update events, rejected samples]
        self.DeclareStateOutputPort("nmhe_diagnostics", self._diag)

    @property
    def problem(self) -> NmheProblem:
        return self._problem

    def window(self, context) -> NmheWindow:
        """The estimator's window as stored in ``context``."""
        M, n_u = self._problem.M, self._problem.n_u
        mem = context.get_discrete_state(self._mem).CopyToVector()
        return NmheWindow(
            z=context.get_discrete_state(self._z).CopyToVector().reshape(M, 4),
            u=context.get_discrete_state(self._u).CopyToVector().reshape(M, n_u),
            trajectory=context.get_discrete_state(self._traj).CopyToVector().reshape(M, 6),
            prior=mem[:6],
            bias=mem[6:9],
            count=int(mem[9]),
            imu=context.get_discrete_state(self._imu).CopyToVector().reshape(M, 3),
            accel_bias=mem[10:12],
        )

    def diagnostics(self, context) -> dict:
        """failures, solves, last_ms, max_ms, mean_ms of the updates so far."""
        d = context.get_discrete_state(self._diag).CopyToVector()
        solves = int(d[DIAG_SOLVES])
        return {
            "failures": int(d[DIAG_FAILURES]),
            "solves": solves,
            "last_ms": float(d[DIAG_LAST_MS]),
            "max_ms": float(d[DIAG_MAX_MS]),
            "mean_ms": float(d[DIAG_TOTAL_MS]) / solves if solves else 0.0,
            "screened": int(d[DIAG_SCREENED]),
        }

    def _update(self, context, discrete_state):
        p = self._problem
        d = context.get_discrete_state(self._diag).CopyToVector()
        d[DIAG_EVENTS] += 1
        if d[DIAG_EVENTS] == 1 and p.cfg.update_offset == 0:  # t_0: no sample held yet
            discrete_state.get_mutable_vector(self._diag).SetFromVector(d)
            return
        window = self.window(context)
        z_new = self._pose.Eval(context)
        u_new = self._thrust.Eval(context)
        imu_new = None
        if self._imu_mean.HasValue(context):
            m = self._imu_mean.Eval(context)
            # the mean over the interval that ends at the newest pose sample, or none
            if abs(m[3] - (context.get_time() - self._sample_age)) < 0.5 * p.dt:
                imu_new = m[:3]
        estimate = context.get_discrete_state(self._est).CopyToVector()
        est_time = context.get_discrete_state(self._est_time).GetAtIndex(0)
        if imu_new is not None and not np.all(np.isfinite(imu_new)):
            imu_new = None  # a broken IMU mean is a missing one
        z_new, u_new, skipped = screen_sample(z_new, u_new, window.u[-1])
        d[DIAG_SCREENED] += skipped
        t_start = time.perf_counter()
        try:
            window, sol = p.step(window, z_new, u_new, self._initial_state, imu_new)
            ok = sol.success
            estimate = p.predict(sol.estimate, window.u[-1], self._lead, window.bias)
            est_time = context.get_time() - self._sample_age + self._lead
        except (RuntimeError, ValueError, np.linalg.LinAlgError):
            # Keep the last estimate propagated and start a fresh window from the next sample.
            ok = False
            window = p.empty_window()
            estimate = p.predict(estimate, u_new, p.dt)  # the held output, one period on
            est_time += p.dt
        ms = 1e3 * (time.perf_counter() - t_start)
        if not np.all(np.isfinite(estimate)):
            ok, window = False, p.empty_window()
            estimate = context.get_discrete_state(self._est).CopyToVector()
            est_time = context.get_discrete_state(self._est_time).GetAtIndex(0)
        d[DIAG_FAILURES] += 0 if ok else 1
        d[DIAG_SOLVES] += 1
        d[DIAG_LAST_MS] = ms
        d[DIAG_MAX_MS] = max(d[DIAG_MAX_MS], ms)
        d[DIAG_TOTAL_MS] += ms
        discrete_state.get_mutable_vector(self._z).SetFromVector(window.z.ravel())
        discrete_state.get_mutable_vector(self._u).SetFromVector(window.u.ravel())
        discrete_state.get_mutable_vector(self._traj).SetFromVector(window.trajectory.ravel())
        discrete_state.get_mutable_vector(self._imu).SetFromVector(window.imu.ravel())
        discrete_state.get_mutable_vector(self._mem).SetFromVector(
            np.concatenate([window.prior, window.bias, [window.count], window.accel_bias])
        )
        discrete_state.get_mutable_vector(self._est).SetFromVector(estimate)
        discrete_state.get_mutable_vector(self._est_time).SetFromVector([est_time])
        discrete_state.get_mutable_vector(self._diag).SetFromVector(d)

    def _calc_bias(self, context, output):
        output.SetFromVector(context.get_discrete_state(self._mem).CopyToVector()[6:9])

    def _calc_failures(self, context, output):
        output.SetFromVector([context.get_discrete_state(self._diag).GetAtIndex(DIAG_FAILURES)])

    def _calc_solve_ms(self, context, output):
        output.SetFromVector([context.get_discrete_state(self._diag).GetAtIndex(DIAG_LAST_MS)])
