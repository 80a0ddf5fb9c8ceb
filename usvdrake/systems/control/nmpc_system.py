"""``Nmpc``: the NMPC of Roboat II §IV-B as a 10 Hz LeafSystem with zero-order hold."""

from dataclasses import dataclass, field

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.systems.control.nmpc_problem import NmpcConfig, NmpcProblem
from usvdrake.systems.guidance.reference_trajectory import HoldPose
from usvdrake.vessel import VesselParams


@dataclass
class NmpcMemory:
    """What the controller remembers between steps (abstract state in the Context)."""

    warm: tuple | None = None  # the last plan shifted by one step: (q (N+1, 6), u (N, n_u))
    predicted: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))  # last predicted states
    # numpy arrays, not lists: Drake deep-copies abstract state at every update, and a deep
    # copy of a long list costs O(n) Python work per step (a 40-minute fleet run spent 70 % of
    # its time there); an array copies as one block
    solve_ms: np.ndarray = field(
        default_factory=lambda: np.zeros(0)
    )  # every solve's wall time [ms]
    costs: np.ndarray = field(
        default_factory=lambda: np.zeros(0)
    )  # (10a) of every successful solve
    failures: int = 0  # solves that failed in total
    consecutive: int = 0  # failures in a row (→ zero thrust past the limit)
    disturbance: np.ndarray = field(
        default_factory=lambda: np.zeros(3)
    )  # d̂, body frame [N, N, N m]


class Nmpc(LeafSystem):
    """Real-time-iteration NMPC (see ``nmpc_problem``) tracking a timed reference.

    .. pydrake_system::

        name: Nmpc
        input_ports:
        - state_estimate
        - disturbance_estimate (optional)
        - reference_trajectory (only when built with reference=None)
        output_ports:
        - thruster_command
        - predicted_trajectory
        - nmpc_failures
        - nmpc_diagnostics

    ``nmpc_diagnostics`` = [solves, failures, median solve time [ms], 95th percentile [ms]]
    over the run so far (what the mission's metrics report).

    Every dt seconds, ``cfg.update_offset`` after the sensors sample (after the estimator's
    update, see ``Nmhe``): sample the reference over the horizon, solve from the estimate with the
    previous plan (shifted) as warm start, hold the first input. A failed solve never stops the
    mission: the previous plan's next input is applied (the plan shifted again) and counted;
    after ``max_consecutive_failures`` failures in a row the command is zero thrust until a solve
    succeeds. ``reference`` is any object with ``sample(times) -> (q_ref (n, 6), ν̇_ref (n, 3))``.

    Offset-free: the model adds a constant body-frame force d̂ over the horizon — from
    ``disturbance_estimate`` when connected (the NMHE's slow-force estimate), else learnt here
    from the one-step prediction error (``NmpcConfig.disturbance_gain``).
    """

    def __init__(self, vessel: VesselParams, cfg: NmpcConfig, reference):
        super().__init__()
        self._problem = NmpcProblem(vessel, cfg)
        self._cfg, self._reference = cfg, reference
        n_u = self._problem.nu
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        # optional: an estimator's body-frame force estimate (e.g. the NMHE's); replaces d̂
        self._dist = self.DeclareVectorInputPort("disturbance_estimate", 3)
        self._ref_port = None
        if reference is None:
            self._ref_port = self.DeclareAbstractInputPort(
                "reference_trajectory", AbstractValue.Make(HoldPose([0.0, 0.0], 0.0))
            )
        self._u = self.DeclareDiscreteState(BasicVector(np.zeros(n_u)))
        self._mem = self.DeclareAbstractState(AbstractValue.Make(NmpcMemory()))
        self.DeclareInitializationUnrestrictedUpdateEvent(self._reset)
        self.DeclarePeriodicUnrestrictedUpdateEvent(cfg.dt, cfg.update_offset, self._step)
        self.DeclareStateOutputPort("thruster_command", self._u)
        self.DeclareAbstractOutputPort(
            "predicted_trajectory",
            lambda: AbstractValue.Make(np.zeros((0, 6))),
            self._calc_predicted,
            prerequisites_of_calc={self.abstract_state_ticket(self._mem)},
        )
        self.DeclareVectorOutputPort(
            "nmpc_failures",
            1,
            self._calc_failures,
            prerequisites_of_calc={self.abstract_state_ticket(self._mem)},
        )
        self.DeclareVectorOutputPort(
            "nmpc_diagnostics",
            4,
            self._calc_diagnostics,
            prerequisites_of_calc={self.abstract_state_ticket(self._mem)},
        )

    @property
    def problem(self) -> NmpcProblem:
        return self._problem

    @property
    def reference(self):
        """The fixed reference, or None when it comes in on ``reference_trajectory``."""
        return self._reference

    def memory(self, context) -> NmpcMemory:
        return context.get_abstract_state(self._mem).get_value()

    def _reset(self, context, state):
        state.get_mutable_abstract_state(self._mem).set_value(NmpcMemory())

    def _step(self, context, state):
        p = self._problem
        old = context.get_abstract_state(self._mem).get_value()
        mem = NmpcMemory(
            old.warm,
            old.predicted,
            old.solve_ms,
            old.costs,
            old.failures,
            old.consecutive,
            old.disturbance,
        )
        q_hat = self._est.Eval(context)
        if self._dist.HasValue(context):
            mem.disturbance = np.array(self._dist.Eval(context), float)
        elif self._cfg.disturbance_gain > 0 and mem.warm is not None:
            # the previous plan predicted where we would be now: its shifted first state
            mem.disturbance = p.update_disturbance(mem.disturbance, q_hat[3:], mem.warm[0][0, 3:])
            if not np.isfinite(mem.disturbance).all():
                mem.disturbance = np.zeros(3)
        times = context.get_time() + p.dt * np.arange(p.N + 1)
        reference = self._reference if self._ref_port is None else self._ref_port.Eval(context)
        q_ref, nu_dot_ref = reference.sample(times)
        u_ref = p.feedforward(q_ref, nu_dot_ref, mem.disturbance)
        try:
            sol = p.solve(q_hat, q_ref, u_ref, mem.warm, mem.disturbance)
        except Exception:  # a numerical failure must never end the mission; it is counted
            sol = None
        if sol is not None and sol.success:
            u_now = sol.u[0]
            mem.warm = p.shift(sol.q, sol.u, mem.disturbance)
            mem.predicted = sol.q
            mem.solve_ms = np.append(mem.solve_ms, sol.solve_ms)
            mem.costs = np.append(mem.costs, sol.cost)
            mem.consecutive = 0
        else:
            mem.failures += 1
            mem.consecutive += 1
            if sol is not None:
                mem.solve_ms = np.append(mem.solve_ms, sol.solve_ms)
            if mem.warm is not None and mem.consecutive <= self._cfg.max_consecutive_failures:
                u_now = mem.warm[1][0]  # the previous plan's input for this step
                mem.warm = p.shift(*mem.warm, mem.disturbance)
            else:
                u_now = np.zeros(p.nu)
                mem.warm = None
        state.get_mutable_discrete_state(self._u).SetFromVector(u_now)
        state.get_mutable_abstract_state(self._mem).set_value(mem)

    def _calc_predicted(self, context, value):
        value.set_value(self.memory(context).predicted)

    def _calc_failures(self, context, output):
        output.SetFromVector([self.memory(context).failures])

    def _calc_diagnostics(self, context, output):
        mem = self.memory(context)
        ms = mem.solve_ms if len(mem.solve_ms) else np.zeros(1)
        output.SetFromVector(
            [len(mem.solve_ms), mem.failures, np.median(ms), np.percentile(ms, 95)]
        )
