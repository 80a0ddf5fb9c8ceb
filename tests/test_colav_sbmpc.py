"""Scenario-Based MPC (Johansen et al. 2016): COLREG-typical choices on hand-made encounters.

Angles counter-clockwise from east: a starboard (right) turn is a NEGATIVE course offset."""

import numpy as np
import pytest

from usvdrake.systems.colav.sbmpc import (
    NMI,
    Sbmpc,
    SbmpcParams,
    behaviours,
    hazard,
    predict_own,
    stand_on_released,
)
from usvdrake.systems.colav.tracking import Track

KNOT = NMI / 3600.0
NORTH = np.pi / 2
U = 10.0 * KNOT


def _decide(target_pos, target_vel, params=None, speed=U):
    s = Sbmpc(params or SbmpcParams())
    return s.decide([0.0, 0.0], NORTH, speed, NORTH, speed, positions=target_pos,
                    velocities=target_vel)  # fmt: skip


def test_no_targets_keeps_course_and_speed():
    d = _decide([], [])
    assert (d.course_offset, d.speed_factor, d.active) == (0.0, 1.0, False)
    far = _decide([[0.0, 20.0 * NMI]], [[0.0, -5.0]])  # beyond d_init
    assert (far.course_offset, far.speed_factor) == (0.0, 1.0)


@pytest.mark.parametrize("range_nmi", [4.0, 6.0])
def test_head_on_turns_to_starboard(range_nmi):
    d = _decide([[30.0, range_nmi * NMI]], [[0.0, -12.0 * KNOT]])
    assert d.active
    assert d.course_offset < 0.0  # starboard: ψ decreasing
    assert d.speed_factor == 1.0
    assert d.min_distance >= SbmpcParams().d_safe
    # the port alternative of the same size is judged worse
    chi, fac = behaviours(SbmpcParams())
    mirror = np.flatnonzero(np.isclose(chi, -d.course_offset) & (fac == 1.0))[0]
    assert d.costs[mirror] > d.cost


@pytest.mark.parametrize("minutes", [10.0, 15.0])
def test_give_way_crossing_turns_starboard_and_passes_astern(minutes):
    tc = 60.0 * minutes  # both reach (0, U tc) at tc on the present courses
    vt = np.array([-12.0 * KNOT, 0.0])  # from starboard (east), heading west
    pt = np.array([12.0 * KNOT * tc, U * tc])
    d = _decide([pt], [vt])
    assert d.course_offset < 0.0 or d.speed_factor < 1.0
    assert d.course_offset <= 0.0
    assert d.min_distance >= SbmpcParams().d_safe
    # never ahead of the target's bow: where the own ship crosses the target's course line
    # (y = U tc), the target has already passed (is west of us): the own ship passes astern.
    p = SbmpcParams()
    pos, vel, _, t = predict_own(p, [0.0, 0.0], NORTH, U, NORTH, U)
    path, v_end = pos[d.index], vel[d.index, -1]
    if path[-1, 1] >= pt[1]:
        k = np.flatnonzero(path[:, 1] >= pt[1])[0]
        t_cross, x_cross = t[k], path[k, 0]
    else:  # beyond the horizon: the prediction holds its final velocity
        t_cross = t[-1] + (pt[1] - path[-1, 1]) / v_end[1]
        x_cross = path[-1, 0] + v_end[0] * (t_cross - t[-1])
    target_x = pt[0] + vt[0] * t_cross
    assert target_x < x_cross - p.d_safe  # target at least d_safe past the crossing point


def test_stand_on_keeps_course_while_far():
    tc = 25.0 * 60.0  # target from port (west) heading east, collision in 25 min
    vt = np.array([12.0 * KNOT, 0.0])
    d = _decide([[-12.0 * KNOT * tc, U * tc]], [vt])
    assert (d.course_offset, d.speed_factor) == (0.0, 1.0)
    assert d.active


def test_stand_on_acts_when_close_and_not_to_port():
    tc = 7.0 * 60.0  # give-way vessel has not acted; 7 min to collision
    vt = np.array([12.0 * KNOT, 0.0])
    d = _decide([[-12.0 * KNOT * tc, U * tc]], [vt])
    assert (d.course_offset, d.speed_factor) != (0.0, 1.0)
    assert d.course_offset <= 0.0  # Rule 17(c): no port turn for a vessel on our port side


def test_accepts_tracks_and_remembers_last_choice():
    s = Sbmpc()
    tr = Track(5, 0.0, np.array([0.0, 5.0 * NMI]), np.array([0.0, -6.0]), np.eye(4), 0.0, 3)
    d1 = s.decide([0.0, 0.0], NORTH, U, NORTH, U, [tr])
    assert s.last == (d1.course_offset, d1.speed_factor)
    # the change cost g makes keeping the previous choice cheaper than before
    p = SbmpcParams()
    first, _ = hazard(p, [0, 0], NORTH, U, NORTH, U, [[0, 5 * NMI]], [[0, -6]], (0.0, 1.0))
    again, _ = hazard(p, [0, 0], NORTH, U, NORTH, U, [[0, 5 * NMI]], [[0, -6]], s.last)
    assert again[d1.index] <= first[d1.index]


def test_scale_free_parameters_for_a_canal_boat():
    p = SbmpcParams.for_safety_distance(
        5.0, horizon_s=60.0, dt_s=0.5, course_time_constant_s=2.0, speed_time_constant_s=3.0
    )
    assert p.d_close == pytest.approx(5.0 * 3.0)
    s = Sbmpc(p)
    d = s.decide([0.0, 0.0], NORTH, 1.0, NORTH, 1.0, positions=[[0.0, 40.0]],
                 velocities=[[0.0, -1.0]])  # fmt: skip
    assert d.course_offset < 0.0
    assert d.min_distance >= 5.0


def test_prediction_follows_offset_course_and_speed():
    p = SbmpcParams()
    pos, vel, chi, t = predict_own(p, [100.0, 200.0], NORTH, U, NORTH, U)
    c, f = behaviours(p)
    k = np.flatnonzero(np.isclose(c, np.radians(-30.0)) & (f == 0.5))[0]
    assert chi[k, -1] == pytest.approx(NORTH - np.radians(30.0), abs=1e-6)
    assert np.hypot(*vel[k, -1]) == pytest.approx(0.5 * U, rel=1e-3)
    assert pos[k, 0] == pytest.approx([100.0, 200.0])


def test_roles_are_remembered_per_track_and_passed_targets_forgotten():
    s = Sbmpc()
    tr = Track(9, 0.0, np.array([0.0, 5.0 * NMI]), np.array([0.0, -6.0]), np.eye(4), 0.0, 3)
    s.decide([0.0, 0.0], NORTH, U, NORTH, U, [tr])
    assert s.roles[9][0]  # head-on
    # after our own 40° starboard turn the fresh geometry is no longer head-on; the role stays
    s.decide([0.0, 0.0], NORTH - np.radians(40.0), U, NORTH, U, [tr])
    assert s.roles[9][0]
    # the target has passed (opening) and is farther than d_close: ignored and forgotten
    gone = Track(9, 0.0, np.array([0.0, -2.0 * NMI]), np.array([0.0, -6.0]), np.eye(4), 0.0, 3)
    d = s.decide([0.0, 0.0], NORTH, U, NORTH, U, [gone])
    assert (d.course_offset, d.speed_factor, d.active) == (0.0, 1.0, False)
    assert 9 not in s.roles


def test_stand_on_release_needs_a_close_cpa_and_is_latched():
    p = SbmpcParams()
    tc = 7.0 * 60.0  # within the release time (0.6 × 900 s) ...
    vt = np.array([12.0 * KNOT, 0.0])
    collision = np.array([[-12.0 * KNOT * tc, U * tc]])
    v0 = np.array([0.0, U])
    assert stand_on_released(p, [0.0, 0.0], v0, collision, [vt])[0]
    # ... but a target that will pass 1.5 nmi ahead has not left us to act (Rule 17(a))
    passing = collision + [[0.0, 1.5 * NMI]]
    assert not stand_on_released(p, [0.0, 0.0], v0, passing, [vt])[0]
    # once released for a track, it stays released while the track is relevant
    s = Sbmpc()
    far = Track(7, 0.0, collision[0], vt, np.eye(4), 0.0, 3)
    s.decide([0.0, 0.0], NORTH, U, NORTH, U, [far])
    assert 7 in s.released
    later = Track(7, 0.0, collision[0] - vt * 600.0, vt, np.eye(4), 0.0, 3)  # tcpa now > 540 s
    s.decide([0.0, 0.0], NORTH, U, NORTH, U, [later])
    assert 7 in s.released


def test_no_behaviour_heads_to_port_of_the_route_before_a_head_on_cpa():
    # the own ship is right of its route: the guidance's LOS course points 30° to port of it
    route = NORTH
    s = Sbmpc()
    tr = Track(3, 0.0, np.array([30.0, 4.0 * NMI]), np.array([0.0, -12.0 * KNOT]), np.eye(4), 0, 3)
    d = s.decide([0.0, 0.0], NORTH, U, route + np.radians(30.0), U, [tr], path_course=route)
    commanded = route + np.radians(30.0) + d.course_offset
    assert np.degrees(commanded - route) <= SbmpcParams().port_limit_deg + 1e-9
    assert d.encounter_open


def _gw_crossing_track(position):
    """Track 5: a 12 kn target heading west, crossing from our starboard (give-way crossing)."""
    return Track(
        5, 0.0, np.asarray(position, float), np.array([-12.0 * KNOT, 0.0]), np.eye(4), 0, 3
    )


@pytest.mark.parametrize("hold", [True, False])
def test_port_limit_holds_until_the_target_is_past_and_clear_on_the_return_course(hold):
    route = NORTH
    s = Sbmpc(SbmpcParams(hold_until_clear=hold))
    d = s.decide(
        [0.0, 0.0], NORTH, U, NORTH, U, [_gw_crossing_track([NMI, NMI])], path_course=route
    )
    assert s.roles[5][1]  # give-way crossing from the first geometry
    # later: we are 30° to starboard of the route, the target is past its CPA on this course but
    # ahead of it on the guidance's return course (30° to port of the route): not yet clear
    tr = _gw_crossing_track([-1000.0, 1500.0])
    d = s.decide([0.0, 0.0], route - np.radians(30.0), U, route + np.radians(30.0), U, [tr],
                 path_course=route)  # fmt: skip
    port = np.degrees(route + np.radians(30.0) + d.course_offset - route)
    if hold:
        assert port <= SbmpcParams().port_limit_deg + 1e-9
        assert not s.duties[5][1]
    else:  # the older rule keeps no per-track duties
        assert s.duties == {}
    if hold:  # past on both courses: cleared (latched), the return to the route is free
        far = _gw_crossing_track([-2500.0, 1000.0])
        s.decide([0.0, 0.0], route, U, route + np.radians(30.0), U, [far], path_course=route)
        assert s.duties[5][1]


def test_an_unreleased_stand_on_ship_keeps_the_route_course():
    # a crossing target from port, far off: stand-on, not released; the ship is left of its route
    # so the guidance's LOS course points 30° to starboard of it: keep the route's course instead
    route = NORTH
    s = Sbmpc(SbmpcParams(hold_until_clear=True))
    tr = Track(6, 0.0, np.array([-3.0 * NMI, 3.0 * NMI]), np.array([12.0 * KNOT, 0.0]),
               np.eye(4), 0, 3)  # fmt: skip
    d = s.decide([0.0, 0.0], route, U, route - np.radians(30.0), U, [tr], path_course=route)
    assert s.roles[6][2] and 6 not in s.released
    heading = np.degrees(route - np.radians(30.0) + d.course_offset - route)
    assert abs(heading) <= SbmpcParams().port_limit_deg + 1e-9


def _track(tid, pos, vel):
    return Track(tid, 0.0, np.asarray(pos, float), np.asarray(vel, float), np.eye(4), 0.0, 3)


def test_stand_on_before_release_owes_no_crossing_ahead_cost():
    # A ship crossing from port, a little slower, on a near-collision course 15 min out: the own
    # ship is stand-on and not yet released (6.2 km, TCPA > 0.6 horizon), so it keeps course and
    # speed even though holding on passes ahead of the target's bow (Rule 17(a)(i)); the
    # crossing-ahead cost is the give-way ship's (Rule 15).
    tc = 900.0
    tgt = _track(4, [-0.9 * U * tc, U * tc], [0.9 * U, 0.0])
    d = Sbmpc().decide([0.0, 0.0], NORTH, U, NORTH, U, [tgt])
    assert d.active and (d.course_offset, d.speed_factor) == (0.0, 1.0)


def test_shallow_crossing_from_starboard_is_given_way_early():
    # Faster, 45° apart, from starboard: the paper's angles call it "overtaking us" (stand-on,
    # no collision cost until 1 nmi), DNV's sectors a give-way crossing; with duties held the
    # give-way reading wins and the own ship acts now, 2.5 nmi out.
    heading = NORTH + np.radians(45.0)  # towards north-west
    v = 1.3 * U * np.array([np.cos(heading), np.sin(heading)])
    tc = 900.0
    tgt = _track(5, np.array([0.0, U * tc]) - v * tc, v)
    held = Sbmpc().decide([0.0, 0.0], NORTH, U, NORTH, U, [tgt])
    assert held.course_offset < 0.0 or held.speed_factor < 1.0
    older = Sbmpc(SbmpcParams(hold_until_clear=False))
    off = older.decide([0.0, 0.0], NORTH, U, NORTH, U, [tgt])
    assert (off.course_offset, off.speed_factor) == (0.0, 1.0)  # the paper's roles stand on


def test_a_target_briefly_irrelevant_keeps_its_duty():
    # A give-way crossing target looks past its CPA for a moment (the own ship stopped and
    # pointing away) but not on the guidance's course: its role is kept, not re-classified.
    s = Sbmpc()
    tgt = _track(6, [3000.0, 3000.0], [-U, 0.0])  # from starboard, heading west
    s.decide([0.0, 0.0], NORTH, U, NORTH, U, [tgt])
    assert s.roles[6][1]  # give-way crossing
    s.decide([0.0, 0.0], -NORTH, 0.01, NORTH, U, [_track(6, [-1000.0, 3000.0], [-U, 0.0])])
    assert 6 in s.roles and s.roles[6][1]


def test_near_the_route_end_a_released_crossing_target_still_forbids_a_port_turn():
    # Released for a crossing target from port while on the route's course (7 min to a
    # collision). Later, near the route's end (stand-on targets no longer hold the course),
    # the ship is 30° to starboard and the target is past its CPA on that course but not on
    # the guidance's return course 30° to port: turning back would bring it closer again, so
    # the no-port-turn limit from the release course holds (Rule 17(c)).
    tc = 7.0 * 60.0
    vt = np.array([12.0 * KNOT, 0.0])
    s = Sbmpc()
    s.decide([0.0, 0.0], NORTH, U, NORTH, U, [_track(8, [-12.0 * KNOT * tc, U * tc], vt)],
             path_course=NORTH)  # fmt: skip
    assert 8 in s.released and s.roles[8][3]  # stand-on crossing, released
    starboard, back = NORTH - np.radians(30.0), NORTH + np.radians(30.0)
    d = s.decide([0.0, 0.0], starboard, U, back, U, [_track(8, [-800.0, -1000.0], vt)],
                 path_course=NORTH, hold_stand_on=False)  # fmt: skip
    port = np.degrees(back + d.course_offset - NORTH)
    assert port <= SbmpcParams().port_limit_deg + 1e-9


def test_the_prediction_ends_where_the_route_ends():
    """A target that will cross the own ship's course line 1.5 km ahead, 300 s from now: on
    a voyage that goes on, holding course meets it there and the SB-MPC turns away; with the
    route's end 600 m ahead (arrival radius 150 m) the ship is in before the target comes
    within the safety distance, so it holds course and speed."""
    target = dict(positions=[[1500.0, -1500.0]], velocities=[[0.0, 5.0]])
    on = Sbmpc(SbmpcParams()).decide([0, 0], 0.0, 5.0, 0.0, 5.0, **target)
    assert on.course_offset < 0.0 and on.min_distance < SbmpcParams().d_safe * 1.1
    ends = Sbmpc(SbmpcParams()).decide(
        [0, 0], 0.0, 5.0, 0.0, 5.0, **target, destination=(600.0, 0.0), arrival_radius=150.0
    )
    assert (ends.course_offset, ends.speed_factor) == (0.0, 1.0)
    assert ends.min_distance > SbmpcParams().d_safe  # until the arrival


def test_a_behaviour_that_keeps_the_required_cpa_wins_over_one_that_breaks_it():
    """DNV situation 19 at 305 s (rounded): a ship overtaking us from astern at 7.8 m/s, its
    stand-on duty released, and a slower ship ahead; the guidance pulls back to port. The
    relative-speed weight of C·R makes a pass at < 926 m from the overtaking ship cheaper than
    a wider starboard turn; the required CPA ranks first (``keep_required_cpa``)."""
    geometry = dict(
        position=[618.0, 1385.0], course=1.3208, speed=5.128, course_ref=2.1242, speed_ref=5.144,
        target_positions=[[692.0, 3501.0], [116.0, 246.0]],
        target_velocities=[[-0.80, 3.00], [-0.05, 7.77]],
        last=(np.radians(-45.0), 1.0),
        roles=[[False, False, False, False], [False, False, True, False]],
        released=[False, True],
    )  # fmt: skip
    cpa = SbmpcParams().cpa_required
    weighted, d_weighted = hazard(SbmpcParams(keep_required_cpa=False), **geometry)
    assert d_weighted[np.argmin(weighted)] < cpa  # the risk alone breaks the requirement
    guarded, d_guarded = hazard(SbmpcParams(), **geometry)
    assert d_guarded[np.argmin(guarded)] >= cpa
    assert np.any(d_weighted >= cpa)  # a behaviour that keeps it existed


def test_no_behaviour_keeps_the_required_cpa_the_guard_changes_nothing():
    # already 850 m abeam of a ship overtaking us: every behaviour passes nearer than 926 m
    geometry = dict(
        position=[0.0, 0.0], course=NORTH, speed=U, course_ref=NORTH, speed_ref=U,
        target_positions=[[-850.0, -300.0]], target_velocities=[[0.0, 6.0]],
    )  # fmt: skip
    off, d_off = hazard(SbmpcParams(keep_required_cpa=False), **geometry)
    on, _ = hazard(SbmpcParams(), **geometry)
    assert np.all(d_off < SbmpcParams().cpa_required)
    np.testing.assert_array_equal(off, on)


def test_near_the_route_end_slowing_down_beats_sailing_past_it():
    """DNV situation 18 at 1120 s (rounded): 4 km from the route's end, held 45° to starboard
    of the guidance's course by two ships it overtook. At full speed that course runs past the
    end along the last leg without coming within the arrival radius, where the guidance ends the
    voyage; the same offset at half speed does not get there within the horizon (``k_miss``)."""
    end = np.array([0.0, 9259.0])
    geometry = dict(
        position=[1218.0, 5466.0], course=1.6726, speed=5.143, course_ref=2.4541, speed_ref=5.144,
        target_positions=[[-97.0, 5452.0], [10.0, 5817.0]],
        target_velocities=[[-0.50, 3.52], [-1.08, 2.85]],
        last=(np.radians(-45.0), 1.0), roles=np.zeros((2, 4), bool), released=[True, True],
        destination=end, arrival_radius=150.0, end_leg_start=[0.0, 0.0],
    )  # fmt: skip
    chi, fac = behaviours(SbmpcParams())
    blind, _ = hazard(SbmpcParams(k_miss=0.0), **geometry)
    k = np.argmin(blind)
    assert fac[k] == 1.0 and chi[k] < 0.0  # full speed on a starboard offset ...
    g = geometry
    own_p, *_ = predict_own(
        SbmpcParams(), g["position"], g["course"], g["speed"], g["course_ref"], g["speed_ref"]
    )
    track = own_p[k]
    assert np.all(np.hypot(*(track - end).T) > 150.0) and np.any(track[:, 1] > end[1] + 150.0)
    seen, _ = hazard(SbmpcParams(), **geometry)  # ... runs past the end: slow down instead
    assert fac[np.argmin(seen)] < 1.0
    far = dict(geometry, destination=end + [0.0, 5000.0])  # beyond miss_range: no such cost
    np.testing.assert_array_equal(*(hazard(SbmpcParams(k_miss=m), **far)[0] for m in (0.0, 10.0)))
