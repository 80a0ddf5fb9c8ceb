"""``SbmpcColav``: Scenario-Based MPC collision avoidance (Johansen et al. 2016; ``sbmpc``)
between the route guidance and the autopilot, on tracked targets only."""

import time

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.angles import wrap_angle
from usvdrake.systems.colav.sbmpc import Sbmpc, SbmpcParams

# colav_diagnostics layout
DIAGNOSTICS = ("offset", "factor", "cost", "min_predicted_distance", "active", "decide_ms",
               "decisions", "encounter_open")  # fmt: skip


class SbmpcColav(LeafSystem):
    """Re-decides (course offset, speed factor) every ``period`` seconds and commands nominal
    course + offset at nominal speed × factor at all times (the nominal course is the route's
    LOS course, which steers back to the route once the offset returns to 0).

    .. pydrake_system::

        name: SbmpcColav
        input_ports:
        - state
        - nominal
        - path_course (optional)
        - distance_to_end (optional)
        - tracks
        output_ports:
        - command
        - colav_diagnostics

    ``state`` = own [x y ψ u v r]; ``nominal`` = [course [rad], speed [m/s]] from guidance;
    ``tracks``: a list of ``tracking.Track`` (the AIS tracker's; never the targets' truth);
    ``command`` = [course [rad], speed [m/s]]; ``colav_diagnostics`` = [offset [rad], factor,
    cost, min_predicted_distance [m], active, decide_ms, decisions, encounter_open]. While an
    encounter is open the guidance's pull back to the route (``path_course``, optional) is at
    most ``max_return`` [rad]. Within ``end_release`` [m] of the route's end
    (``distance_to_end``, optional) no stand-on duty bounds the course (``Sbmpc.decide``'s
    ``hold_stand_on``): a stand-on ship held off its route there would miss its end. The
    ``Sbmpc`` (last choice, remembered COLREG roles) is abstract state; the last decision is
    discrete state. ``destination`` (the route's end [x, y]) and ``arrival_radius`` [m]: the
    predictions end where they arrive, and with ``end_leg_start`` (the last leg's start) a
    prediction that runs past the end without arriving costs more (``Sbmpc.decide``).
    """

    def __init__(
        self,
        params: SbmpcParams | None = None,
        period: float = 5.0,
        max_return: float | None = None,
        end_release: float | None = None,
        destination=None,
        arrival_radius: float = 0.0,
        end_leg_start=None,
    ):
        super().__init__()
        if not period > 0.0:
            raise ValueError(f"SbmpcColav: period must be positive, got {period}")
        self._state = self.DeclareVectorInputPort("state", 6)
        self._nominal = self.DeclareVectorInputPort("nominal", 2)
        self._path = self.DeclareVectorInputPort("path_course", 1)
        self._max_return = max_return
        self._to_end = self.DeclareVectorInputPort("distance_to_end", 1)
        self._end_release = end_release
        self._destination = None if destination is None else np.asarray(destination, float)
        self._arrival = float(arrival_radius)
        self._leg_start = None if end_leg_start is None else np.asarray(end_leg_start, float)
        self._tracks = self.DeclareAbstractInputPort("tracks", AbstractValue.Make([]))
        self._sbmpc = self.DeclareAbstractState(AbstractValue.Make(Sbmpc(params)))
        initial = np.array([0.0, 1.0, 0.0, np.inf, 0.0, 0.0, 0.0, 0.0])
        self._diag = self.DeclareDiscreteState(BasicVector(initial))
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        deps = {
            self.xd_ticket(),
            self.input_port_ticket(self._nominal.get_index()),
            self.input_port_ticket(self._path.get_index()),
        }
        self.DeclareVectorOutputPort("command", 2, self._calc_command, deps)
        self.DeclareStateOutputPort("colav_diagnostics", self._diag)

    def _update(self, context, state):
        x, y, psi, u, v, _ = self._state.Eval(context)
        course_ref, speed_ref = self._nominal.Eval(context)
        c, s = np.cos(psi), np.sin(psi)
        vx, vy = u * c - v * s, u * s + v * c  # velocity over ground: SB-MPC works in courses
        sbmpc = state.get_mutable_abstract_state(self._sbmpc).get_value()
        # nearly stopped, the course over ground is noise: the heading is where the ship points
        sog = float(np.hypot(vx, vy))
        course = float(np.arctan2(vy, vx)) if sog > sbmpc.params.min_target_speed else float(psi)
        path = float(self._path.Eval(context)[0]) if self._path.HasValue(context) else None
        hold = not (
            self._end_release is not None
            and self._to_end.HasValue(context)
            and self._to_end.Eval(context)[0] < self._end_release
        )
        t0 = time.perf_counter()
        d = sbmpc.decide(
            [x, y], course, sog, float(course_ref),
            float(speed_ref), self._tracks.Eval(context),
            path_course=path, hold_stand_on=hold, destination=self._destination,
            arrival_radius=self._arrival, end_leg_start=self._leg_start,
        )  # fmt: skip
        ms = 1e3 * (time.perf_counter() - t0)
        count = context.get_discrete_state(self._diag).GetAtIndex(6) + 1.0
        row = [d.course_offset, d.speed_factor, d.cost, d.min_distance, float(d.active), ms, count]
        row.append(float(d.encounter_open))
        state.get_mutable_discrete_state(self._diag).SetFromVector(row)

    def _calc_command(self, context, output):
        diag = context.get_discrete_state(self._diag).value()
        offset, factor, encounter_open = diag[0], diag[1], diag[7]
        course, speed = self._nominal.Eval(context)
        if encounter_open and self._max_return is not None and self._path.HasValue(context):
            # while a target is before its CPA, the guidance's pull back to the route is kept
            # shallow: a steep return would be a turn to port, or a stand-on ship's deviation
            path = self._path.Eval(context)[0]
            pull = np.clip(wrap_angle(course - path), -self._max_return, self._max_return)
            course = path + pull
        output.SetFromVector([wrap_angle(course + offset), speed * factor])
