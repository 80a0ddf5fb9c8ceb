"""The traffic-situation diagram (issue 37): its shells, its wiring (the autonomy sees the
targets only through AIS), and one DNV situation end to end through ``usvdrake encounter``."""

import dataclasses
import json

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator

from usvdrake.cli import main
from usvdrake.diagrams.encounter_diagram import (
    AUTONOMY,
    WORLD,
    build_encounter_diagram,
    own_ship_params,
    route_time,
    sbmpc_params,
)
from usvdrake.run.encounter import prepare, run_encounter, situation_paths
from usvdrake.systems.colav.route_los import advance_leg, arrived, los_course
from usvdrake.systems.colav.sbmpc import NMI
from usvdrake.systems.colav.sbmpc_colav import DIAGNOSTICS, SbmpcColav
from usvdrake.systems.colav.scaling import froude_scaled
from usvdrake.systems.colav.situation import DATA_DIR, load_situation, situation_files
from usvdrake.systems.colav.tracking import Track

KNOT = NMI / 3600.0
HEAD_ON = DATA_DIR / "traffic_situation_01.json"
THREE_TARGETS = DATA_DIR / "traffic_situation_27.json"


def _connections(diagram):
    """(receiving system name, input port name) → (sending system name, output port name)."""
    return {
        (si.get_name(), si.get_input_port(ii).get_name()): (
            so.get_name(),
            so.get_output_port(oi).get_name(),
        )
        for (si, ii), (so, oi) in diagram.connection_map().items()
    }


def test_the_standard_set_is_shipped():
    files = situation_files(DATA_DIR)
    assert [p.stem[-2:] for p in files] == [f"{k:02d}" for k in range(1, 41)]
    assert all(load_situation(p).targets for p in files[::13])


def test_route_los_steers_back_switches_legs_and_arrives():
    wps = np.array([[0.0, 0.0], [0.0, 5000.0], [5000.0, 5000.0]])
    # 100 m east (right) of a northbound leg: steer left of north, by atan(100 / 1000).
    assert los_course(wps, 0, [100.0, 1000.0], 1000.0) == pytest.approx(np.pi / 2 + np.arctan(0.1))
    assert advance_leg(wps, 0, [0.0, 4700.0], 250.0) == 0
    assert advance_leg(wps, 0, [0.0, 4800.0], 250.0) == 1
    assert advance_leg(wps, 1, [9000.0, 5000.0], 250.0) == 1  # the last leg stays active
    # Near the end but far abeam (after an avoidance manoeuvre): straight at the end.
    assert los_course(wps, 1, [4500.0, 5500.0], 1000.0) == pytest.approx(-np.pi / 4)
    assert arrived(wps, [4900.0, 5000.0], 150.0) and not arrived(wps, [4800.0, 5000.0], 150.0)


def test_froude_scaling_keeps_the_encounter():
    s = load_situation(THREE_TARGETS)
    k = 0.01
    m = froude_scaled(s, k, own_length=2.0, own_width=1.0)
    assert np.allclose(m.own_ship.xy, k * s.own_ship.xy)
    assert np.allclose(m.targets[1].xy, k * s.targets[1].xy)
    assert m.targets[1].speed0 == pytest.approx(np.sqrt(k) * s.targets[1].speed0)
    assert route_time(m) == pytest.approx(np.sqrt(k) * route_time(s))
    assert (m.own_ship.length, m.own_ship.width) == (2.0, 1.0)
    x, y = m.to_local(m.targets[0].lat[-1], m.targets[0].lon[-1])  # geodetic follows local
    assert np.hypot(x - m.targets[0].xy[-1, 0], y - m.targets[0].xy[-1, 1]) < 1e-3


def test_diagram_builds_with_its_ports():
    situation = load_situation(THREE_TARGETS)
    diagram = build_encounter_diagram(situation)
    for name in AUTONOMY + WORLD:
        assert diagram.HasSubsystemNamed(name)
    context = diagram.CreateDefaultContext()
    own = diagram.GetOutputPort("own_state").Eval(context)
    assert np.allclose(own[:2], situation.own_ship.xy[0])
    assert diagram.GetOutputPort("target_states").size() == 4 * len(situation.targets)
    diag = diagram.GetOutputPort("colav_diagnostics").Eval(context)
    assert len(diag) == len(DIAGNOSTICS) and diag[1] == 1.0  # factor 1 before any decision
    assert diagram.GetOutputPort("mission_complete").Eval(context)[0] == 0.0


@pytest.mark.parametrize("own", ["ship", "roboat2"])
def test_autonomy_has_no_path_to_the_targets_true_state(own):
    situation, config = prepare(THREE_TARGETS, own)
    diagram = build_encounter_diagram(situation, own, config)
    wires = _connections(diagram)
    assert wires[("sbmpc_colav", "tracks")] == ("ais_tracker", "tracks")
    assert wires[("ais_tracker", "ais_reports")] == ("ais_transponders", "ais_reports")
    assert wires[("ais_transponders", "target_states")] == ("target_ships", "target_states")
    for (receiver, _), (sender, _) in wires.items():
        if receiver in AUTONOMY:
            assert sender != "target_ships", receiver
    # Everything downstream of the true states, not passing the transponders: no autonomy.
    reached, frontier = set(), {"target_ships"}
    while frontier:
        sender = frontier.pop()
        for (receiver, _), (source, _) in wires.items():
            if source == sender and receiver != "ais_transponders" and receiver not in reached:
                reached.add(receiver)
                frontier.add(receiver)
    assert not reached & set(AUTONOMY), reached


def test_sbmpc_colav_keeps_the_return_to_the_route_shallow_while_an_encounter_is_open():
    path = np.pi / 2
    colav = SbmpcColav(period=5.0, max_return=np.radians(8.0))
    context = colav.CreateDefaultContext()
    colav.GetInputPort("state").FixValue(context, [500.0, 0.0, path, 10 * KNOT, 0.0, 0.0])
    # far right of the route, the LOS course pulls 40° to port of it
    colav.GetInputPort("nominal").FixValue(context, [path + np.radians(40.0), 10 * KNOT])
    colav.GetInputPort("path_course").FixValue(context, [path])
    track = Track(2, 0.0, np.array([600.0, 4 * NMI]), np.array([0.0, -10 * KNOT]), np.eye(4), 0, 3)
    colav.GetInputPort("tracks").FixValue(context, AbstractValue.Make([track]))
    Simulator(colav, context).AdvanceTo(0.1)
    values = colav.GetOutputPort("colav_diagnostics").Eval(context)
    diag = dict(zip(DIAGNOSTICS, values, strict=True))
    assert diag["encounter_open"] == 1.0
    course, _ = colav.GetOutputPort("command").Eval(context)
    assert np.degrees(course - path) <= 8.0 + 1e-9  # neither the pull nor the offset to port
    # with no target the guidance's full pull comes back
    colav.GetInputPort("tracks").FixValue(context, AbstractValue.Make([]))
    Simulator(colav, context).AdvanceTo(5.1)
    course, _ = colav.GetOutputPort("command").Eval(context)
    assert course == pytest.approx(path + np.radians(40.0))


def test_los_pulls_back_to_the_leg_by_the_lookahead_angle():
    wps = np.array([[0.0, 0.0], [0.0, 10_000.0]])
    free = los_course(wps, 0, [2000.0, 1000.0], 1000.0)
    assert np.degrees(free - np.pi / 2) == pytest.approx(np.degrees(np.arctan(2.0)))


def test_sbmpc_colav_turns_to_starboard_for_a_head_on_track():
    colav = SbmpcColav(period=5.0)
    context = colav.CreateDefaultContext()
    colav.GetInputPort("state").FixValue(context, [0.0, 0.0, np.pi / 2, 10 * KNOT, 0.0, 0.0])
    colav.GetInputPort("nominal").FixValue(context, [np.pi / 2, 10 * KNOT])
    track = Track(2, 0.0, np.array([30.0, 4 * NMI]), np.array([0.0, -10 * KNOT]), np.eye(4), 0, 3)
    colav.GetInputPort("tracks").FixValue(context, AbstractValue.Make([track]))
    Simulator(colav, context).AdvanceTo(0.1)  # the periodic update at t = 0
    values = colav.GetOutputPort("colav_diagnostics").Eval(context)
    diag = dict(zip(DIAGNOSTICS, values, strict=True))
    assert diag["active"] == 1.0 and diag["decisions"] == 1.0
    assert diag["offset"] < 0.0  # starboard: the course angle decreases
    course, speed = colav.GetOutputPort("command").Eval(context)
    assert course == pytest.approx(np.pi / 2 + diag["offset"])
    assert speed == pytest.approx(10 * KNOT * diag["factor"])


def test_state_lives_in_the_context():
    """A cloned context continues as the original: the tracker, the transponders and the
    SB-MPC (abstract state) are copied with it, not shared (a shared tracker would be advanced
    by both simulators). Equal to rounding: each simulator's integrator picks its own steps."""
    diagram = build_encounter_diagram(load_situation(HEAD_ON))
    sim = Simulator(diagram)
    sim.AdvanceTo(300.0)
    twin = Simulator(diagram, sim.get_context().Clone())
    sim.AdvanceTo(600.0)
    twin.AdvanceTo(600.0)
    for port in ("own_state", "track_states", "colav_diagnostics"):
        a = diagram.GetOutputPort(port).Eval(sim.get_context())
        b = diagram.GetOutputPort(port).Eval(twin.get_context())
        keep = slice(None, 5) if port == "colav_diagnostics" else slice(None)  # not decide_ms
        assert np.allclose(a[keep], b[keep], rtol=1e-6, atol=1e-3, equal_nan=True), port


def test_head_on_end_to_end_through_the_command(tmp_path, capsys):
    out = tmp_path / "ho"
    assert main(["encounter", str(HEAD_ON), "--out", str(out), "--quiet"]) == 0
    for name in ("encounter.json", "track.csv", "targets.csv", "encounter.png"):
        assert (out / name).stat().st_size > 0, name
    e = json.loads((out / "encounter.json").read_text())
    assert e["arrived"] and e["collisions"] == 0
    assert e["min_cpa_m"] >= 0.5 * NMI
    assert [t["encounter"] for t in e["targets"]] == ["HO"]
    header = (out / "track.csv").read_text().splitlines()[0]
    assert header == "t_s,lat_deg,lon_deg,heading_deg,sog_kn"
    printed = capsys.readouterr().out
    assert "HO" in printed and "compliant" in printed


def test_an_sbmpc_of_one_behaviour_holds_it():
    """``run_encounter(sbmpc=...)`` replaces the own ship's SB-MPC (bench/colav_reachability.py
    holds one behaviour this way): allowed only "keep course and speed", the head-on ship is
    run down; allowed only a 45° starboard turn, it is passed wide."""
    situation, cfg = prepare(HEAD_ON)
    base = sbmpc_params(own_ship_params(situation), cfg.safety_distance_m)
    cpa = {}
    for offset in (0.0, -45.0):
        one = dataclasses.replace(base, course_offsets_deg=(offset,), speed_factors=(1.0,))
        r = run_encounter(HEAD_ON, None, duration=1200.0, plot=False, sbmpc=one)
        (target,) = r["evaluation"].targets
        cpa[offset] = target.cpa_m
        assert r["evaluation"].collisions == (1 if offset == 0.0 else 0)
    assert cpa[0.0] < 100.0 < 0.5 * NMI < cpa[-45.0]


def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["encounter", str(tmp_path / "missing.json"), "--out", str(tmp_path)]) == 2
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    assert main(["encounter", str(broken), "--out", str(tmp_path)]) == 2
    assert main(["encounters", str(tmp_path / "none"), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and all(line.startswith("usvdrake: error:") for line in err)


def test_a_set_on_dask_writes_each_situation_and_the_summary(tmp_path, capsys):
    files = [str(DATA_DIR / f"traffic_situation_0{k}.json") for k in (2, 4)]
    out = tmp_path / "set"
    assert main(["encounters", *files, "--out", str(out), "--workers", "1", "--quiet"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["situations"] == 2 and not s["failed"] and s["collisions"] == 0
    assert [e["situation"] for e in s["entries"]] == [
        "traffic_situation_02",
        "traffic_situation_04",
    ]
    for stem in ("traffic_situation_02", "traffic_situation_04"):
        assert (out / stem / "encounter.json").is_file() and (
            out / stem / "encounter.png"
        ).is_file()
    printed = capsys.readouterr().out
    assert "02 CR-GW" in printed and "usvdrake encounters: 2 situations" in printed


def test_roboat2_as_own_ship_on_a_froude_scaled_head_on(tmp_path):
    r = run_encounter(HEAD_ON, tmp_path / "roboat", own="roboat2")
    e = r["evaluation"]
    assert r["length_scale"] == pytest.approx(2.0 / 122.0)  # Roboat II's 2 m hull / 122 m ship
    assert r["safety_distance_m"] == pytest.approx(0.5 * NMI * r["length_scale"])
    assert e.arrived and e.collisions == 0 and e.min_cpa_m >= r["safety_distance_m"]
    assert e.path_length_m < 200.0  # the 9.3 km route at 1/61 scale
    assert (tmp_path / "roboat" / "encounter.png").is_file()


def test_a_shipped_situation_is_found_by_its_name():
    assert situation_paths(["traffic_situation_01"]) == [DATA_DIR / "traffic_situation_01.json"]
    assert len(situation_paths([])) == 40  # the standard set
