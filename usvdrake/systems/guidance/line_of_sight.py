"""Lookahead-based line-of-sight path following over a waypoint list (Fossen 2011 §10.3.2).

For the active segment p_k → p_{k+1} with path angle α_k, the along-track and cross-track errors
    s = (x − x_k) cos α_k + (y − y_k) sin α_k,    e = −(x − x_k) sin α_k + (y − y_k) cos α_k
give the desired course ψ_d = α_k + atan(−e / Δ), Δ the lookahead distance [m]. The next segment
is taken when the vessel is within the acceptance radius of p_{k+1} or has passed it along
track. The speed reference ramps down linearly within ``slowdown_radius`` of the final waypoint.
"""

from dataclasses import dataclass, field

import numpy as np

from usvdrake.angles import wrap_angle


@dataclass
class MissionConfig:
    waypoints: list[list[float]] = field(default_factory=list)  # [[x, y], ...] [m], world ENU
    speed: float = 0.0  # [m/s] cruise speed; 0 takes the vessel's cruise_speed
    acceptance_radius: float = 2.0  # [m] a waypoint counts as reached inside this circle
    slowdown_radius: float = 6.0  # [m] speed ramps down to zero over this distance to the goal


@dataclass
class ControlConfig:
    rate_hz: float = 10.0  # [Hz] guidance + controller rate, zero-order hold (Roboat II §VI: 10 Hz)
    lookahead: float = 4.0  # [m] line-of-sight look-ahead distance Δ (Fossen 2011 §10.3.2)
    heading_natural_frequency: float = 0.8  # [rad/s] closed-loop heading bandwidth ω_ψ
    heading_damping: float = 1.0  # [-] closed-loop heading damping ζ_ψ
    surge_bandwidth: float = 0.5  # [1/s] surge speed loop bandwidth
    sway_bandwidth: float = 0.5  # [1/s] sway damping loop bandwidth (holonomic vessels)


@dataclass
class LosReference:
    heading: float  # ψ_d [rad]
    speed: float  # u_d [m/s]
    cross_track: float  # e [m]
    distance_to_goal: float  # [m] straight-line distance to the final waypoint
    index: int  # active segment's target waypoint (k + 1)
    complete: bool  # the final waypoint has been reached


def advance_index(
    waypoints: np.ndarray, index: int, position: np.ndarray, acceptance_radius: float
) -> int:
    """Next target waypoint index after reaching / passing the current one(s)."""
    n = len(waypoints)
    while index < n - 1:
        target = waypoints[index]
        prev = waypoints[index - 1] if index > 0 else None
        reached = np.linalg.norm(position - target) <= acceptance_radius
        passed = False
        if prev is not None:
            seg = target - prev
            length = np.linalg.norm(seg)
            if length > 0:
                passed = (position - prev) @ seg / length >= length
        if reached or passed:
            index += 1
        else:
            break
    return index


def los_reference(
    waypoints: np.ndarray,
    index: int,
    position: np.ndarray,
    start: np.ndarray,
    cruise_speed: float,
    lookahead: float,
    acceptance_radius: float,
    slowdown_radius: float,
) -> LosReference:
    """The LOS reference for target waypoint ``index``; ``start`` is where the path begins
    (the vessel's initial position, used as p_{k} for the first segment)."""
    target = waypoints[index]
    prev = waypoints[index - 1] if index > 0 else start
    seg = target - prev
    if np.linalg.norm(seg) < 1e-9:
        seg = target - position
    alpha = np.arctan2(seg[1], seg[0])
    rel = position - prev
    e = -rel[0] * np.sin(alpha) + rel[1] * np.cos(alpha)
    heading = wrap_angle(alpha + np.arctan2(-e, lookahead))
    goal = waypoints[-1]
    d_goal = float(np.linalg.norm(goal - position))
    last = index == len(waypoints) - 1
    complete = last and d_goal <= acceptance_radius
    # Slow down only on the final leg: a closed route's goal may be its start.
    speed = cruise_speed * min(1.0, d_goal / slowdown_radius) if last else cruise_speed
    speed = 0.0 if complete else speed
    if last and d_goal < lookahead:
        heading = float(np.arctan2(goal[1] - position[1], goal[0] - position[0]))
    return LosReference(float(heading), float(speed), float(e), d_goal, index, bool(complete))
