"""AIS-like position reports of a target ship, as a class A transponder would send them.

Reporting interval from the target's speed over ground and whether it is changing course, as
Table 1 of ITU-R M.1371 ("Class A shipborne mobile equipment reporting intervals") gives it
(transcribed in public documents; the ITU page itself we only saw as its table of contents):

    at anchor or moored, ≤ 3 kn           3 min       0-14 kn            10 s
    0-14 kn and changing course          3⅓ s        14-23 kn            6 s
    14-23 kn and changing course           2 s        > 23 kn (any)       2 s

A report carries position (east/north in the local frame), course over ground and speed over
ground, each with Gaussian noise; reports can be lost with a given probability, and the interval
gets a small jitter (SOTDMA slots are not exact). Angles follow usvdrake's frame: COG is measured
counter-clockwise from east [rad] (a real AIS message sends it clockwise from north in degrees;
`cog_from_true_course` converts).

Noise draws are reproducible: report k of target id uses numpy.random.default_rng([seed, 601, id,
k]) (stream 601 in usvdrake.random_streams' numbering).
"""

from dataclasses import dataclass

import numpy as np

from usvdrake.angles import wrap_angle

KNOT = 1852.0 / 3600.0  # [m/s]
AIS_STREAM = 601


def cog_from_true_course(course_deg):
    """True course (clockwise from north, degrees) → our COG (counter-clockwise from east, rad)."""
    return wrap_angle(np.radians(90.0 - np.asarray(course_deg, dtype=float)))


def class_a_interval(sog_mps: float, changing_course: bool = False, moored: bool = False) -> float:
    """Nominal class A reporting interval [s] of ITU-R M.1371 Table 1."""
    kn = sog_mps / KNOT
    if moored and kn <= 3.0:
        return 180.0
    if kn <= 14.0:
        return 10.0 / 3.0 if changing_course else 10.0
    if kn <= 23.0:
        return 2.0 if changing_course else 6.0
    return 2.0


@dataclass(frozen=True)
class AisReport:
    """One received position report (local frame, SI units)."""

    target_id: int
    t_s: float
    east_m: float
    north_m: float
    cog_rad: float  # course over ground, counter-clockwise from east
    sog_mps: float

    @property
    def velocity(self) -> np.ndarray:
        return self.sog_mps * np.array([np.cos(self.cog_rad), np.sin(self.cog_rad)])


@dataclass(frozen=True)
class AisNoise:
    """Report noise (1σ) and loss. Defaults: GNSS-grade position, AIS resolution-grade COG/SOG."""

    position_m: float = 10.0
    cog_rad: float = np.radians(1.0)
    sog_mps: float = 0.1 * KNOT
    jitter_s: float = 0.2
    loss_probability: float = 0.0
    turn_rate_threshold: float = np.radians(5.0) / 60.0  # "changing course": ≥ 5°/min


class AisTransmitter:
    """The AIS transponder of one target: call `report(t, truth)` every simulation step; it
    returns an AisReport when one is due (and not lost), else None."""

    def __init__(self, target_id: int, seed: int = 0, noise: AisNoise | None = None, t0=0.0):
        self.target_id = int(target_id)
        self.seed = int(seed)
        self.noise = noise or AisNoise()
        self._k = 0
        # First report at a random phase of the interval, as transponders are not synchronised.
        self.next_t = float(t0) + 10.0 * self._rng(-1).uniform()

    def _rng(self, k: int) -> np.random.Generator:
        return np.random.default_rng([self.seed, AIS_STREAM, self.target_id, k + 1])

    def report(
        self, t: float, east: float, north: float, vel_east: float, vel_north: float, turn_rate=0.0
    ) -> AisReport | None:
        """The report due at time t [s] from the true position [m], velocity [m/s] and rate of
        turn [rad/s] of the target, or None."""
        if t + 1e-9 < self.next_t:
            return None
        nz = self.noise
        rng = self._rng(self._k)
        self._k += 1
        sog = float(np.hypot(vel_east, vel_north))
        turning = abs(turn_rate) >= nz.turn_rate_threshold
        interval = class_a_interval(sog, turning)
        self.next_t = t + max(0.5, interval + nz.jitter_s * rng.standard_normal())
        w = rng.standard_normal(4)
        lost = rng.uniform() < nz.loss_probability
        if lost:
            return None
        cog = float(np.arctan2(vel_north, vel_east)) if sog > 1e-6 else 0.0
        return AisReport(
            target_id=self.target_id,
            t_s=float(t),
            east_m=float(east + nz.position_m * w[0]),
            north_m=float(north + nz.position_m * w[1]),
            cog_rad=float(wrap_angle(cog + nz.cog_rad * w[2])),
            sog_mps=float(max(0.0, sog + nz.sog_mps * w[3])),
        )
