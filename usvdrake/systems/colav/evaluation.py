"""Evaluation of a finished encounter from sampled tracks (plain numpy): per target the COLREG
situation at its start, CPA, collision and a compliance verdict with reasons; per situation
arrival and path length; the CSV / JSON outputs of ``usvdrake encounter(s)``.

What the verdict checks (COLREGs Rules 8, 13-17, as operationalised for post-mission track
evaluation by Woerner et al. 2019 and, for the SB-MPC's own COLREG costs, Johansen et al.
2016 — the structure is theirs, the numbers in :class:`ColregParams` are our own defaults, not
taken from them):

- the encounter starts at the first sample where a risk of collision exists (Rule 7: the
  constant-velocity prediction gives 0 ≤ TCPA ≤ ``tcpa_horizon_s`` and DCPA < ``dcpa_risk_m``,
  or the range is below the safety distance); it is classified there (``encounter.classify``)
  and lasts until the sampled CPA;
- give-way (Rules 14, 15, 16; head-on counts here as both ships must alter): when action is
  needed (predicted DCPA at the start < safety distance), it must be *readily apparent* (Rule
  8(b): a course change ≥ ``min_course_change_deg`` or a speed reduction ≥
  ``min_speed_reduction``) and *early* (Rule 16: begun, where it last left the keep-course /
  keep-speed tolerances, while the range is ≥ ``early_range_m`` or ≥ ``early_time_s`` before the
  CPA); in head-on and crossing give-way no port turn beyond
  ``port_tolerance_deg`` (Rule 14(a) alter to starboard; Rule 15 and common practice: pass
  astern); in crossing give-way never cross ahead of the target's bow (Rule 15);
- stand-on (Rule 17): keep course and speed (within ``keep_course_tol_deg`` /
  ``keep_speed_tol``) until the give-way ship is clearly not acting — the range falls below
  ``standon_release_m`` or the predicted TCPA below ``standon_release_tcpa_s`` with DCPA below
  the safety distance — then any action, except (crossing, Rule 17(c)) a port turn for a ship on
  the own port side. Deviations while the own ship is giving way to another target, or acting
  as a released stand-on ship towards another (Rule 17(a)(ii), from that target's release to
  its CPA), are excused (multi-ship encounters, where one ship's duties can conflict with
  another's: Rule 2(b));
- a collision (hull outlines overlap, :mod:`usvdrake.systems.colav.hull`) is never compliant.

Course changes are measured against the planned route's course (nearest leg) when a route is
given, else against the heading at the encounter's start; speed changes against the speed at
the start. Starboard = clockwise = decreasing ψ.
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from usvdrake.angles import wrap_angle
from usvdrake.jsonable import jsonable
from usvdrake.systems.colav.encounter import EncounterType, classify, cpa, track_cpa, velocity
from usvdrake.systems.colav.hull import Hull, first_collision
from usvdrake.systems.colav.situation import (
    NAUTICAL_MILE,
    EncounterSettings,
    TrafficSituation,
    mps_to_knots,
    psi_to_heading_deg_true,
)


@dataclass(frozen=True)
class ShipTrack:
    """A sampled track: time [s], position [m], heading ψ [rad], speed over ground [m/s]."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    psi: np.ndarray
    speed: np.ndarray

    def __post_init__(self):
        arrays = [np.atleast_1d(np.asarray(v, float)) for v in (self.t, self.x, self.y)]
        arrays += [np.atleast_1d(np.asarray(v, float)) for v in (self.psi, self.speed)]
        n = len(arrays[0])
        if n == 0 or any(len(a) != n for a in arrays):
            raise ValueError("ShipTrack: t, x, y, psi, speed must be non-empty and of equal length")
        for name, arr in zip(("t", "x", "y", "psi", "speed"), arrays, strict=True):
            object.__setattr__(self, name, arr)

    @property
    def xy(self) -> np.ndarray:
        return np.column_stack([self.x, self.y])

    def resample(self, t) -> ShipTrack:
        """Linear interpolation at times ``t`` (ψ unwrapped first; held outside the samples)."""
        t = np.atleast_1d(np.asarray(t, float))
        if len(self.t) == 1:
            return ShipTrack(
                t, *(np.full(len(t), v[0]) for v in (self.x, self.y, self.psi, self.speed))
            )
        psi = wrap_angle(np.interp(t, self.t, np.unwrap(self.psi)))
        return ShipTrack(
            t,
            np.interp(t, self.t, self.x),
            np.interp(t, self.t, self.y),
            psi,
            np.interp(t, self.t, self.speed),
        )

    def path_length(self) -> float:
        return float(np.sum(np.hypot(np.diff(self.x), np.diff(self.y))))

    @classmethod
    def from_ship(cls, ship, t) -> ShipTrack:
        """The track of a situation ship following its waypoints at its leg speeds."""
        x, y, psi, v = ship.state_at(t)
        return cls(np.atleast_1d(np.asarray(t, float)), x, y, psi, v)


@dataclass(frozen=True)
class ColregParams:
    """Thresholds of the evaluation (defaults: ship scale, issue 37's 0.5 nmi safety distance).
    Our own choices, not values taken from the literature cited in the module docstring."""

    safety_distance_m: float = 0.5 * NAUTICAL_MILE
    tcpa_horizon_s: float = 1800.0  # risk of collision looked for this far ahead
    dcpa_risk_m: float = 1.0 * NAUTICAL_MILE
    min_course_change_deg: float = 20.0  # readily apparent course change
    min_speed_reduction: float = 0.5  # readily apparent speed reduction (fraction)
    early_range_m: float = 2.0 * NAUTICAL_MILE
    early_time_s: float = 300.0
    port_tolerance_deg: float = 10.0
    keep_course_tol_deg: float = 10.0
    keep_speed_tol: float = 0.2
    standon_release_m: float = 1.0 * NAUTICAL_MILE
    standon_release_tcpa_s: float = 600.0
    arrival_radius_m: float = 200.0

    def scaled(self, k: float) -> ColregParams:
        """All distances × ``k`` (times unchanged): e.g. the canal-scale set."""
        d = asdict(self)
        for key in d:
            if key.endswith("_m"):
                d[key] *= k
        return ColregParams(**d)


@dataclass
class TargetEvaluation:
    """The evaluation of one target encounter (JSON-friendly through :meth:`to_dict`)."""

    target_id: int
    encounter: str  # EncounterType value ("HO", "CR-GW", ..., "safe")
    role: str  # "give-way", "stand-on", "none"
    t_start_s: float | None
    range_at_start_m: float | None
    dcpa_predicted_m: float | None
    cpa_m: float
    t_cpa_s: float
    collision: bool
    t_collision_s: float | None
    action_required: bool
    t_action_s: float | None
    range_at_action_m: float | None
    max_starboard_deg: float
    max_port_deg: float
    max_speed_reduction: float
    crossed_ahead: bool
    compliant: bool
    reasons: list[str] = field(default_factory=list)
    t_release_s: float | None = None  # stand-on: when the give-way ship was clearly not acting
    t_apparent_s: float | None = None  # give-way: when the action became readily apparent

    def to_dict(self) -> dict:
        return jsonable(asdict(self))


@dataclass
class SituationEvaluation:
    """The evaluation of one situation: its targets and the own ship's voyage."""

    situation: str
    title: str
    targets: list[TargetEvaluation]
    collisions: int
    min_cpa_m: float
    encounters: int  # targets with a COLREG situation (not "safe")
    compliant: int  # of those, judged compliant
    arrived: bool
    final_distance_m: float
    path_length_m: float
    planned_length_m: float
    path_ratio: float
    duration_s: float

    def to_dict(self) -> dict:
        d = asdict(self)
        d["targets"] = [t.to_dict() for t in self.targets]
        return jsonable(d)


# ------------------------------------------------------------------------------- helpers


def route_course(route_xy, x, y) -> np.ndarray:
    """Course ψ [rad] of the planned route's leg nearest to each position (x, y)."""
    route = np.asarray(route_xy, float)
    seg = np.diff(route, axis=0)
    seg_len2 = np.maximum(np.sum(seg * seg, axis=1), 1e-12)
    p = np.column_stack([np.atleast_1d(x), np.atleast_1d(y)])
    rel = p[:, None, :] - route[None, :-1, :]
    s = np.clip(np.sum(rel * seg[None], axis=2) / seg_len2[None], 0.0, 1.0)
    dist = np.linalg.norm(rel - s[..., None] * seg[None], axis=2)
    k = np.argmin(dist, axis=1)
    return np.arctan2(seg[k, 1], seg[k, 0])


def _in_intervals(t, intervals) -> np.ndarray:
    mask = np.zeros(len(t), bool)
    for t0, t1 in intervals:
        mask |= (t >= t0) & (t <= t1)
    return mask


def _encounter_start(own: ShipTrack, tgt: ShipTrack, p: ColregParams):
    """Index of the first sample with a risk of collision (module docstring), or None."""
    dp = tgt.xy - own.xy
    rng = np.linalg.norm(dp, axis=1)
    dcpa, tcpa = cpa(own.xy, velocity(own.psi, own.speed), tgt.xy, velocity(tgt.psi, tgt.speed))
    risk = ((tcpa >= 0) & (tcpa <= p.tcpa_horizon_s) & (dcpa < p.dcpa_risk_m)) | (
        rng < p.safety_distance_m
    )
    idx = np.flatnonzero(risk)
    return (int(idx[0]), rng, dcpa, tcpa) if len(idx) else (None, rng, dcpa, tcpa)


def _crossed_ahead(own: ShipTrack, tgt: ShipTrack, window) -> bool:
    """Whether the own ship crossed the target's heading line ahead of its bow in ``window``."""
    dp = own.xy - tgt.xy
    c, s = np.cos(tgt.psi), np.sin(tgt.psi)
    along = c * dp[:, 0] + s * dp[:, 1]
    cross = -s * dp[:, 0] + c * dp[:, 1]
    idx = np.flatnonzero(window[:-1] & window[1:])
    for i in idx:
        if cross[i] == 0.0 or cross[i] * cross[i + 1] < 0.0:
            u = cross[i] / (cross[i] - cross[i + 1]) if cross[i] != cross[i + 1] else 0.0
            if along[i] + u * (along[i + 1] - along[i]) > 0.0:
                return True
    return False


# ---------------------------------------------------------------------------- per target


def evaluate_target(
    own: ShipTrack,
    tgt: ShipTrack,
    own_hull: Hull,
    tgt_hull: Hull,
    settings: EncounterSettings,
    params: ColregParams = ColregParams(),
    route_xy=None,
    target_id: int = 0,
    excused=(),
) -> TargetEvaluation:
    """Evaluate one target encounter from tracks sampled at the same times (the target's is
    resampled onto the own ship's times if they differ). ``route_xy`` is the own planned route
    ((n, 2) waypoints), ``excused`` (t0, t1) intervals in which the own ship gives way to other
    targets (stand-on deviations there are not counted)."""
    if len(tgt.t) != len(own.t) or not np.allclose(tgt.t, own.t):
        tgt = tgt.resample(own.t)
    t = own.t
    cpa_m, t_cpa = track_cpa(t, own.xy, tgt.xy)
    t_col = first_collision(t, (own.x, own.y, own.psi), own_hull, (tgt.x, tgt.y, tgt.psi), tgt_hull)
    collision = t_col is not None
    k0, rng, dcpa, _ = _encounter_start(own, tgt, params)
    blank = dict(
        target_id=int(target_id),
        cpa_m=cpa_m,
        t_cpa_s=t_cpa,
        collision=collision,
        t_collision_s=t_col,
        t_action_s=None,
        range_at_action_m=None,
        max_starboard_deg=0.0,
        max_port_deg=0.0,
        max_speed_reduction=0.0,
        crossed_ahead=False,
    )
    if k0 is None:
        # No risk of collision was ever found: no COLREG duty, only a collision can fail it.
        reasons = [f"collision at t = {t_col:.1f} s (hull outlines overlap)"] if collision else []
        return TargetEvaluation(
            encounter=EncounterType.SAFE.value,
            role="none",
            t_start_s=None,
            range_at_start_m=None,
            dcpa_predicted_m=None,
            action_required=False,
            compliant=not collision,
            reasons=reasons,
            **blank,
        )
    etype = classify(
        own.xy[k0], own.psi[k0], own.speed[k0], tgt.xy[k0], tgt.psi[k0], tgt.speed[k0],
        settings, require_closing=False,
    )  # fmt: skip
    # The window of the encounter: from its start to the CPA (at least one sample).
    window = (t >= t[k0]) & (t <= max(t_cpa, t[k0]))
    psi_ref = route_course(route_xy, own.x, own.y) if route_xy is not None else own.psi[k0]
    dpsi = np.degrees(wrap_angle(own.psi - psi_ref))  # > 0: turned to port
    speed_ref = max(float(own.speed[k0]), 1e-6)
    reduction = 1.0 - own.speed / speed_ref
    starboard = float(max(0.0, np.max(-dpsi[window])))
    port = float(max(0.0, np.max(dpsi[window])))
    red = float(max(0.0, np.max(reduction[window])))
    result = TargetEvaluation(
        encounter=etype.value,
        role=etype.role,
        t_start_s=float(t[k0]),
        range_at_start_m=float(rng[k0]),
        dcpa_predicted_m=float(dcpa[k0]),
        action_required=bool(dcpa[k0] < params.safety_distance_m),
        compliant=True,
        reasons=[],
        **{**blank, "max_starboard_deg": starboard, "max_port_deg": port},
    )
    result.max_speed_reduction = red
    if etype.give_way:
        _judge_give_way(result, etype, own, tgt, window, dpsi, reduction, rng, t_cpa, params)
    elif etype.stand_on:
        _judge_stand_on(result, etype, own, tgt, window, dpsi, reduction, rng, params, excused)
    if collision:
        result.reasons.append(f"collision at t = {t_col:.1f} s (hull outlines overlap)")
    result.compliant = not result.reasons
    return result


def _judge_give_way(res, etype, own, tgt, window, dpsi, reduction, rng, t_cpa, p):
    t = own.t
    # Readily apparent: a turn to starboard (either side when overtaking, Rule 13) or a slow-down.
    turn = np.abs(dpsi) if etype is EncounterType.OVERTAKING_GIVE_WAY else -dpsi
    apparent = window & (
        (turn >= p.min_course_change_deg) | (reduction >= p.min_speed_reduction - 1e-9)
    )
    if np.any(apparent):
        k = int(np.argmax(apparent))
        res.t_apparent_s = float(t[k])
        # dated from its onset (the unbroken deviation beyond the keep tolerances that became
        # apparent at k): a 122 m ship ordered to half speed nears 50 % only asymptotically
        begun = window & ((turn > p.keep_course_tol_deg) | (reduction > p.keep_speed_tol))
        while k > 0 and begun[k - 1]:
            k -= 1
        res.t_action_s, res.range_at_action_m = float(t[k]), float(rng[k])
    if res.action_required:
        if res.t_action_s is None:
            res.reasons.append(
                f"give-way: no readily apparent action (starboard {res.max_starboard_deg:.0f}°, "
                f"speed reduction {100 * res.max_speed_reduction:.0f} %; Rules 8, 16)"
            )
        elif res.range_at_action_m < p.early_range_m and t_cpa - res.t_action_s < p.early_time_s:
            res.reasons.append(
                f"give-way: action late (range {res.range_at_action_m:.0f} m, "
                f"{t_cpa - res.t_action_s:.0f} s before CPA; Rule 16)"
            )
    if etype in (EncounterType.HEAD_ON, EncounterType.CROSSING_GIVE_WAY):
        if res.max_port_deg > p.port_tolerance_deg:
            rule = "Rule 14" if etype is EncounterType.HEAD_ON else "Rule 15"
            res.reasons.append(f"altered course to port by {res.max_port_deg:.0f}° ({rule})")
    if etype is EncounterType.CROSSING_GIVE_WAY:
        res.crossed_ahead = _crossed_ahead(own, tgt, window)
        if res.crossed_ahead:
            res.reasons.append("crossed ahead of the stand-on ship's bow (Rule 15)")


def _judge_stand_on(res, etype, own, tgt, window, dpsi, reduction, rng, p, excused):
    t = own.t
    dcpa, tcpa = cpa(own.xy, velocity(own.psi, own.speed), tgt.xy, velocity(tgt.psi, tgt.speed))
    release = (rng < p.standon_release_m) | (
        (tcpa >= 0) & (tcpa <= p.standon_release_tcpa_s) & (dcpa < p.safety_distance_m)
    )
    # The first release after the start; the keeping phase is the window before it.
    k_start = int(np.argmax(window))
    after = np.flatnonzero(release[k_start:])
    k_rel = k_start + int(after[0]) if len(after) else len(t)
    res.t_release_s = float(t[k_rel]) if k_rel < len(t) else None
    keep = window & (np.arange(len(t)) < k_rel) & ~_in_intervals(t, excused)
    if np.any(keep):
        course_dev = float(np.max(np.abs(dpsi[keep])))
        speed_dev = float(np.max(np.abs(reduction[keep])))
        if course_dev > p.keep_course_tol_deg or speed_dev > p.keep_speed_tol:
            off = (np.abs(dpsi) > p.keep_course_tol_deg) | (np.abs(reduction) > p.keep_speed_tol)
            k = int(np.flatnonzero(keep & off)[0])
            res.t_action_s, res.range_at_action_m = float(t[k]), float(rng[k])
            res.reasons.append(
                f"stand-on: did not keep course and speed before the give-way ship was clearly "
                f"not acting (course {course_dev:.0f}°, speed {100 * speed_dev:.0f} % at range "
                f"{rng[k]:.0f} m; Rule 17(a)(i))"
            )
    if etype is EncounterType.CROSSING_STAND_ON:
        # Port turns made after the release, measured from the heading held at the release.
        acted = window & (np.arange(len(t)) >= k_rel)
        if np.any(acted) and float(np.max(dpsi[acted] - dpsi[k_rel])) > p.port_tolerance_deg:
            res.reasons.append(
                "stand-on: altered course to port for a ship on the own port side (Rule 17(c))"
            )


# ------------------------------------------------------------------------- per situation


def evaluate_situation(
    name: str,
    title: str,
    own: ShipTrack,
    own_hull: Hull,
    targets: dict,
    settings: EncounterSettings,
    route_xy,
    params: ColregParams = ColregParams(),
) -> SituationEvaluation:
    """Evaluate a finished situation. ``targets`` maps target id → (ShipTrack, Hull); ``route_xy``
    the own planned route ((n, 2) waypoints, the last one the destination)."""
    route = np.asarray(route_xy, float)
    # First pass: give-way intervals, and stand-on ones from their release (Rule 17(a)(ii):
    # action then is the own ship's to take), excuse stand-on deviations for other targets.
    first = {
        tid: evaluate_target(own, tr, own_hull, h, settings, params, route, tid)
        for tid, (tr, h) in targets.items()
    }
    evals = []
    for tid, (tr, h) in targets.items():
        excused = [
            (e.t_start_s, e.t_cpa_s)
            for other, e in first.items()
            if other != tid and e.role == "give-way" and e.t_start_s is not None
        ] + [
            (e.t_release_s, e.t_cpa_s)
            for other, e in first.items()
            if other != tid and e.role == "stand-on" and e.t_release_s is not None
        ]
        if first[tid].role == "stand-on" and excused:
            evals.append(
                evaluate_target(own, tr, own_hull, h, settings, params, route, tid, excused)
            )
        else:
            evals.append(first[tid])
    final = float(np.hypot(own.x[-1] - route[-1, 0], own.y[-1] - route[-1, 1]))
    planned = float(np.sum(np.linalg.norm(np.diff(route, axis=0), axis=1)))
    path = own.path_length()
    encounters = [e for e in evals if e.encounter != EncounterType.SAFE.value]
    return SituationEvaluation(
        situation=name,
        title=title,
        targets=evals,
        collisions=sum(e.collision for e in evals),
        min_cpa_m=min((e.cpa_m for e in evals), default=float("inf")),
        encounters=len(encounters),
        compliant=sum(e.compliant for e in encounters),
        arrived=final <= params.arrival_radius_m,
        final_distance_m=final,
        path_length_m=path,
        planned_length_m=planned,
        path_ratio=path / planned if planned > 0 else float("nan"),
        duration_s=float(own.t[-1] - own.t[0]),
    )


def evaluate_traffic_situation(
    situation: TrafficSituation,
    own: ShipTrack,
    targets: dict,
    settings: EncounterSettings,
    params: ColregParams = ColregParams(),
    name: str | None = None,
) -> SituationEvaluation:
    """:func:`evaluate_situation` with the hulls and the planned route taken from a
    :class:`TrafficSituation`; ``targets`` maps target id → ShipTrack (ids as in the situation)."""
    hulls = {s.id: Hull.from_ship(s) for s in situation.targets}
    if name is None:
        name = situation.source.stem if situation.source is not None else situation.title
    return evaluate_situation(
        name,
        situation.title,
        own,
        Hull.from_ship(situation.own_ship),
        {tid: (tr, hulls[tid]) for tid, tr in targets.items()},
        settings,
        situation.own_ship.xy,
        params,
    )


def write_situation_outputs(
    directory, situation: TrafficSituation, own: ShipTrack, targets: dict, evaluation
) -> Path:
    """``DIR/encounter.json``, ``DIR/track.csv`` and ``DIR/targets.csv`` of one situation
    (``targets`` maps target id → ShipTrack); returns the directory."""
    d = Path(directory)
    d.mkdir(parents=True, exist_ok=True)
    write_json(d / "encounter.json", evaluation)
    write_track_csv(d / "track.csv", *geodetic_columns(situation, own))
    cols = {tid: geodetic_columns(situation, tr) for tid, tr in targets.items()}
    write_targets_csv(d / "targets.csv", cols)
    return d


def summarize(evaluations) -> dict:
    """The set summary (``OUT/summary.json``): counts over all situations and one entry each."""
    evaluations = list(evaluations)
    n_enc = sum(e.encounters for e in evaluations)
    n_ok = sum(e.compliant for e in evaluations)
    return jsonable(
        {
            "situations": len(evaluations),
            "collisions": sum(e.collisions for e in evaluations),
            "min_cpa_m": min((e.min_cpa_m for e in evaluations), default=None),
            "colreg_compliance": n_ok / n_enc if n_enc else None,
            "encounters": n_enc,
            "compliant_encounters": n_ok,
            "arrived": sum(bool(e.arrived) for e in evaluations),
            "max_path_ratio": max((e.path_ratio for e in evaluations), default=None),
            "entries": [
                {
                    "situation": e.situation,
                    "title": e.title,
                    "collisions": e.collisions,
                    "min_cpa_m": e.min_cpa_m,
                    "colreg_compliance": e.compliant / e.encounters if e.encounters else None,
                    "arrived": e.arrived,
                    "path_ratio": e.path_ratio,
                    "encounters": [t.encounter for t in e.targets],
                    "compliant": [t.compliant for t in e.targets],
                }
                for e in evaluations
            ],
        }
    )


# -------------------------------------------------------------------------------- outputs

TRACK_HEADER = ("t_s", "lat_deg", "lon_deg", "heading_deg", "sog_kn")


def traffic_metrics(times, own_states, target_states) -> dict:
    """A mission's traffic metrics from samples at the same times: ``own_states`` (n × ≥ 2, x y
    first) and ``target_states`` (n × 4 m, [x y ψ speed] per target): the smallest
    centre-to-centre distance to any target [m], when [s] and to which target (index)."""
    own = np.asarray(own_states, float)
    tgt = np.asarray(target_states, float)
    m = tgt.shape[1] // 4 if tgt.ndim == 2 else 0
    n = min(len(own), len(tgt))
    if m == 0 or n == 0:
        return {"traffic_targets": m, "traffic_min_distance_m": None}
    xy = tgt[:n].reshape(n, m, 4)[:, :, :2]
    d = np.linalg.norm(xy - own[:n, None, :2], axis=2)
    k, j = np.unravel_index(int(np.argmin(d)), d.shape)
    return {
        "traffic_targets": m,
        "traffic_min_distance_m": float(d[k, j]),
        "traffic_min_distance_t_s": float(np.asarray(times, float)[k]),
        "traffic_nearest_target": int(j),
    }


def write_track_csv(path, t, lat, lon, heading_deg, sog_kn) -> Path:
    """The own ship's ``track.csv``: ``t_s,lat_deg,lon_deg,heading_deg,sog_kn`` (true heading in
    degrees clockwise from north, as DNV's files; t from the situation's start)."""
    path = Path(path)
    cols = [np.atleast_1d(np.asarray(c, float)) for c in (t, lat, lon, heading_deg, sog_kn)]
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(TRACK_HEADER)
        for row in zip(*cols, strict=True):
            w.writerow(_fmt_row(row))
    return path


def write_targets_csv(path, tracks) -> Path:
    """``targets.csv``: ``id,t_s,lat_deg,lon_deg,heading_deg,sog_kn``; ``tracks`` maps target
    id → (t, lat, lon, heading_deg, sog_kn) arrays."""
    path = Path(path)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(("id",) + TRACK_HEADER)
        for tid, cols in tracks.items():
            cols = [np.atleast_1d(np.asarray(c, float)) for c in cols]
            for row in zip(*cols, strict=True):
                w.writerow((tid, *_fmt_row(row)))
    return path


def geodetic_columns(situation: TrafficSituation, track: ShipTrack):
    """A local track → the CSV columns (t [s], lat [deg], lon [deg], true heading [deg], SOG
    [kn]) in the situation's geodetic frame."""
    lat, lon = situation.to_geodetic(track.x, track.y)
    return track.t, lat, lon, psi_to_heading_deg_true(track.psi), mps_to_knots(track.speed)


def _fmt_row(row):
    t, lat, lon, hdg, sog = (float(v) for v in row)
    hdg = round(hdg, 3) % 360.0  # never "360.000"
    return (f"{t:.3f}", f"{lat:.8f}", f"{lon:.8f}", f"{hdg:.3f}", f"{sog:.4f}")


def write_json(path, obj) -> Path:
    """Strict JSON (non-finite floats → null) of a dict or an evaluation with ``to_dict``."""
    path = Path(path)
    data = obj.to_dict() if hasattr(obj, "to_dict") else jsonable(obj)
    path.write_text(json.dumps(data, indent=2, allow_nan=False) + "\n")
    return path
