"""Scenario-Based MPC collision avoidance (Johansen et al. 2016), vectorised.

A finite set of control behaviours k = (course offset χ_k, propulsion factor P_k) is each
simulated over a horizon: the own ship follows course χ_d + χ_k at speed P_k·u_d (first-order
course and speed response, the autopilot's closed loop), every tracked target at constant
velocity. Each behaviour gets the hazard (Johansen et al. 2016 §III, our notation and weights)

    H_k = max_{t, i} [ C_i^k(t) R_i^k(t) + κ μ_i^k(t) + λ τ_i^k(t) ] + f(P_k, χ_k) + g(P_k, χ_k)

    R = (T/t)^p (d_safe/d)^q  if d ≤ d_safe, else 0   (collision risk; the paper's 1/t^p made
                                                       dimensionless by the horizon T)
    C = k_coll |v_0 − v_i|² / U_ref²                   (collision cost, relative speed)
    μ = CLOSE(t) ∧ STARBOARD(t) ∧ (HEAD-ON₀ ∨ CROSSING-GIVE-WAY₀)   (COLREG violation)
        ∨ CLOSE(t) ∧ χ_k > 0 ∧ CROSSING-STAND-ON₀                   (Rule 17(c), ours)
    τ = CLOSE(t) ∧ the own ship has crossed the target's course line ahead of its bow
        (crossing targets only: Rule 15; in head-on μ asks for the port-to-port pass, and an
        overtaking ship keeps out of the way of the one it overtakes, Rule 13)
    f = k_P (1 − P) + k_χ χ²   (k_χ larger for port offsets than starboard ones)
    g = k_dP |P − P_last| + k_dχ (χ − χ_last)²   (likewise by the side of the change)

and the behaviour of least H is chosen. Deviations from the paper, all ours: (1) the situation
(head-on, crossing give-way / stand-on, being overtaken) is classified with the paper's angles
φ_AH, φ_OT, φ_HO, φ_CR from the geometry when the target becomes relevant, and `Sbmpc`
remembers it per track id while the side and closeness are tested along the prediction; as we
read the paper it evaluates the geometry at every predicted time, which lets a port turn in a
crossing escape the penalty by making the courses no longer "crossed", and our own manoeuvre
would re-classify a head-on target as a crossing one. (2) The transitional term
τ penalises crossing ahead of a target (COLREG Rule 15: the give-way vessel shall avoid crossing
ahead), in the role the transitional cost plays in later SB-MPC variants. (3) Stand-on (Rule 17):
a target for which the own ship is stand-on (crossing from port, or overtaking us) adds no
collision risk while it is farther than `stand_on_range` and its time to CPA is longer than
`stand_on_tcpa_fraction` of the horizon, so the own ship keeps course and speed until then and
acts only when the give-way vessel has not. (4) Targets farther than `d_init`, and targets past
their closest point of approach (time to CPA < 0) farther than `d_close`, are ignored: once
nothing is relevant the nominal (0, 1) is returned. (5) The change cost g weighs a change back
to port less than the deviation cost f of keeping a starboard offset, so the own ship returns to
its course once the hazard is gone. (6) The hazard adds k_mean × the time-average of C·R over the
horizon: when the own ship is already inside a safety zone, the maximum over time is reached
at the first step for every behaviour alike, and the average then prefers the behaviour that
leaves the zone soonest. (7) Given the route's end (``destination``), a behaviour's prediction
ends where it arrives there: a target that passes the end after the own ship is in is no hazard
(without it, a ship whose route ends beside a target's track was held off its end). (8) The
required CPA comes first (``keep_required_cpa``): when some behaviour is predicted to pass every
target (but a stand-on one still held) at ``cpa_required`` or more, the behaviours that are not
cost ``k_forbidden`` more; C is weighted by the relative speed, so a ship overtaking us slowly
was otherwise passed inside the required CPA. (9) Within ``miss_range`` of the route's end
(``destination``, with ``end_leg_start`` the last leg's start), a behaviour predicted to run
past the end along the last leg without coming within ``arrival_radius`` costs ``k_miss``: the
guidance ends the voyage there, and holding a starboard offset past the end is no cheaper in
the paper's cost than slowing down until the way in is clear.

Use: pass the guidance's course (e.g. line-of-sight, which steers back to the route) as the
nominal course and let the autopilot steer nominal + offset at nominal speed × factor at all
times, re-deciding every few seconds; pass tracks with ids so that roles are remembered.

Angles follow usvdrake: counter-clockwise from east. A STARBOARD turn (to the right) is a
NEGATIVE course offset (the course angle decreases), and a target is on the starboard side when
the cross product of the own heading with the line of sight is negative.
"""

from dataclasses import dataclass, field

import numpy as np

from usvdrake.angles import wrap_angle
from usvdrake.systems.colav.encounter import EncounterType, classify_bearings, relative_bearings
from usvdrake.systems.colav.situation import EncounterSettings

NMI = 1852.0  # [m]


@dataclass(frozen=True)
class SbmpcParams:
    """SB-MPC parameters. Distances [m] scale with the ship (see `for_safety_distance`)."""

    course_offsets_deg: tuple[float, ...] = (
        -90.0, -75.0, -60.0, -45.0, -30.0, -15.0, 0.0, 15.0, 30.0, 45.0, 60.0, 75.0, 90.0,
    )  # fmt: skip
    # The paper's propulsion set is {1, 0.5, 0, −1}; full reverse (−1) is left out by default
    # because our speed controllers do not go astern; add it here if yours does.
    speed_factors: tuple[float, ...] = (1.0, 0.5, 0.0)
    horizon_s: float = 900.0
    dt_s: float = 5.0
    course_time_constant_s: float = 30.0  # own course response to a new course command
    speed_time_constant_s: float = 90.0  # own speed response to a new speed command
    # 30 % over issue 37's 0.5 nmi CPA: room for tracking noise, the constant-velocity guess of
    # the targets and the own ship's lag behind the first-order prediction.
    d_safe: float = 1.3 * 0.5 * NMI
    d_close: float = 1.5 * NMI  # COLREG terms count inside this range
    d_init: float = 8.0 * NMI  # targets farther than this are ignored
    stand_on_range: float = 1.0 * NMI  # stand-on: keep course and speed while farther ...
    stand_on_tcpa_fraction: float = 0.6  # ... and while time to CPA > this × horizon
    # ... or while the nominal passing distance is at least this (the required CPA): then the
    # give-way ship has acted enough, and a stand-on ship that moves would break Rule 17(a)
    cpa_required: float = 0.5 * NMI
    # while a head-on or give-way crossing target, or a stand-on crossing one (Rule 17(c)), is
    # before its CPA, no behaviour may head more than this to port of the route (our rule:
    # COLREGs Rules 14, 15 and 17(c) forbid the turn to port the prediction might prefer)
    port_limit_deg: float = 8.0
    k_forbidden: float = 1e6
    p: float = 1.0  # time exponent of R
    q: float = 4.0  # distance exponent of R
    k_coll: float = 1.0
    k_mean: float = 3.0  # weight of the time-averaged risk (our addition, see the docstring)
    kappa: float = 5.0  # COLREG violation μ
    lam: float = 5.0  # crossing ahead τ
    # speed reduction; 3 → 1.5 made slowing down compete with long starboard detours (DNV 12
    # and 27 came back under 1.2 × the route, docs/experiments/colav-tuning.md run d5)
    k_p: float = 1.5
    k_chi_starboard: float = 1.0  # per rad²
    k_chi_port: float = 3.0
    k_dp: float = 0.5
    k_dchi_starboard: float = 0.4  # per rad² of change towards starboard
    k_dchi_port: float = 0.6  # towards port; < k_chi_starboard so that the ship returns
    phi_ah_deg: float = 68.5  # "ahead" sector half-angle
    phi_ot_deg: float = 68.5  # overtaking: courses within this angle
    phi_ho_deg: float = 22.5  # head-on: courses opposite within this angle
    phi_cr_deg: float = 68.5  # crossing: courses differ by more than this
    min_target_speed: float = 0.25  # [m/s] slower targets are treated as stationary (no role)
    # roles from DNV's trafficgen sectors (``encounter.classify_bearings``, the evaluation's
    # classification) instead of the paper's angles: a target crossing at a shallow angle from
    # starboard is then a give-way crossing, not a ship overtaking us (our option)
    sector_roles: bool = False
    # Rule 8(d) "until the other vessel is finally past and clear", per track and latched: the
    # no-port rule holds for a target with a duty (head-on, crossing, by the paper's angles or
    # DNV's sectors) until it is past its CPA both on the present course and on the nominal
    # (return) one; a stand-on crossing target's port limit after the release is measured from
    # the course held at the release (Rule 17(c)); an unreleased stand-on target keeps the
    # course within ``port_limit_deg`` of the route's while no give-way duty is open (Rule
    # 17(a)(i)). False: the older rule (SB-MPC's roles, open until the present course's CPA).
    # On by default since run d6 (docs/experiments/colav-tuning.md, runs d0-d9): compliance
    # DNV 81.1 → 92.6 %, canal 60 → 96.4 %, every DNV path within 1.2 × the route.
    hold_until_clear: bool = True
    # the stand-on crossing port limit from the course held at the release even when that is to
    # starboard of the route (True: the evaluation's reading of Rule 17(c); False: from the
    # route's course at most, so a ship released while on a give-way offset for another target
    # may return to its route: shorter paths, see docs/experiments/colav-tuning.md)
    stand_on_limit_from_release: bool = True
    # a behaviour predicted to pass a target (other than a stand-on one still held) nearer than
    # ``cpa_required`` is ranked below every behaviour predicted to keep it, when one does: the
    # required CPA is the must, the weighted risk only orders what keeps it (our addition)
    keep_required_cpa: bool = True
    # within ``miss_range`` of the route's end, a behaviour predicted to go past the end along
    # the last leg without coming within the arrival radius costs ``k_miss``: the guidance ends
    # the voyage there, so slowing down until the way in is clear is cheaper (our addition)
    k_miss: float = 10.0
    miss_range: float = 4000.0

    @classmethod
    def for_safety_distance(
        cls, cpa: float, margin: float = 1.3, **overrides
    ) -> "SbmpcParams":  # fmt: skip
        """Parameters for a required CPA [m]: d_safe = margin × cpa, and d_close, d_init and
        stand_on_range scaled from the defaults, which are set for a 0.5 nmi CPA. Times (horizon,
        dt, time constants) are not scaled: pass them in `overrides` for another ship."""
        s = cpa / (0.5 * NMI)
        base = cls()
        kw = dict(
            d_safe=margin * cpa,
            cpa_required=cpa,
            d_close=base.d_close * s,
            d_init=base.d_init * s,
            stand_on_range=base.stand_on_range * s,
            miss_range=base.miss_range * s,
        )
        kw.update(overrides)
        return cls(**kw)


@dataclass(frozen=True)
class SbmpcDecision:
    """The chosen behaviour and diagnostics."""

    course_offset: float  # [rad], negative = starboard
    speed_factor: float
    index: int  # into behaviours(params)
    cost: float
    costs: np.ndarray = field(repr=False)  # every behaviour's H_k
    min_distance: float  # predicted minimum distance to any target with the chosen behaviour
    active: bool  # False: no target in range, nominal (0, 1) returned
    encounter_open: bool = False  # a relevant target is not yet past its closest approach


def behaviours(params: SbmpcParams) -> tuple[np.ndarray, np.ndarray]:
    """(χ_k [rad], P_k) of every behaviour, offsets major."""
    chi = np.radians(np.asarray(params.course_offsets_deg, dtype=float))
    fac = np.asarray(params.speed_factors, dtype=float)
    return np.repeat(chi, fac.size), np.tile(fac, chi.size)


def predict_own(params, position, course, speed, course_ref, speed_ref):
    """Own-ship positions, velocities and courses for every behaviour: (S, N+1, 2), (S, N+1, 2),
    (S, N+1). First-order course and speed responses, trapezoidal position integration."""
    chi_k, fac_k = behaviours(params)
    n = int(round(params.horizon_s / params.dt_s))
    t = params.dt_s * np.arange(n + 1)
    target_course = course_ref + chi_k  # (S,)
    err0 = wrap_angle(course - target_course)
    ec = np.exp(-t / params.course_time_constant_s)
    es = np.exp(-t / params.speed_time_constant_s)
    chi = target_course[:, None] + err0[:, None] * ec[None, :]
    u_target = fac_k * speed_ref
    u = u_target[:, None] + (speed - u_target)[:, None] * es[None, :]
    vel = np.stack([u * np.cos(chi), u * np.sin(chi)], axis=-1)
    steps = 0.5 * params.dt_s * (vel[:, 1:] + vel[:, :-1])
    pos = np.concatenate([np.zeros((chi_k.size, 1, 2)), np.cumsum(steps, axis=1)], axis=1)
    return pos + np.asarray(position, dtype=float), vel, chi, t


def classify_sectors(own_velocity, rel_position, target_velocity, min_speed: float):
    """The roles of :func:`classify` from DNV's trafficgen sectors (``encounter``): HO → head-on,
    CR-GW → give-way crossing, CR-SO → stand-on crossing, OT-SO → stand-on (being overtaken);
    OT-GW (we overtake: keep out of the way on either side) and no risk → no role."""
    v0 = np.asarray(own_velocity, dtype=float)
    rel = np.asarray(rel_position, dtype=float).reshape(-1, 2)
    tv = np.asarray(target_velocity, dtype=float).reshape(-1, 2)
    out = np.zeros((4, rel.shape[0]), bool)
    settings = EncounterSettings()  # DNV's angles (trafficgen's encounter_settings.json)
    psi0 = float(np.arctan2(v0[1], v0[0]))
    for i in range(rel.shape[0]):
        if np.linalg.norm(tv[i]) <= min_speed:
            continue
        beta, alpha = relative_bearings((0.0, 0.0), psi0, rel[i], np.arctan2(tv[i, 1], tv[i, 0]))
        kind = classify_bearings(beta, alpha, settings)
        out[0, i] = kind is EncounterType.HEAD_ON
        out[1, i] = kind is EncounterType.CROSSING_GIVE_WAY
        out[3, i] = kind is EncounterType.CROSSING_STAND_ON
        out[2, i] = out[3, i] or kind is EncounterType.OVERTAKING_STAND_ON
    return out[0], out[1], out[2], out[3]


def classify(params, own_velocity, rel_position, target_velocity):
    """Situation at t0 per target (Johansen et al. 2016 §III angles, or with ``sector_roles``
    DNV's sectors, :func:`classify_sectors`): (head_on, give_way_crossing, stand_on,
    stand_on_crossing) boolean arrays of shape (M,). rel_position = target − own."""
    if params.sector_roles:
        return classify_sectors(own_velocity, rel_position, target_velocity,
                                params.min_target_speed)  # fmt: skip
    c = np.cos
    v0 = np.asarray(own_velocity, dtype=float)
    s0 = np.linalg.norm(v0)
    si = np.linalg.norm(target_velocity, axis=1)
    dist = np.linalg.norm(rel_position, axis=1)
    dot = target_velocity @ v0
    moving = si > params.min_target_speed
    ahead = rel_position @ v0 > c(np.radians(params.phi_ah_deg)) * s0 * dist
    starboard = v0[0] * rel_position[:, 1] - v0[1] * rel_position[:, 0] < 0.0
    head_on = moving & (dot < -c(np.radians(params.phi_ho_deg)) * s0 * si) & ahead
    overtaken = (dot > c(np.radians(params.phi_ot_deg)) * s0 * si) & (s0 < si)  # it overtakes us
    crossed = moving & (dot < c(np.radians(params.phi_cr_deg)) * s0 * si) & ~head_on & ~overtaken
    give_way_crossing = crossed & starboard
    stand_on_crossing = crossed & ~starboard
    stand_on = stand_on_crossing | (overtaken & moving & ~ahead)
    return head_on, give_way_crossing, stand_on, stand_on_crossing


def own_velocity(params: SbmpcParams, course, speed) -> np.ndarray:
    """The own velocity the roles are judged from: along ``course`` at least at
    ``min_target_speed`` (a caller whose ship is nearly stopped passes its heading as the course:
    ``SbmpcColav`` does; the guidance's course would make a target behind the bow look past its
    CPA and be forgotten)."""
    return max(speed, params.min_target_speed) * np.array([np.cos(course), np.sin(course)])


def relevance(params: SbmpcParams, position, v0, tp, tv):
    """(relevant mask, range, time to CPA) of each target at t0: a target counts while within
    d_init unless it is past its CPA and farther than d_close."""
    rel = tp - np.asarray(position, dtype=float)
    dv = tv - v0
    range0 = np.linalg.norm(rel, axis=1)
    tcpa = -np.sum(rel * dv, axis=1) / np.maximum(np.sum(dv * dv, axis=1), 1e-12)
    keep = (range0 <= params.d_init) & ~((tcpa < 0.0) & (range0 > params.d_close))
    return keep, range0, tcpa


def stand_on_released(params: SbmpcParams, position, v0, tp, tv) -> np.ndarray:
    """(M,) whether the own ship, if stand-on to each target, may act now (Rule 17(a)(ii)): the
    target is within ``stand_on_range``, or the nominal CPA is nearer than the required one and
    less than ``stand_on_tcpa_fraction`` of the horizon away."""
    rel = np.asarray(tp, float).reshape(-1, 2) - np.asarray(position, dtype=float)
    dv = np.asarray(tv, float).reshape(-1, 2) - v0
    range0 = np.linalg.norm(rel, axis=1)
    tcpa = -np.sum(rel * dv, axis=1) / np.maximum(np.sum(dv * dv, axis=1), 1e-12)
    dcpa = np.linalg.norm(rel + dv * np.maximum(tcpa, 0.0)[:, None], axis=1)
    soon = (tcpa <= params.stand_on_tcpa_fraction * params.horizon_s) & (dcpa < params.cpa_required)
    return (range0 <= params.stand_on_range) | soon


def hazard(
    params: SbmpcParams,
    position,
    course: float,
    speed: float,
    course_ref: float,
    speed_ref: float,
    target_positions,
    target_velocities,
    last=(0.0, 1.0),
    roles=None,
    released=None,
    destination=None,
    arrival_radius: float = 0.0,
    end_leg_start=None,
):
    """H_k of every behaviour and the predicted minimum distance of each: ((S,), (S,)).

    roles: optional (M, 4) booleans (head_on, give_way_crossing, stand_on, stand_on_crossing)
    per target, e.g. remembered from when the target first became relevant; classified from the
    present geometry when None. released: optional (M,) booleans, stand-on duties already
    released (kept released by ``Sbmpc``, so the choice does not flip at the threshold)."""
    chi_k, fac_k = behaviours(params)
    last_chi, last_fac = last
    dchi = chi_k - last_chi
    f = (
        params.k_p * (1.0 - fac_k)
        + np.where(chi_k < 0.0, params.k_chi_starboard, params.k_chi_port) * chi_k**2
    )
    g = (
        params.k_dp * np.abs(fac_k - last_fac)
        + np.where(dchi < 0.0, params.k_dchi_starboard, params.k_dchi_port) * dchi**2
    )
    tp = np.asarray(target_positions, dtype=float).reshape(-1, 2)
    tv = np.asarray(target_velocities, dtype=float).reshape(-1, 2)
    if tp.shape[0] == 0:
        return f + g, np.full(chi_k.size, np.inf)
    pos0 = np.asarray(position, dtype=float)
    v0 = own_velocity(params, course, speed)
    keep, range0, tcpa0 = relevance(params, pos0, v0, tp, tv)
    if not np.any(keep):
        return f + g, np.full(chi_k.size, np.inf)
    if roles is None:
        roles = np.stack(classify(params, v0, tp - pos0, tv), axis=1)
    roles = np.asarray(roles, dtype=bool).reshape(-1, 4)[keep]
    was_released = np.zeros(keep.size, bool) if released is None else np.asarray(released, bool)
    release = stand_on_released(params, pos0, v0, tp, tv) | was_released
    tp, tv, range0, tcpa0 = tp[keep], tv[keep], range0[keep], tcpa0[keep]
    release = release[keep]
    own_p, own_v, own_chi, t = predict_own(params, pos0, course, speed, course_ref, speed_ref)
    # Relative geometry target − own, (S, N+1, M) per component; targets at constant velocity.
    rx = (tp[:, 0] + t[:, None] * tv[:, 0])[None] - own_p[:, :, 0, None]
    ry = (tp[:, 1] + t[:, None] * tv[:, 1])[None] - own_p[:, :, 1, None]
    dist = np.sqrt(rx * rx + ry * ry)
    head_on, give_way, stand_on, so_cross = roles.T
    # Collision risk C·R, zero for a stand-on target still far in range and in time
    # (Rule 17: keep course and speed while the give-way vessel can act).
    u_ref = max(speed_ref, speed, params.min_target_speed)
    dvx = own_v[:, :, 0, None] - tv[:, 0]
    dvy = own_v[:, :, 1, None] - tv[:, 1]
    c_cost = (params.k_coll / u_ref**2) * (dvx * dvx + dvy * dvy)
    tw = (params.horizon_s / np.maximum(t, params.dt_s)) ** params.p  # (N+1,)
    ratio = params.d_safe / np.maximum(dist, 1e-3 * params.d_safe)
    holding = stand_on & ~release
    inside = (dist <= params.d_safe) & ~holding
    risk = np.where(inside, c_cost * tw[None, :, None] * ratio**params.q, 0.0)
    # COLREG violation μ: a head-on or give-way-crossing target close on our starboard side.
    close = dist <= params.d_close
    hx, hy = np.cos(own_chi)[:, :, None], np.sin(own_chi)[:, :, None]
    mu = close & (hx * ry - hy * rx < 0.0) & (head_on | give_way)
    # Rule 17(c): a stand-on vessel that acts does not turn to port for a vessel on its port side.
    mu |= close & ((chi_k > 0.0)[:, None, None] & so_cross)
    # τ: crossing the target's course line ahead of its bow (side changed while ahead of it).
    sp = np.linalg.norm(tv, axis=1)
    ex, ey = tv[:, 0] / np.maximum(sp, 1e-9), tv[:, 1] / np.maximum(sp, 1e-9)
    side = ey * rx - ex * ry  # cross(target heading, own − target)
    along = -(ex * rx + ey * ry)
    crossed_ahead = (side * side[:, :1, :] < 0.0) & (along > 0.0)
    # a stand-on ship still holding (Rule 17(a)(i)) owes the target nothing, passing ahead included
    tau = (
        close & crossed_ahead & ((sp > params.min_target_speed) & (give_way | so_cross & ~holding))
    )
    inst = risk + params.kappa * mu + params.lam * tau
    missed = np.zeros(chi_k.size, bool)
    if destination is not None:
        # the voyage ends where a behaviour's prediction reaches the route's end: what the
        # targets do after that is no hazard to it
        end = np.asarray(destination, float)
        there = np.hypot(*(own_p - end).transpose(2, 0, 1))
        reached = np.cumsum(there <= arrival_radius, axis=1) > 0
        done = np.zeros_like(reached)
        done[:, 1:] = reached[:, :-1]  # from the step after the first arrival
        inst = np.where(done[:, :, None], 0.0, inst)
        risk = np.where(done[:, :, None], 0.0, risk)
        dist = np.where(done[:, :, None], np.inf, dist)
        if (
            end_leg_start is not None
            and params.k_miss > 0.0
            and np.hypot(*(pos0 - end)) < params.miss_range
        ):
            a = np.asarray(end_leg_start, float)
            length = float(np.hypot(*(end - a)))
            e = (end - a) / max(length, 1e-9)
            past = (own_p - a) @ e >= length + arrival_radius  # the guidance's "past the end"
            missed = np.any(past & ~reached, axis=1)
    h = inst.reshape(chi_k.size, -1).max(axis=1)
    h += params.k_miss * missed
    if params.keep_required_cpa:
        # C·R weighs a pass by the relative speed: a ship overtaking us slowly costs little
        # even inside the required CPA, so the weighted risk alone may prefer breaking it
        near = np.where(holding[None, None, :], np.inf, dist).reshape(chi_k.size, -1).min(axis=1)
        keeps = near >= params.cpa_required
        if np.any(keeps):
            h = h + np.where(keeps, 0.0, params.k_forbidden)
    # Already inside a safety zone, every behaviour's maximum sits at t ≈ 0 and is the same for
    # all; the time-average of the risk then tells which behaviour leaves the zone soonest.
    h += params.k_mean * risk.mean(axis=1).sum(axis=1)
    dmin = dist.reshape(chi_k.size, -1).min(axis=1)
    return h + f + g, dmin


class Sbmpc:
    """The decision maker: keeps the previous choice for the change cost g, and each target's
    COLREG role from the decision at which it became relevant (by track id), so that the own
    ship's manoeuvre does not re-classify a head-on target as a crossing one; a target that
    stops being relevant is forgotten."""

    def __init__(self, params: SbmpcParams | None = None):
        self.params = params or SbmpcParams()
        self.last = (0.0, 1.0)
        self.roles: dict = {}
        self.released: set = set()  # track ids whose stand-on duty was released (latched)
        self.duties: dict = {}  # track id → [roles (4,), cleared, course at release or None]
        self._chi, self._fac = behaviours(self.params)

    def decide(
        self, position, course, speed, course_ref, speed_ref, tracks=None, *, positions=None,
        velocities=None, ids=None, path_course=None, hold_stand_on=True, destination=None,
        arrival_radius=0.0, end_leg_start=None,
    ) -> SbmpcDecision:  # fmt: skip
        """Choose (course offset, speed factor) from the own state (position [m], course [rad],
        speed [m/s]), the nominal course and speed from guidance, and the targets: `tracks`
        (objects with .position, .velocity and .target_id, e.g. tracking.Track) or arrays
        (with `ids` to remember roles; without ids roles are classified afresh each call).
        `path_course`: the route's course, which the no-port-turn rule is measured from
        (default the nominal course). `hold_stand_on` False: no stand-on duty bounds the course
        (``hold_until_clear``; e.g. near the route's end, which the ship must still make).
        `destination`: the route's end; each behaviour's prediction stops counting hazards
        from the step after it comes within `arrival_radius` [m] of it; with `end_leg_start`
        (the last leg's start) one that runs past the end without arriving costs `k_miss`."""
        if tracks is not None:
            positions = [tr.position for tr in tracks]
            velocities = [tr.velocity for tr in tracks]
            ids = [tr.target_id for tr in tracks]
        tp = np.asarray(positions if positions is not None else [], float).reshape(-1, 2)
        tv = np.asarray(velocities if velocities is not None else [], float).reshape(-1, 2)
        pos0 = np.asarray(position, dtype=float)
        v0 = own_velocity(self.params, course, speed)
        keep, range0, tcpa0 = relevance(self.params, pos0, v0, tp, tv)
        encounter_open = bool(np.any(keep & (tcpa0 > 0.0)))
        roles = None
        if ids is not None:
            fresh = np.stack(classify(self.params, v0, tp - pos0, tv), axis=1).reshape(-1, 4)
            vn = speed_ref * np.array([np.cos(course_ref), np.sin(course_ref)])
            tcpa_nominal = relevance(self.params, pos0, vn, tp, tv)[2]  # on the return course
            gone = (range0 > self.params.d_init) | (tcpa_nominal < 0)
            for i, tid in enumerate(ids):
                # a target that drops out of relevance for a moment (e.g. while the own ship
                # is stopped) keeps its role and duties unless it is gone or past on the
                # guidance's (return) course too
                if not keep[i] and (gone[i] or not self.params.hold_until_clear):
                    self.roles.pop(tid, None)
                elif tid not in self.roles:
                    self.roles[tid] = fresh[i]
            roles = np.array([self.roles.get(tid, fresh[i]) for i, tid in enumerate(ids)])
            if self.params.hold_until_clear:
                sect = np.stack(
                    classify_sectors(v0, tp - pos0, tv, self.params.min_target_speed), axis=1
                )
                roles = self._hazard_roles(ids, roles, sect)
            now = stand_on_released(self.params, pos0, v0, tp, tv)
            self.released = {tid for tid in self.released if tid in self.roles}
            self.released |= {tid for i, tid in enumerate(ids) if keep[i] and now[i]}
            released = np.array([tid in self.released for tid in ids], bool)
        else:
            released = None
        if not np.any(keep):
            self.last = (0.0, 1.0)
            i0 = int(np.argmin(np.abs(self._chi) + np.abs(1.0 - self._fac)))
            return SbmpcDecision(0.0, 1.0, i0, 0.0, np.zeros(self._chi.size), np.inf, False)
        costs, dmin = hazard(
            self.params, pos0, course, speed, course_ref, speed_ref, tp, tv, self.last, roles,
            released, destination, arrival_radius, end_leg_start,
        )  # fmt: skip
        if roles is not None and self.params.hold_until_clear:
            ref = course_ref if path_course is None else path_course
            duty = self._duty_costs(
                ids, keep, tcpa0, tcpa_nominal, sect, pos0, tp, course, course_ref, ref,
                released, hold_stand_on,
            )  # fmt: skip
            # the duties yield to safety (Rule 2(b), "if the circumstances of the case admit"):
            # only while some allowed behaviour is predicted to keep the required CPA
            if np.any((duty == 0.0) & (dmin >= self.params.cpa_required)):
                costs = costs + duty
        elif roles is not None:
            duty = roles[:, 0] | roles[:, 1] | roles[:, 3]  # HO, GW crossing, SO crossing
            if np.any(keep & (tcpa0 > 0.0) & duty):
                ref = course_ref if path_course is None else path_course
                port = wrap_angle(course_ref + self._chi - ref) > np.radians(
                    self.params.port_limit_deg
                )
                costs = costs + np.where(port, self.params.k_forbidden, 0.0)
        k = int(np.argmin(costs))
        self.last = (float(self._chi[k]), float(self._fac[k]))
        return SbmpcDecision(
            course_offset=self.last[0],
            speed_factor=self.last[1],
            index=k,
            cost=float(costs[k]),
            costs=costs,
            min_distance=float(dmin[k]),
            active=True,
            encounter_open=encounter_open,
        )

    def _hazard_roles(self, ids, roles, sect) -> np.ndarray:
        """The roles the hazard uses with ``hold_until_clear``: a head-on or give-way duty by
        either classification (the paper's angles or DNV's sectors, latched in ``duties``)
        wins over the paper's stand-on, so that a ship crossing from starboard at a shallow
        angle, "overtaking" by the paper's angles, is not held as a stand-on target (no
        collision cost) until it is 1 nmi away. sect: (M, 4) DNV's sector roles now."""
        if len(ids) == 0:
            return roles
        union = np.array(
            [self.duties[tid][0] if tid in self.duties else roles[i] | sect[i]
             for i, tid in enumerate(ids)], dtype=bool,
        ).reshape(-1, 4)  # fmt: skip
        duty = union[:, 0] | union[:, 1]
        return np.column_stack([union[:, 0], union[:, 1], roles[:, 2] & ~duty, roles[:, 3] & ~duty])

    def _duty_costs(
        self, ids, keep, tcpa0, tcpa_nominal, sect, pos0, tp, course, course_ref, ref, released,
        hold_stand_on=True,
    ) -> np.ndarray:  # fmt: skip
        """(S,) ``k_forbidden`` for every behaviour that breaks an open duty (``hold_until_clear``):
        updates ``self.duties`` (first relevance: the union of the paper's and DNV's roles)."""
        p = self.params
        lim = np.radians(p.port_limit_deg)
        rel_now = float(wrap_angle(course - ref))
        ranges = np.linalg.norm(tp - pos0, axis=1)
        port_limit, keep_course, give_way_open = np.inf, False, False
        for i, tid in enumerate(ids):
            if not keep[i]:
                continue
            duty = self.duties.setdefault(tid, [self.roles[tid] | sect[i], False, None])
            # past and clear: the CPA is behind on the present course and on the return one
            duty[1] = duty[1] or (tcpa0[i] < 0.0 and tcpa_nominal[i] < 0.0)
            if duty[1]:
                continue
            head_on, give_way, stand_on, so_cross = duty[0]
            if head_on or give_way:
                port_limit, give_way_open = min(port_limit, lim), True
            # near the route's end a far stand-on target, or one already past on the present
            # course, no longer holds the course; a close one before its CPA still does (a
            # port turn towards it is what Rule 17(c) forbids)
            # (a released crossing one released near the route's course is past only on the
            # return course too: a port turn back towards it is what would bring its CPA back,
            # Rule 17(c); released well to starboard, holding that to its CPA would take the
            # ship far past the route's end, and it returns as before)
            near_route = duty[2] is not None and duty[2] >= -lim
            past = tcpa0[i] < 0.0 and not (so_cross and released[i] and near_route)
            if not hold_stand_on and (ranges[i] > p.d_close or past):
                continue
            if so_cross and released[i]:
                duty[2] = rel_now if duty[2] is None else duty[2]
                base = duty[2] if p.stand_on_limit_from_release else max(duty[2], 0.0)
                port_limit = min(port_limit, base + lim)
            elif so_cross:
                port_limit = min(port_limit, lim)
            keep_course |= bool(stand_on and not released[i])
        self.duties = {tid: d for tid, d in self.duties.items() if tid in self.roles}
        heading = wrap_angle(course_ref + self._chi - ref)
        bad = heading > port_limit
        if keep_course and not give_way_open:
            bad |= np.abs(heading) > lim
        return np.where(bad, p.k_forbidden, 0.0)
