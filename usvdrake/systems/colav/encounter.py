"""COLREG encounter classification (Rules 13-15) and the closest point of approach (plain numpy).

Classification follows the sector definitions of DNV's ``trafficgen`` (trafficgen docs and its
``determine_colreg``; the standard encounter set of Sæter et al. 2023 is generated with them), in
our own formulation. Two relative bearings describe the geometry:

- β: the bearing of the target seen from the own ship, relative to the own heading, clockwise,
  in [0°, 360°) (β = 90° is dead abeam to starboard);
- α: the bearing of the own ship seen from the target, relative to the target's heading,
  clockwise, in [−180°, 180°).

With ``encounter_settings.json``'s angles (θ15 = [112.5°, 247.5°] is "22.5° abaft the beam" on
either side, COLREGs Rule 13(b); θ13crit = 67.5°, θ14crit = 5°, θ15crit = 5°), checked in this
order:

1. overtaking stand-on (Rule 13, the target overtakes us): θ15[0] < β < θ15[1] and
   |α| ≤ θ13crit;
2. overtaking give-way (Rule 13, we overtake): θ15[0] < α mod 360 < θ15[1] and |β| ≤ θ13crit
   (β taken in (−180°, 180°]);
3. head-on (Rule 14, "reciprocal or nearly reciprocal courses"): |β| ≤ θ14crit and
   |α| ≤ θ14crit;
4. crossing give-way (Rule 15, target on our starboard side): 0 < β < θ15[0] and
   −θ15[0] < α ≤ θ15crit;
5. crossing stand-on (Rule 15/17, target on our port side): 0 < α mod 360 < θ15[0] and
   −θ15[0] < β ≤ θ15crit (β in (−180°, 180°]);
6. otherwise no risk of collision by geometry ("safe").

trafficgen classifies geometry only; :func:`classify` also calls an encounter "safe" when the
range is opening (no risk of collision, COLREGs Rule 7), unless ``require_closing=False``.

Angles in, out of our world frame: ψ in radians counter-clockwise from +x (east); positions in
local ENU metres.
"""

from __future__ import annotations

from enum import Enum

import numpy as np

from usvdrake.systems.colav.situation import EncounterSettings

_TOL = 1e-3  # [deg] the tolerance trafficgen allows on its "≤ criterion" comparisons


class EncounterType(str, Enum):
    """A COLREG situation as seen from the own ship; values are trafficgen's title codes."""

    HEAD_ON = "HO"
    CROSSING_GIVE_WAY = "CR-GW"
    CROSSING_STAND_ON = "CR-SO"
    OVERTAKING_GIVE_WAY = "OT-GW"
    OVERTAKING_STAND_ON = "OT-SO"
    SAFE = "safe"

    @property
    def give_way(self) -> bool:
        """The own ship must keep out of the way (head-on: both ships alter, Rule 14)."""
        return self in (
            EncounterType.HEAD_ON,
            EncounterType.CROSSING_GIVE_WAY,
            EncounterType.OVERTAKING_GIVE_WAY,
        )

    @property
    def stand_on(self) -> bool:
        """The own ship must keep course and speed (Rule 17(a)(i))."""
        return self in (EncounterType.CROSSING_STAND_ON, EncounterType.OVERTAKING_STAND_ON)

    @property
    def role(self) -> str:
        """ "give-way", "stand-on" or "none"."""
        return "give-way" if self.give_way else "stand-on" if self.stand_on else "none"


def _compass_deg(psi):
    """Our ψ [rad] → compass angle [deg, clockwise from north] (not wrapped)."""
    return 90.0 - np.degrees(psi)


def relative_bearings(own_pos, own_psi, target_pos, target_psi) -> tuple[float, float]:
    """(β, α) [deg]: β the target's bearing relative to the own bow in [0, 360), α the own ship's
    bearing relative to the target's bow in [−180, 180) (module docstring)."""
    dx, dy = np.asarray(target_pos, float)[:2] - np.asarray(own_pos, float)[:2]
    bearing = np.degrees(np.arctan2(dx, dy))  # true bearing own → target, clockwise from north
    beta = np.mod(bearing - _compass_deg(own_psi), 360.0)
    alpha = np.mod(bearing + 180.0 - _compass_deg(target_psi) + 180.0, 360.0) - 180.0
    return float(beta), float(alpha)


def classify_bearings(beta: float, alpha: float, settings: EncounterSettings) -> EncounterType:
    """The COLREG situation from the relative bearings β, α [deg] (module docstring's sectors)."""
    t13, t14, t15c = settings.theta13_criteria, settings.theta14_criteria, settings.theta15_criteria
    lo, hi = settings.theta15
    beta = float(np.mod(beta, 360.0))
    alpha = float(np.mod(alpha + 180.0, 360.0) - 180.0)
    beta_s = beta if beta <= 180.0 else beta - 360.0  # (−180, 180]
    alpha_360 = alpha % 360.0
    if lo < beta < hi and abs(alpha) <= t13 + _TOL:
        return EncounterType.OVERTAKING_STAND_ON
    if lo < alpha_360 < hi and abs(beta_s) <= t13 + _TOL:
        return EncounterType.OVERTAKING_GIVE_WAY
    if abs(beta_s) <= t14 + _TOL and abs(alpha) <= t14 + _TOL:
        return EncounterType.HEAD_ON
    if 0.0 < beta < lo and -lo < alpha <= t15c + _TOL:
        return EncounterType.CROSSING_GIVE_WAY
    if 0.0 < alpha_360 < lo and -lo < beta_s <= t15c + _TOL:
        return EncounterType.CROSSING_STAND_ON
    return EncounterType.SAFE


def velocity(psi, speed) -> np.ndarray:
    """Velocity vector(s) [m/s] in the world frame from ψ [rad] and speed [m/s]."""
    psi, speed = np.asarray(psi, float), np.asarray(speed, float)
    return np.stack([speed * np.cos(psi), speed * np.sin(psi)], axis=-1)


def classify(
    own_pos,
    own_psi: float,
    own_speed: float,
    target_pos,
    target_psi: float,
    target_speed: float,
    settings: EncounterSettings,
    require_closing: bool = True,
) -> EncounterType:
    """The COLREG situation of one target for the own ship (ψ = course over ground when known).

    Geometry as trafficgen (module docstring); with ``require_closing`` an opening range (the
    relative velocity points away from the target) is "safe"."""
    if require_closing:
        dp = np.asarray(target_pos, float)[:2] - np.asarray(own_pos, float)[:2]
        dv = velocity(target_psi, target_speed) - velocity(own_psi, own_speed)
        if float(dp @ dv) >= 0.0:
            return EncounterType.SAFE
    beta, alpha = relative_bearings(own_pos, own_psi, target_pos, target_psi)
    return classify_bearings(beta, alpha, settings)


# ------------------------------------------------------------------- closest point of approach


def cpa(p_own, v_own, p_tgt, v_tgt):
    """Closest point of approach for constant velocities: (DCPA [m], TCPA [s]).

    TCPA = −(Δp·Δv)/|Δv|² with Δp = p_tgt − p_own, Δv = v_tgt − v_own; DCPA = |Δp + TCPA·Δv|.
    TCPA is negative when the closest approach is past (DCPA is then the distance at that past
    time); with no relative motion TCPA = 0 and DCPA the present range. Inputs broadcast over
    leading axes (last axis x, y); scalars out for single vectors."""
    dp = np.asarray(p_tgt, float)[..., :2] - np.asarray(p_own, float)[..., :2]
    dv = np.asarray(v_tgt, float)[..., :2] - np.asarray(v_own, float)[..., :2]
    dv2 = np.sum(dv * dv, axis=-1)
    moving = dv2 > 1e-18
    tcpa = np.where(moving, -np.sum(dp * dv, axis=-1) / np.where(moving, dv2, 1.0), 0.0)
    dcpa = np.linalg.norm(dp + tcpa[..., None] * dv, axis=-1)
    if np.ndim(dcpa) == 0:
        return float(dcpa), float(tcpa)
    return dcpa, tcpa


def track_cpa(t, p_own, p_tgt) -> tuple[float, float]:
    """Minimum distance [m] and its time [s] between two tracks sampled at the same times ``t``
    (positions (n, 2)), exact for straight-line motion between samples (the closed form of
    :func:`cpa` on each interval, clamped to it)."""
    t = np.asarray(t, float)
    d = np.asarray(p_tgt, float)[:, :2] - np.asarray(p_own, float)[:, :2]
    r = np.linalg.norm(d, axis=1)
    k = int(np.argmin(r))
    best, t_best = float(r[k]), float(t[k])
    if len(t) < 2:
        return best, t_best
    dt = np.diff(t)
    dd = np.diff(d, axis=0)  # relative displacement over each interval
    a = np.sum(dd * dd, axis=1)
    s = np.where(a > 1e-18, -np.sum(d[:-1] * dd, axis=1) / np.where(a > 1e-18, a, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)
    dist = np.linalg.norm(d[:-1] + s[:, None] * dd, axis=1)
    j = int(np.argmin(dist))
    if dist[j] < best:
        best, t_best = float(dist[j]), float(t[j] + s[j] * dt[j])
    return best, t_best


def distances(p_own, p_tgt) -> np.ndarray:
    """Range between two tracks sampled at the same times [m]."""
    return np.linalg.norm(np.asarray(p_tgt, float)[:, :2] - np.asarray(p_own, float)[:, :2], axis=1)
