"""The velocity-setpoint law of Ueland 2017 (§Velocity Control Law, eqs. 2-4) and its LeafSystem.

Ueland 2017 does not command a speed: it moves the position setpoint of the motion controller along
the planned path, farther ahead in open water and closer in narrow places, and the reference
model and PD controller turn the distance into speed. Per cycle:

1. the path (the planner's first 128 points) is re-discretised at r_q = 0.01 m into p_1..p_N;
2. l = the index of the point closest to the vessel;
3. the look-ahead r_s (eq. 2) is piecewise linear in d_min, the lidar's nearest return:
   0.1 m up to 0.3 m, d_min − 0.2 up to 1 m, 2 d_min − 1.2 up to 2.1 m, 3 m beyond;
4. n = round(r_s / r_q) (eq. 3), and the setpoint is p_s with s = min(n + l, N) (eq. 4).
"""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.messages import LaserScan

R_Q = 0.01  # [m] Ueland 2017: re-discretisation step of the path
PATH_POINTS = 128  # Ueland 2017: "the first 128 discrete positions in the planned path"


def lookahead_distance(d_min: float) -> float:
    """Ueland 2017 eq. (2): the look-ahead r_s [m] for the nearest object at ``d_min`` [m].
    Continuous at 1 m and 2.1 m; at 0.3 m it steps from 0.1 to 0.1 (d_min − 0.2 = 0.1): continuous
    too."""
    d = float(d_min)
    if np.isnan(d):
        raise ValueError("lookahead_distance: d_min is NaN")
    if d <= 0.3:
        return 0.1
    if d < 1.0:
        return d - 0.2
    if d < 2.1:
        return 2.0 * d - 1.2
    return 3.0


def rediscretise(path: np.ndarray, step: float = R_Q) -> np.ndarray:
    """Ueland 2017 step 1: points every ``step`` [m] along the polyline ``path`` (n × 2), first and
    last point included (the last gap may be shorter)."""
    path = np.asarray(path, dtype=float).reshape(-1, 2)
    if len(path) < 2:
        return path.copy()
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    if s[-1] <= 0.0:
        return path[:1].copy()
    stations = np.append(np.arange(0.0, s[-1], step), s[-1])
    return np.column_stack([np.interp(stations, s, path[:, 0]), np.interp(stations, s, path[:, 1])])


def setpoint_on_path(
    dense: np.ndarray, position, d_min: float, step: float = R_Q
) -> tuple[np.ndarray, int, int]:
    """Ueland 2017 steps 2-4 on a re-discretised path ``dense`` (N × 2): the setpoint p_s, the
    closest index l and the setpoint index s = min(l + n, N) (0-based here: min(l + n, N − 1))."""
    p = np.asarray(position, dtype=float)[:2]
    closest = int(np.argmin(((dense - p) ** 2).sum(axis=1)))
    n = int(round(lookahead_distance(d_min) / step))
    s = min(closest + n, len(dense) - 1)
    return dense[s].copy(), closest, s


def nearest_return(scan: LaserScan) -> float:
    """d_min [m]: the lidar's nearest valid return; inf when nothing is in range."""
    if scan.valid.size == 0 or not scan.valid.any():
        return np.inf
    return float(scan.ranges[scan.valid].min())


class VelocitySetpointLaw(LeafSystem):
    """Ueland 2017's velocity-setpoint law at ``rate_hz`` (Ueland 2017 runs it faster than the
    planner).

    .. pydrake_system::

        name: VelocitySetpointLaw
        input_ports:
        - path
        - state_estimate
        - lidar_scan
        output_ports:
        - setpoint
        - lookahead

    ``path`` (abstract (n × 2) [m] array; only the first 128 points are used); ``setpoint`` =
    [x_s, y_s, ψ_s] for the reference model, ψ_s the fixed ``heading`` (the round vessel does not
    steer: Ueland 2017 §Experimental Platform); ``lookahead`` = [r_s, d_min, distance from the
    vessel to the path's closest point (a cross-track error)]. With an empty path the setpoint holds
    where the vessel was when the path emptied (stop, or exploration finished). d_min is measured
    from the lidar, taken to sit at the vessel's centre (Ueland 2017's RPLIDAR is on the centre of
    the lid).
    """

    def __init__(self, heading: float, initial_xy, rate_hz: float = 10.0):
        super().__init__()
        if not rate_hz > 0:
            raise ValueError(f"VelocitySetpointLaw: rate_hz must be positive, got {rate_hz}")
        self._heading = float(heading)
        self._path = self.DeclareAbstractInputPort("path", AbstractValue.Make(np.zeros((0, 2))))
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self._scan = self.DeclareAbstractInputPort("lidar_scan", AbstractValue.Make(LaserScan()))
        x0, y0 = np.asarray(initial_xy, dtype=float)[:2]
        # [x_s, y_s, ψ_s, r_s, d_min, holding, cross-track]
        self._state = self.DeclareDiscreteState(
            BasicVector([x0, y0, self._heading, 0.0, np.inf, 1.0, 0.0])
        )
        # The re-discretised path is cached in the abstract state with the path it came from,
        # so a path that is handed over every planning cycle is re-sampled once, not 10 ×/s.
        self._dense = self.DeclareAbstractState(AbstractValue.Make((np.zeros((0, 2)),) * 2))
        self.DeclarePeriodicUnrestrictedUpdateEvent(1.0 / rate_hz, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "setpoint",
            3,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._state).value()[:3]),
        )
        self.DeclareVectorOutputPort(
            "lookahead",
            3,
            lambda c, o: o.SetFromVector(c.get_discrete_state(self._state).value()[[3, 4, 6]]),
        )

    def _update(self, context, state):
        path = np.asarray(self._path.Eval(context), dtype=float).reshape(-1, 2)[:PATH_POINTS]
        est = self._est.Eval(context)
        current = context.get_discrete_state(self._state).value().copy()
        d_min = nearest_return(self._scan.Eval(context))
        if len(path) == 0:
            if current[5] == 0.0:  # the path just emptied: hold here
                current[:2] = est[:2]
            current[3], current[4], current[5], current[6] = 0.0, d_min, 1.0, 0.0
        else:
            source, dense = context.get_abstract_state(self._dense).get_value()
            if source.shape != path.shape or not np.array_equal(source, path):
                dense = rediscretise(path)
                state.get_mutable_abstract_state(self._dense).set_value((path.copy(), dense))
            p_s, closest, _ = setpoint_on_path(dense, est[:2], d_min)
            current[:2] = p_s
            current[3], current[4], current[5] = lookahead_distance(d_min), d_min, 0.0
            current[6] = np.linalg.norm(dense[closest] - est[:2])
        current[2] = self._heading
        state.get_mutable_discrete_state(self._state).SetFromVector(current)


class ExplorationReport(LeafSystem):
    """The exploration loop's ``reference`` in the form the mission metrics and report read
    for every controller: [ψ_d, speed of the reference model |η̇_d| (the speed Ueland 2017's law asks
    for), distance to the planned path].

    .. pydrake_system::

        name: ExplorationReport
        input_ports:
        - reference_model
        - lookahead
        output_ports:
        - reference
    """

    def __init__(self):
        super().__init__()
        self._ref = self.DeclareVectorInputPort("reference_model", 9)
        self._look = self.DeclareVectorInputPort("lookahead", 3)
        self.DeclareVectorOutputPort("reference", 3, self._calc)

    def _calc(self, context, output):
        ref, look = self._ref.Eval(context), self._look.Eval(context)
        output.SetFromVector([ref[2], np.hypot(ref[3], ref[4]), look[2]])
