"""Encounter evaluation on hand-made cases whose verdict is known (issue 37) — plain numpy."""

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from usvdrake.systems.colav.encounter import EncounterType, cpa, track_cpa
from usvdrake.systems.colav.evaluation import (
    ColregParams,
    ShipTrack,
    evaluate_situation,
    evaluate_target,
    evaluate_traffic_situation,
    geodetic_columns,
    summarize,
    write_json,
    write_situation_outputs,
    write_targets_csv,
    write_track_csv,
)
from usvdrake.systems.colav.hull import Hull, first_collision, hull_corners, polygons_overlap
from usvdrake.systems.colav.situation import (
    DATA_DIR,
    load_encounter_settings,
    load_situation,
    situation_files,
)

SETTINGS = load_encounter_settings()
HULL = Hull(100.0, 16.0)
T = np.arange(0.0, 1601.0, 1.0)  # [s]
NORTH, EAST, SOUTH, WEST = np.pi / 2, 0.0, -np.pi / 2, np.pi


def track(x0, y0, psi0, v0, turn_at=None, turn_deg=0.0, rate_deg=2.0, speed_at=None, v1=None):
    """A track starting at (x0, y0) with heading ψ0 and speed v0 that turns by ``turn_deg``
    (> 0 port, < 0 starboard) at ``rate_deg``/s from ``turn_at`` and changes speed to ``v1`` at
    ``speed_at`` (Euler integration at the 1 s samples)."""
    psi = np.full_like(T, psi0)
    if turn_at is not None:
        done = np.clip((T - turn_at) * rate_deg, 0.0, abs(turn_deg))
        psi = psi0 + np.sign(turn_deg) * np.radians(done)
    v = np.full_like(T, v0)
    if speed_at is not None:
        v = np.where(T >= speed_at, v1, v0)
    dt = np.diff(T, prepend=T[0])
    x = x0 + np.cumsum(v * np.cos(psi) * dt)
    y = y0 + np.cumsum(v * np.sin(psi) * dt)
    return ShipTrack(T, x, y, psi, v)


def judge(own, tgt, **kw):
    return evaluate_target(own, tgt, HULL, HULL, SETTINGS, ColregParams(), target_id=7, **kw)


# --------------------------------------------------------------------------- CPA, hulls


def test_cpa_closed_form_matches_brute_force():
    rng = np.random.default_rng(3)
    ts = np.linspace(-2000.0, 2000.0, 400001)
    for _ in range(20):
        p_o, p_t = rng.uniform(-5000, 5000, (2, 2))
        v_o, v_t = rng.uniform(-8, 8, (2, 2))
        d, tc = cpa(p_o, v_o, p_t, v_t)
        dist = np.linalg.norm((p_t - p_o) + np.outer(ts, v_t - v_o), axis=1)
        k = int(np.argmin(dist))
        assert d == pytest.approx(dist[k], abs=1e-3)
        assert tc == pytest.approx(ts[k], abs=0.02)
    # No relative motion: the present range at TCPA 0; arrays broadcast.
    assert cpa((0, 0), (1, 1), (3, 4), (1, 1)) == (5.0, 0.0)
    d, tc = cpa(np.zeros((3, 2)), np.zeros((3, 2)), [[10, 0], [0, 10], [5, 5]], [[-1, 0]] * 3)
    assert np.allclose(d, [0.0, 10.0, 5.0]) and np.allclose(tc, [10.0, 0.0, 5.0])


def test_track_cpa_between_coarse_samples():
    t = np.arange(0.0, 1000.0, 37.0)  # coarse, the CPA falls between samples
    own = np.column_stack([np.zeros_like(t), 5.0 * t])
    tgt = np.column_stack([300.0 + 0.0 * t, 4000.0 - 4.0 * t])
    d, tc = track_cpa(t, own, tgt)
    d_ref, tc_ref = cpa((0, 0), (0, 5), (300, 4000), (0, -4))
    assert d == pytest.approx(d_ref, abs=1e-9) and tc == pytest.approx(tc_ref, abs=1e-9)


def test_hull_overlap_separating_axes():
    a = hull_corners(HULL, 0.0, 0.0, NORTH)
    assert polygons_overlap(a, hull_corners(HULL, 0.0, 0.0, EAST))[0]  # a cross
    assert not polygons_overlap(a, hull_corners(HULL, 17.0, 0.0, NORTH))[0]  # side by side
    assert polygons_overlap(a, hull_corners(HULL, 15.0, 0.0, NORTH))[0]
    # Diamond off the corner: the bounding circles overlap, the outlines do not.
    assert not polygons_overlap(a, hull_corners(Hull(20, 20), 22.0, 64.0, np.pi / 4))[0]
    # Antenna offsets: the bow 90 m ahead of the reference point.
    off = Hull(100.0, 16.0, a=90.0, b=10.0, c=8.0, d=8.0)
    c = hull_corners(off, 0.0, 0.0, NORTH)[0]
    assert c[:, 1].max() == pytest.approx(90.0) and c[:, 1].min() == pytest.approx(-10.0)


def test_collision_found_between_coarse_samples():
    # A fast crossing sampled every 20 s: the hulls overlap only for ~3 s around t = 100 s.
    t = np.arange(0.0, 201.0, 20.0)
    own = (np.zeros_like(t), 10.0 * t - 1000.0 + 3.0, np.full_like(t, NORTH))
    tgt = (1000.0 - 10.0 * t, np.zeros_like(t), np.full_like(t, WEST))
    hit = first_collision(t, own, HULL, tgt, HULL)
    assert hit is not None and 90.0 < hit < 100.0
    miss = (1000.0 - 10.0 * t, np.full_like(t, 200.0), np.full_like(t, WEST))
    assert first_collision(t, own, HULL, miss, HULL) is None


# ------------------------------------------------------------------------------- head-on


def head_on_target():
    return track(0.0, 8000.0, SOUTH, 5.0)


def test_head_on_course_held_is_a_collision():
    e = judge(track(0.0, 0.0, NORTH, 5.0), head_on_target())
    assert e.encounter == "HO" and e.role == "give-way" and e.t_start_s == 0.0
    assert e.collision and e.cpa_m == pytest.approx(0.0, abs=1e-6)
    assert e.t_cpa_s == pytest.approx(800.0) and e.t_collision_s < 800.0
    assert not e.compliant and e.action_required
    assert any("collision" in r for r in e.reasons)
    assert any("no readily apparent action" in r for r in e.reasons)


def test_head_on_early_starboard_turn_30_is_compliant():
    own = track(0.0, 0.0, NORTH, 5.0, turn_at=60.0, turn_deg=-30.0)
    e = judge(own, head_on_target())
    assert e.encounter == "HO" and not e.collision
    assert e.compliant, e.reasons
    assert e.max_starboard_deg == pytest.approx(30.0) and e.max_port_deg == 0.0
    assert e.cpa_m > 926.0 and e.t_action_s < 100.0 and e.range_at_action_m > 7000.0


def test_head_on_port_turn_is_non_compliant():
    own = track(0.0, 0.0, NORTH, 5.0, turn_at=60.0, turn_deg=30.0)
    e = judge(own, head_on_target())
    assert not e.collision and e.cpa_m > 926.0  # safe, but against Rule 14
    assert not e.compliant
    assert any("port" in r and "Rule 14" in r for r in e.reasons)


def test_head_on_late_starboard_turn_is_non_compliant():
    own = track(0.0, 0.0, NORTH, 5.0, turn_at=720.0, turn_deg=-60.0, rate_deg=3.0)
    e = judge(own, head_on_target())
    assert not e.compliant and any("late" in r for r in e.reasons)


# ------------------------------------------------------------------------------ crossing


def crossing_from_starboard():
    return track(4000.0, 4000.0, WEST, 5.0)  # meets the own ship at (0, 4000) at t = 800 s


def test_crossing_give_way_passing_astern_is_compliant():
    for own in (
        track(0.0, 0.0, NORTH, 5.0, turn_at=30.0, turn_deg=-90.0),  # hard to starboard
        track(0.0, 0.0, NORTH, 5.0, speed_at=30.0, v1=2.5),  # halve the speed
    ):
        e = judge(own, crossing_from_starboard())
        assert e.encounter == "CR-GW" and not e.collision and not e.crossed_ahead
        assert e.compliant, e.reasons


def slowing(t0: float, v0=5.0, v1=2.4, tau=200.0) -> ShipTrack:
    """Heading north at v0, ordered to v1 at t0: the speed decays towards it with time
    constant tau, as a ship's does (it takes ~650 s to lose half of it here)."""
    v = np.where(T >= t0, v1 + (v0 - v1) * np.exp(-np.maximum(T - t0, 0.0) / tau), v0)
    y = np.cumsum(v * np.diff(T, prepend=T[0]))
    return ShipTrack(T, np.zeros_like(T), y, np.full_like(T, NORTH), v)


def test_give_way_slowing_down_is_dated_from_its_onset():
    """Rule 16 asks for early action; Rule 8(b) for one large enough to be seen. A slow-down
    ordered at 30 s passes the 20 % tolerance at ~130 s and reaches 50 % only at ~680 s, less
    than 300 s before the CPA: the action is early (dated from ~130 s) and
    readily apparent (t_apparent_s). A quicker slow-down ordered at 560 s is late: dating from
    the onset does not excuse an order given late."""
    early = judge(slowing(30.0), crossing_from_starboard())
    assert early.encounter == "CR-GW" and early.compliant, early.reasons
    assert early.t_action_s == pytest.approx(30.0 + 200.0 * np.log(2.6 / 1.6), abs=1.5)
    assert early.t_apparent_s == pytest.approx(30.0 + 200.0 * np.log(2.6 / 0.1), abs=1.5)
    assert early.t_cpa_s - early.t_apparent_s < ColregParams().early_time_s  # the old dating
    late = judge(slowing(560.0, tau=40.0), crossing_from_starboard())
    assert late.t_action_s == pytest.approx(560.0 + 40.0 * np.log(2.6 / 1.6), abs=1.5)
    assert not late.compliant and any("late" in r for r in late.reasons)


def test_crossing_ahead_of_give_way_target_is_non_compliant():
    own = track(0.0, 0.0, NORTH, 5.0, speed_at=30.0, v1=9.0)  # speeds up to cross its bow
    e = judge(own, crossing_from_starboard())
    assert e.encounter == "CR-GW" and not e.collision
    assert e.crossed_ahead and not e.compliant
    assert any("crossed ahead" in r for r in e.reasons)


def crossing_from_port(gives_way: bool):
    if gives_way:  # the target turns 60° to starboard early and passes astern of the own ship
        return track(-4000.0, 4000.0, EAST, 5.0, turn_at=60.0, turn_deg=-60.0)
    return track(-4000.0, 4000.0, EAST, 5.0)


def test_stand_on_keeping_course_is_compliant():
    e = judge(track(0.0, 0.0, NORTH, 5.0), crossing_from_port(gives_way=True))
    assert e.encounter == "CR-SO" and e.role == "stand-on"
    assert not e.collision and e.compliant, e.reasons


def test_stand_on_turning_early_to_port_is_non_compliant():
    own = track(0.0, 0.0, NORTH, 5.0, turn_at=30.0, turn_deg=30.0)
    e = judge(own, crossing_from_port(gives_way=True))
    assert e.encounter == "CR-SO" and not e.compliant
    assert any("did not keep course" in r for r in e.reasons)


def test_stand_on_acting_once_give_way_clearly_is_not():
    # The target holds on; the own ship keeps course until the give-way ship is clearly not
    # acting (10 min before the predicted collision, t = 200 s), then turns hard to starboard.
    own = track(0.0, 0.0, NORTH, 5.0, turn_at=420.0, turn_deg=-90.0, rate_deg=3.0)
    e = judge(own, crossing_from_port(gives_way=False))
    assert e.encounter == "CR-SO" and not e.collision
    assert e.compliant, e.reasons
    # Turning to port for a ship on the own port side is against Rule 17(c), even then.
    own = track(0.0, 0.0, NORTH, 5.0, turn_at=420.0, turn_deg=90.0, rate_deg=3.0)
    e = judge(own, crossing_from_port(gives_way=False))
    assert not e.compliant and any("17(c)" in r for r in e.reasons)


# ---------------------------------------------------------------------------- overtaking


def test_overtaking_give_way_may_pass_either_side():
    tgt = track(0.0, 2000.0, NORTH, 2.0)
    for turn in (-30.0, 30.0):
        own = track(0.0, 0.0, NORTH, 6.0, turn_at=20.0, turn_deg=turn)
        e = judge(own, tgt)
        assert e.encounter == "OT-GW" and not e.collision
        assert e.compliant, e.reasons
    e = judge(track(0.0, 0.0, NORTH, 6.0), tgt)
    assert e.collision and not e.compliant


def test_no_risk_is_safe_and_compliant():
    e = judge(track(0.0, 0.0, NORTH, 5.0), track(3000.0, -3000.0, SOUTH, 5.0))
    assert e.encounter == EncounterType.SAFE.value and e.role == "none" and e.compliant


# ------------------------------------------------------------------ situation and outputs


def test_situation_02_course_held_collides_and_outputs(tmp_path):
    sit = load_situation(DATA_DIR / "traffic_situation_02.json")
    t = np.arange(0.0, 1800.0, 2.0)  # the own route takes 1800 s
    own = ShipTrack.from_ship(sit.own_ship, t)
    targets = {s.id: (ShipTrack.from_ship(s, t), Hull.from_ship(s)) for s in sit.targets}
    ev = evaluate_situation(
        "traffic_situation_02",
        sit.title,
        own,
        Hull.from_ship(sit.own_ship),
        targets,
        SETTINGS,
        sit.own_ship.xy,
    )
    (te,) = ev.targets
    assert te.encounter == "CR-GW" and te.collision and not te.compliant
    assert ev.collisions == 1 and ev.encounters == 1 and ev.compliant == 0
    assert ev.arrived and ev.path_ratio == pytest.approx(1.0, abs=2e-3)
    summary = summarize([ev])
    assert summary["situations"] == 1 and summary["collisions"] == 1
    assert summary["colreg_compliance"] == 0.0 and summary["arrived"] == 1
    assert summary["min_cpa_m"] < 50.0 and summary["entries"][0]["encounters"] == ["CR-GW"]
    write_json(tmp_path / "summary.json", summary)
    write_json(tmp_path / "encounter.json", ev)
    assert json.loads((tmp_path / "encounter.json").read_text())["targets"][0]["collision"]

    cols = geodetic_columns(sit, own)
    write_track_csv(tmp_path / "track.csv", *cols)
    write_targets_csv(
        tmp_path / "targets.csv",
        {tid: geodetic_columns(sit, tr) for tid, (tr, _) in targets.items()},
    )
    rows = list(csv.reader((tmp_path / "track.csv").open()))
    assert rows[0] == ["t_s", "lat_deg", "lon_deg", "heading_deg", "sog_kn"]
    first = [float(v) for v in rows[1]]
    wp = sit.own_ship
    assert first[1:3] == pytest.approx([wp.lat[0], wp.lon[0]], abs=1e-7)
    assert first[3] == pytest.approx(wp.heading_deg, abs=0.5) and first[4] == pytest.approx(10.0)
    rows = list(csv.reader((tmp_path / "targets.csv").open()))
    assert rows[0] == ["id", "t_s", "lat_deg", "lon_deg", "heading_deg", "sog_kn"]
    tgt = sit.targets[0]
    assert int(rows[1][0]) == tgt.id
    assert [float(v) for v in rows[1][2:4]] == pytest.approx([tgt.lat[0], tgt.lon[0]], abs=1e-7)


def test_stand_on_deviation_excused_while_giving_way_to_another_target():
    # Target A crosses from port (own is stand-on), B comes head-on (own gives way): the
    # starboard turn for B must not count against the stand-on duty to A.
    own = track(0.0, 0.0, NORTH, 5.0, turn_at=30.0, turn_deg=-30.0)
    a = crossing_from_port(gives_way=True)
    b = head_on_target()
    alone = judge(own, a)
    assert not alone.compliant
    route = np.array([[0.0, 0.0], [0.0, 9000.0]])
    ev = evaluate_situation(
        "multi", "CR-SO, HO", own, HULL, {1: (a, HULL), 2: (b, HULL)}, SETTINGS, route
    )
    by_id = {t.target_id: t for t in ev.targets}
    assert by_id[1].encounter == "CR-SO" and by_id[2].encounter == "HO"
    assert by_id[2].compliant and by_id[1].compliant, by_id[1].reasons
    assert ev.encounters == 2 and ev.compliant == 2


def test_stand_on_deviation_excused_after_another_stand_on_release_only():
    # A crosses from port far out and gives way; B crosses from port nearer and holds on, so
    # the own ship (stand-on to both) may act for B once B is clearly not acting (Rule
    # 17(a)(ii)). That action must not count against the duty to keep course for A; the same
    # turn before B's release still does.
    a = track(-6000.0, 6000.0, EAST, 5.0, turn_at=60.0, turn_deg=-60.0)
    b = crossing_from_port(gives_way=False)
    route = np.array([[0.0, 0.0], [0.0, 9000.0]])
    for turn_at, ok in ((420.0, True), (30.0, False)):
        own = track(0.0, 0.0, NORTH, 5.0, turn_at=turn_at, turn_deg=-90.0, rate_deg=3.0)
        assert not judge(own, a).compliant
        ev = evaluate_situation(
            "two", "CR-SO, CR-SO", own, HULL, {1: (a, HULL), 2: (b, HULL)}, SETTINGS, route
        )
        by_id = {t.target_id: t for t in ev.targets}
        assert by_id[1].encounter == by_id[2].encounter == "CR-SO"
        if ok:  # held on until 10 min before the predicted collision (t = 200 s)
            assert by_id[2].t_release_s == pytest.approx(200.0, abs=10.0)
        assert by_id[1].compliant is ok, (turn_at, by_id[1].reasons)
        assert by_id[2].compliant is ok, (turn_at, by_id[2].reasons)


SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "traffic_situations"


@pytest.mark.skipif(not SHARED.is_dir(), reason="no ../shared/data/traffic_situations")
def test_standard_set_with_courses_held_collides_everywhere():
    # Every encounter of the standard set is on a collision course: with no avoidance at all
    # each target is classified as its title says, collides, and is judged non-compliant.
    evals = []
    t = np.arange(0.0, 1800.0, 2.0)
    for p in situation_files(SHARED):
        sit = load_situation(p)
        own = ShipTrack.from_ship(sit.own_ship, t)
        tgts = {s.id: (ShipTrack.from_ship(s, t), Hull.from_ship(s)) for s in sit.targets}
        ev = evaluate_situation(
            p.stem, sit.title, own, Hull.from_ship(sit.own_ship), tgts, SETTINGS, sit.own_ship.xy
        )
        assert tuple(e.encounter for e in ev.targets) == sit.target_titles, p.name
        assert all(e.collision and not e.compliant for e in ev.targets), p.name
        evals.append(ev)
    s = summarize(evals)
    assert s["situations"] == 40 and s["collisions"] == s["encounters"] == 95
    assert s["colreg_compliance"] == 0.0 and s["arrived"] == 40


def test_situation_helpers_write_the_three_outputs(tmp_path):
    sit = load_situation(DATA_DIR / "traffic_situation_04.json")
    t = np.arange(0.0, 1800.0, 5.0)
    own = ShipTrack.from_ship(sit.own_ship, t)
    targets = {s.id: ShipTrack.from_ship(s, t) for s in sit.targets}
    ev = evaluate_traffic_situation(sit, own, targets, SETTINGS)
    assert ev.situation == "traffic_situation_04" and ev.targets[0].encounter == "OT-GW"
    out = write_situation_outputs(tmp_path / "s04", sit, own, targets, ev)
    assert sorted(p.name for p in out.iterdir()) == ["encounter.json", "targets.csv", "track.csv"]
    doc = json.loads((out / "encounter.json").read_text())
    assert doc["title"] == "OT-GW" and doc["targets"][0]["role"] == "give-way"
    assert len((out / "track.csv").read_text().splitlines()) == len(t) + 1
