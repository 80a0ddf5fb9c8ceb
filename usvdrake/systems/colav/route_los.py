"""Line-of-sight course along a ship's route (plain numpy): the own ship's nominal course.

Lookahead-based LOS (Fossen 2021, straight-line path following): χ = χ_path − atan(e / Δ)
with e the cross-track error (positive left of the leg) and Δ the lookahead distance. A leg is
done when the along-track position comes within `switch_radius` of its end. On the last leg,
once the end is nearer than Δ (or less than Δ ahead along the leg), the course points at the
end itself (a collision-avoidance
manoeuvre can leave the ship far abeam of the route near its end, and LOS alone would then sail
past); the route is done within `arrival_radius` of its end or once past it along the last leg by
more than that.
"""

import numpy as np


def leg_frame(waypoints: np.ndarray, index: int):
    """(start, unit direction, length) of leg index → index + 1."""
    a, b = waypoints[index], waypoints[index + 1]
    seg = b - a
    length = float(np.linalg.norm(seg))
    return a, seg / max(length, 1e-9), length


def advance_leg(waypoints: np.ndarray, index: int, position, switch_radius: float) -> int:
    """The active leg after `position`: the index grows while the leg's end is within
    `switch_radius` along the track; the last leg (len(waypoints) − 2) stays active."""
    p = np.asarray(position, float)
    while index < len(waypoints) - 2:
        a, e, length = leg_frame(waypoints, index)
        if (p - a) @ e <= length - switch_radius:
            break
        index += 1
    return index


def arrived(waypoints: np.ndarray, position, arrival_radius: float) -> bool:
    """Within `arrival_radius` of the route's end, or past it along the last leg by more than
    the radius (a ship that misses the end still stops, rather than circling it)."""
    p = np.asarray(position, float)
    a, e, length = leg_frame(waypoints, len(waypoints) - 2)
    past = (p - a) @ e >= length + arrival_radius
    return bool(np.hypot(*(p - waypoints[-1])) <= arrival_radius or past)


def los_course(waypoints: np.ndarray, index: int, position, lookahead: float) -> float:
    """The course [rad, counter-clockwise from east] on leg `index`: LOS, or straight at the
    route's end on the last leg once the end is within `lookahead` (straight-line or along the
    leg)."""
    p = np.asarray(position, float)
    index = min(index, len(waypoints) - 2)
    to_end = waypoints[-1] - p
    a, e, length = leg_frame(waypoints, index)
    rel = p - a
    near_end = np.hypot(*to_end) < lookahead or rel @ e > length - lookahead
    if index == len(waypoints) - 2 and near_end:  # the last stretch: straight at the end
        return float(np.arctan2(to_end[1], to_end[0]))
    cross = e[0] * rel[1] - e[1] * rel[0]  # > 0: left of the leg, so steer right
    return float(np.arctan2(e[1], e[0]) - np.arctan2(cross, lookahead))
