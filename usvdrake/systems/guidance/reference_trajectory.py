"""A timed reference trajectory for the NMPC from a planned path (Roboat II §III, §VI-B).

Roboat II's NMPC tracks references from an A* planner at u = 0.6 m/s surge and v = 0 (Roboat II
§VI-B); goals are given one after another and the vessel "approaches the current goal position
and heads to the next goal by fast turning itself". :class:`ReferenceTrajectory` turns the
planner's straight legs (:mod:`grid_astar`) into that reference:

* Geometry. Each corner of the polyline is rounded by a circular arc of radius R = u / r_max,
  tangent to both legs (so heading is continuous and |r| = u |κ| ≤ r_max), the tangent length
  being R tan(|Δψ|/2) for a turn of Δψ. An arc cuts inside its corner by R (sec(Δψ/2) − 1),
  towards the obstacle the corner wraps, so when a planning grid is given each arc is checked
  against the grid's clearance and, if it comes too close, the corner is pushed outwards along
  its bisector (by the cut-in first, then more) while both new legs stay clear. A corner whose
  arc does not fit (legs too short, turn > 120°, or no clear push) becomes a stop: the vessel
  comes to rest on it and turns in place, as Roboat II does with its sway thrusters.
* Timing. Between stops the surge speed follows a rest-to-rest profile with cosine ramps,
      u(t) = U (1 − cos(π t / T)) / 2,   0 ≤ t ≤ T = π U / (2 a_max),
  whose acceleration U π/(2T) sin(π t/T) is continuous and peaks at a_max; legs too short to
  reach U get a lower peak. Turns in place use the same profile in ψ with r_max and ṙ_max.
* Reference. q_ref = [x y ψ u v r] with ψ the unwrapped path tangent, v = 0 and r = κ u;
  ν̇_ref = [u̇ 0 ṙ] with ṙ = κ u̇ (r steps by ±u/R where an arc meets a straight leg; the
  impulse of ṙ there is not represented).

Defaults: a_max = 0.1 m/s² takes m11 a_max = 17 N of Roboat II's 100 N surge thrust (Roboat II eq.
14, m11 = 172 kg), leaving most for feedback and 0.6 m/s is reached in 9.4 s over 2.8 m; r_max =
0.25 rad/s keeps a margin under the |r| ≤ 0.3 rad/s we allow Roboat II at 0.6 m/s (R = 2.4 m;
holding v = 0 on the arc takes m11 u r = 26 N of sway thrust); ṙ_max = 0.1 rad/s² needs m33 ṙ_max =
2.4 N m of ~100 N m yaw authority.
"""

import math
from dataclasses import dataclass

import numpy as np

from usvdrake.systems.guidance.grid_astar import DEFAULT_INFLATION, PlanningGrid
from usvdrake.worlds.world import World

MAX_FILLET_TURN = 2.0 * math.pi / 3.0  # [rad] sharper corners stop and turn in place
MAX_PUSHES = 4  # attempts at pushing one corner outwards before making it a stop


def _wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


@dataclass(frozen=True)
class RestToRest:
    """Rest-to-rest motion over ``distance`` with cosine ramps (module docstring)."""

    distance: float  # [m] or [rad] travelled
    peak: float  # [m/s] or [rad/s] cruise rate actually reached
    ramp: float  # [s] duration of each ramp
    duration: float  # [s] total

    @classmethod
    def make(cls, distance: float, rate: float, accel: float) -> "RestToRest":
        if not (rate > 0 and accel > 0):
            raise ValueError(f"RestToRest: rate and accel must be positive, got {rate}, {accel}")
        distance = abs(float(distance))
        if distance == 0.0:
            return cls(0.0, 0.0, 0.0, 0.0)
        peak = min(rate, math.sqrt(2.0 * accel * distance / math.pi))
        ramp = math.pi * peak / (2.0 * accel)
        cruise = (distance - peak * ramp) / peak
        return cls(distance, peak, ramp, 2.0 * ramp + max(cruise, 0.0))

    def __call__(self, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, rate and acceleration at times ``tau`` [s] since the start (held at rest
        outside [0, duration])."""
        tau = np.clip(np.asarray(tau, float), 0.0, self.duration)
        if self.duration == 0.0:
            z = np.zeros_like(tau)
            return z, z, z

        def up(t):
            w = math.pi / self.ramp
            return (
                0.5 * self.peak * (t - np.sin(w * t) / w),
                0.5 * self.peak * (1.0 - np.cos(w * t)),
                0.5 * self.peak * w * np.sin(w * t),
            )

        p_up, v_up, a_up = up(np.minimum(tau, self.ramp))
        back = np.minimum(self.duration - tau, self.ramp)
        p_dn, v_dn, a_dn = up(back)
        accelerating = tau < self.ramp
        braking = self.duration - tau < self.ramp
        cruise_p = 0.5 * self.peak * self.ramp + self.peak * (tau - self.ramp)
        p = np.where(accelerating, p_up, np.where(braking, self.distance - p_dn, cruise_p))
        v = np.where(accelerating, v_up, np.where(braking, v_dn, self.peak))
        a = np.where(accelerating, a_up, np.where(braking, -a_dn, 0.0))
        return p, v, a


@dataclass(frozen=True)
class Curve:
    """A plane curve of straight lines (κ = 0) and circular arcs, by arc length s [m]."""

    s0: np.ndarray  # (k,) [m] arc length at the start of each piece
    p0: np.ndarray  # (k, 2) [m] start point of each piece
    psi0: np.ndarray  # (k,) [rad] tangent heading at the start of each piece (unwrapped)
    kappa: np.ndarray  # (k,) [1/m] curvature of each piece, + turning left
    length: float  # [m]

    @classmethod
    def fillet(cls, points: np.ndarray, radius: float) -> "Curve":
        """The polyline ``points`` with every interior corner rounded by an arc of ``radius``
        [m] (the caller has checked that the tangent lengths fit)."""
        d = np.diff(points, axis=0)
        seg = np.hypot(d[:, 0], d[:, 1])
        u = d / seg[:, None]
        heading = np.arctan2(u[:, 1], u[:, 0])
        turn = np.array([_wrap(b - a) for a, b in zip(heading[:-1], heading[1:], strict=True)])
        psi = heading[0] + np.concatenate([[0.0], np.cumsum(turn)])  # unwrapped leg headings
        tangent = radius * np.tan(0.5 * np.abs(turn))
        pieces = []  # (s0, x0, y0, ψ0, κ)
        s = 0.0
        for i in range(len(seg)):
            a = points[i] + (tangent[i - 1] if i > 0 else 0.0) * u[i]
            line = seg[i] - (tangent[i - 1] if i > 0 else 0.0)
            line -= tangent[i] if i < len(turn) else 0.0
            pieces.append((s, *a, psi[i], 0.0))
            s += max(line, 0.0)
            if i < len(turn) and tangent[i] > 0.0:
                a = points[i + 1] - tangent[i] * u[i]
                pieces.append((s, *a, psi[i], math.copysign(1.0 / radius, turn[i])))
                s += radius * abs(turn[i])
        pc = np.array(pieces)
        return cls(pc[:, 0], pc[:, 1:3], pc[:, 3], pc[:, 4], float(s))

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Points (n × 2) [m], headings [rad] and curvatures [1/m] at arc lengths ``s``."""
        s = np.clip(np.atleast_1d(np.asarray(s, float)), 0.0, self.length)
        i = np.clip(np.searchsorted(self.s0, s, side="right") - 1, 0, len(self.s0) - 1)
        sigma, k, psi0 = s - self.s0[i], self.kappa[i], self.psi0[i]
        psi = psi0 + k * sigma
        arc = k != 0.0
        k_safe = np.where(arc, k, 1.0)
        dx = np.where(arc, (np.sin(psi) - np.sin(psi0)) / k_safe, sigma * np.cos(psi0))
        dy = np.where(arc, (np.cos(psi0) - np.cos(psi)) / k_safe, sigma * np.sin(psi0))
        return self.p0[i] + np.column_stack([dx, dy]), psi, k


def _turn(points: np.ndarray, i: int) -> float:
    """Signed change of heading [rad] at interior vertex i, + to the left."""
    a, b = points[i] - points[i - 1], points[i + 1] - points[i]
    return math.atan2(a[0] * b[1] - a[1] * b[0], a @ b)


def _outward(points: np.ndarray, i: int) -> np.ndarray:
    """Unit vector from vertex i away from the centre of its turn."""
    a = points[i] - points[i - 1]
    b = points[i + 1] - points[i]
    w = a / np.linalg.norm(a) - b / np.linalg.norm(b)
    return w / np.linalg.norm(w)


def _arc_points(points: np.ndarray, i: int, radius: float, spacing: float) -> np.ndarray:
    """Samples of the fillet arc at vertex i, ends included."""
    c = Curve.fillet(points[i - 1 : i + 2], radius)
    arc = np.nonzero(c.kappa != 0.0)[0]
    if len(arc) == 0:
        return points[i : i + 1]
    s_start = c.s0[arc[0]]
    s_end = c.s0[arc[0] + 1] if arc[0] + 1 < len(c.s0) else c.length
    n = max(2, int(np.ceil((s_end - s_start) / spacing)) + 1)
    return c.at(np.linspace(s_start, s_end, n))[0]


def smooth_corners(
    points: np.ndarray, radius: float, grid: PlanningGrid | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Decide which corners of a polyline get a fillet of ``radius`` [m] and which are stops,
    pushing corners outwards where a fillet would come closer than ``grid.inflation`` to an
    obstacle (module docstring). Returns the (possibly moved) points and a bool mask of stops
    (the two ends are always stops)."""
    p = np.array(points, float)
    p = p[np.r_[True, np.hypot(*np.diff(p, axis=0).T) > 1e-9]]
    straight = [j for j in range(1, len(p) - 1) if abs(_turn(p, j)) < 1e-9]
    p = np.delete(p, straight, axis=0)
    n = len(p)
    stop = np.zeros(n, bool)
    stop[[0, -1]] = True
    pushes = np.zeros(n, int)
    spacing = 0.25 * grid.resolution if grid is not None else 0.1

    def tangent(j: int) -> float:
        if stop[j]:
            return 0.0
        return radius * math.tan(0.5 * abs(_turn(p, j)))

    def fits(j: int) -> bool:
        turn = abs(_turn(p, j))
        if turn > MAX_FILLET_TURN:
            return False
        t = radius * math.tan(0.5 * turn)
        left = np.linalg.norm(p[j] - p[j - 1]) - tangent(j - 1)
        right = np.linalg.norm(p[j + 1] - p[j]) - tangent(j + 1)
        return t <= left + 1e-9 and t <= right + 1e-9

    def clear(j: int) -> bool:
        if grid is None:
            return True
        arc = _arc_points(p, j, radius, spacing)
        return bool(np.all(grid.clearance_at(arc) >= grid.inflation - 1e-9))

    for _ in range((MAX_PUSHES + 2) * n):  # each pass adds a stop or a push, or ends
        changed = False
        for j in range(1, n - 1):
            if stop[j] or (fits(j) and clear(j)):
                continue
            if fits(j) and pushes[j] < MAX_PUSHES:
                # Push the corner out so the arc's middle lands where the corner was, then
                # further; accept the first position whose legs and arc are clear.
                turn = abs(_turn(p, j))
                cut = radius * (1.0 / math.cos(0.5 * turn) - 1.0)
                out = _outward(p, j)
                old = p[j].copy()
                for extra in (0.0, 0.25, 0.5, 1.0):
                    p[j] = old + (cut * (1.0 + extra) + extra * grid.resolution) * out
                    if (
                        grid.segment_clear(p[j - 1], p[j])
                        and grid.segment_clear(p[j], p[j + 1])
                        and fits(j)
                        and clear(j)
                    ):
                        break
                else:
                    p[j] = old
                    stop[j] = True
                pushes[j] += 1
            else:
                stop[j] = True
            changed = True
        if not changed:
            break
    # Making a corner a stop frees length for its neighbours and moves nothing, so this last
    # sweep leaves every remaining fillet valid whatever the loop above did.
    for j in range(1, n - 1):
        stop[j] |= not (fits(j) and clear(j))
    return p, stop


@dataclass(frozen=True)
class _Move:
    """Along ``curve`` from rest to rest; headings shifted by ``psi_shift`` (a multiple of
    2π) to continue the unwrapped heading."""

    t0: float
    curve: Curve
    profile: RestToRest
    psi_shift: float

    @property
    def duration(self) -> float:
        return self.profile.duration

    def eval(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        s, u, a = self.profile(t - self.t0)
        xy, psi, k = self.curve.at(s)
        return xy, psi + self.psi_shift, u, k * u, a, k * a


@dataclass(frozen=True)
class _Turn:
    """In place at ``xy`` from heading ``psi0`` by ``dpsi`` [rad]."""

    t0: float
    xy: np.ndarray
    psi0: float
    dpsi: float
    profile: RestToRest

    @property
    def duration(self) -> float:
        return self.profile.duration

    def eval(self, t: np.ndarray) -> tuple[np.ndarray, ...]:
        p, r, a = self.profile(t - self.t0)
        sign = math.copysign(1.0, self.dpsi)
        z = np.zeros_like(p)
        return np.broadcast_to(self.xy, (len(p), 2)), self.psi0 + sign * p, z, sign * r, z, sign * a


class ReferenceTrajectory:
    """Timed reference [x y ψ u v r] along polylines, one per goal (module docstring).

    ``legs``: polylines (n_k × 2) [m], each ending at a goal and starting where the previous
    ended; the vessel comes to rest at each goal, turns in place to the next leg and goes on
    (Roboat II §VI-B). ``speed`` [m/s] cruise surge speed; ``accel`` [m/s²] peak surge acceleration
    of the start and stop ramps; ``yaw_rate`` [rad/s] largest |r| (sets the corner radius speed /
    yaw_rate); ``yaw_accel`` [rad/s²] peak |ṙ| of turns in place; ``grid`` the planning grid, to
    keep corner arcs at its inflation clearance (None: arcs are not checked); ``start_heading`` /
    ``final_heading`` [rad]: turn in place from / to these at the ends (None: start along the path,
    end as it arrives); ``t0`` [s] start time.
    """

    def __init__(
        self,
        legs: list[np.ndarray],
        speed: float = 0.6,
        *,
        accel: float = 0.1,
        yaw_rate: float = 0.25,
        yaw_accel: float = 0.1,
        grid: PlanningGrid | None = None,
        start_heading: float | None = None,
        final_heading: float | None = None,
        t0: float = 0.0,
    ):
        if not legs:
            raise ValueError("ReferenceTrajectory: at least one leg is needed")
        if not (speed > 0 and yaw_rate > 0):
            raise ValueError(f"ReferenceTrajectory: speed {speed} and yaw_rate {yaw_rate} ≤ 0")
        legs = [np.atleast_2d(np.asarray(leg, float)) for leg in legs]
        for k, leg in enumerate(legs):
            if leg.ndim != 2 or leg.shape[1] != 2 or len(leg) == 0:
                raise ValueError(f"ReferenceTrajectory: leg {k} must be n × 2, got {leg.shape}")
            if k > 0 and not np.allclose(leg[0], legs[k - 1][-1]):
                raise ValueError(
                    f"ReferenceTrajectory: leg {k} starts at {leg[0]}, not where leg {k - 1} "
                    f"ends ({legs[k - 1][-1]})"
                )
        self.speed = float(speed)
        self.radius = self.speed / yaw_rate  # [m] corner arc radius
        self.t0 = float(t0)
        phases: list[_Move | _Turn] = []
        polylines: list[np.ndarray] = []
        goal_times = []
        t = self.t0
        xy = legs[0][0]
        psi: float | None = start_heading

        def turn_to(heading: float) -> None:
            nonlocal t, psi
            if psi is None:
                psi = _wrap(heading)
                return
            dpsi = _wrap(heading - psi)
            if abs(dpsi) > 1e-12:
                prof = RestToRest.make(dpsi, yaw_rate, yaw_accel)
                phases.append(_Turn(t, np.array(xy, float), psi, dpsi, prof))
                t += prof.duration
                psi += dpsi

        for leg in legs:
            points, stops = smooth_corners(leg, self.radius, grid)
            polylines.append(points)
            cuts = np.nonzero(stops)[0]
            for a, b in zip(cuts[:-1], cuts[1:], strict=True):
                curve = Curve.fillet(points[a : b + 1], self.radius)
                turn_to(float(curve.psi0[0]))
                shift = psi - float(curve.psi0[0])
                prof = RestToRest.make(curve.length, self.speed, accel)
                phases.append(_Move(t, curve, prof, shift))
                t += prof.duration
                xy = points[b]
                psi = float(curve.at(curve.length)[1][0]) + shift
            goal_times.append(t)
        if final_heading is not None:
            turn_to(final_heading)
        if not phases:  # nowhere to go: hold the start
            hold = 0.0 if psi is None else psi
            phases.append(_Turn(t, np.array(xy, float), hold, 0.0, RestToRest(0, 0, 0, 0)))
        self._phases = phases
        self._starts = np.array([ph.t0 for ph in phases])
        self.t_end = t  # [s] when the final pose is reached
        self.goal_times = np.array(goal_times)  # [s] arrival at each leg's goal
        self.polylines = polylines  # per leg, the corners after pushing outwards
        self.length = float(sum(ph.curve.length for ph in phases if isinstance(ph, _Move)))

    @classmethod
    def from_path(cls, path: np.ndarray, speed: float = 0.6, **kwargs) -> "ReferenceTrajectory":
        """The reference along one path (n × 2) [m]; keywords as for the constructor."""
        return cls([path], speed, **kwargs)

    @classmethod
    def from_goals(
        cls,
        world: World,
        start_xy,
        goals,
        speed: float = 0.6,
        *,
        resolution: float = 0.5,
        inflation: float = DEFAULT_INFLATION,
        grid: PlanningGrid | None = None,
        **kwargs,
    ) -> "ReferenceTrajectory":
        """Plan A* legs start → goals[0] → goals[1] → … in ``world`` (one grid at
        ``resolution`` [m] and ``inflation`` [m] for all, or ``grid`` if given: it must have
        been built with those) and time them; other keywords as for the constructor."""
        if grid is None:
            grid = PlanningGrid.from_world(world, resolution, inflation)
        elif not (
            math.isclose(grid.resolution, resolution) and math.isclose(grid.inflation, inflation)
        ):
            raise ValueError(
                f"from_goals: grid has resolution {grid.resolution} m and inflation "
                f"{grid.inflation} m, but {resolution} m and {inflation} m were asked for"
            )
        goals = np.atleast_2d(np.asarray(goals, float))
        legs = []
        here = np.asarray(start_xy, float)
        for goal in goals:
            legs.append(grid.plan(here, goal))
            here = goal
        return cls(legs, speed, grid=grid, **kwargs)

    @property
    def duration(self) -> float:
        """[s] from ``t0`` until the final pose is reached."""
        return self.t_end - self.t0

    def sample(self, times) -> tuple[np.ndarray, np.ndarray]:
        """``q_ref`` (n × 6: x y ψ u v r) [m, rad, m/s, rad/s] and ``nu_dot_ref`` (n × 3: u̇ v̇ ṙ)
        [m/s², rad/s²] at ``times`` [s] (a scalar gives one row). Before ``t0`` the start pose
        is held, after ``t_end`` the final pose, both at rest."""
        t = np.atleast_1d(np.asarray(times, float)).ravel()
        q = np.zeros((len(t), 6))
        nu_dot = np.zeros((len(t), 3))
        k = np.clip(np.searchsorted(self._starts, t, side="right") - 1, 0, len(self._phases) - 1)
        for j in np.unique(k):
            mask = k == j
            xy, psi, u, r, u_dot, r_dot = self._phases[j].eval(t[mask])
            q[mask, 0:2] = xy
            q[mask, 2] = psi
            q[mask, 3] = u
            q[mask, 5] = r
            nu_dot[mask, 0] = u_dot
            nu_dot[mask, 2] = r_dot
        return q, nu_dot


class HoldPose:
    """A reference that keeps one pose at rest: q_ref = [x y ψ 0 0 0] at every time (station
    keeping while a taxi waits, boards passengers or yields). Same ``sample`` as
    :class:`ReferenceTrajectory`; ``xy`` [m], ``psi`` [rad]."""

    def __init__(self, xy, psi: float):
        self.xy = np.asarray(xy, float).reshape(2)
        self.psi = float(psi)
        self.t_end = -math.inf  # already "arrived"

    def sample(self, times) -> tuple[np.ndarray, np.ndarray]:
        t = np.atleast_1d(np.asarray(times, float)).ravel()
        q = np.zeros((len(t), 6))
        q[:, 0:2] = self.xy
        q[:, 2] = self.psi
        return q, np.zeros((len(t), 3))
