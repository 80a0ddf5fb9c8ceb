"""Issue 37 items 7, 1, 6: the canal-scale situation set, traffic in a scenario, the Meshcat
replay of an encounter with every ship to scale."""

import dataclasses

import numpy as np
import pytest

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.diagrams.encounter_diagram import mission_traffic
from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.errors import ConfigError
from usvdrake.run.encounter import prepare, run_encounter, situation_paths
from usvdrake.run.mission import run_mission
from usvdrake.scenario import TrafficConfig, read_scenario, scenario_yaml, validate_scenario
from usvdrake.systems.colav.encounter import classify
from usvdrake.systems.colav.evaluation import traffic_metrics
from usvdrake.systems.colav.sbmpc import SbmpcParams, classify_sectors
from usvdrake.systems.colav.sbmpc import classify as classify_roles
from usvdrake.systems.colav.scaling import placed
from usvdrake.systems.colav.situation import (
    CANAL_DIR,
    load_encounter_settings,
    load_situation,
    settings_path_for,
)
from usvdrake.vessel import load_vessel
from usvdrake.viz.replay import drawn_paths

CANAL_01 = CANAL_DIR / "canal_situation_01.json"


def test_the_canal_set_is_roboat_scale_and_its_titles_match_the_geometry():
    files = situation_paths(["canal"])
    assert len(files) >= 20
    assert situation_paths(["canal_situation_07"]) == [CANAL_DIR / "canal_situation_07.json"]
    for path in files:
        s = load_situation(path)
        own = s.own_ship
        assert (own.length, own.width) == (2.0, 1.0)
        assert 0.9 < own.speed0 < 1.1  # ~1 m/s
        assert 1 <= len(s.targets) == len(s.target_titles) <= 3
        settings = load_encounter_settings(settings_path_for(path))
        for t, title in zip(s.targets, s.target_titles, strict=True):
            assert t.length <= 5.0 and t.speed0 <= 2.1  # canal boats at canal speeds
            got = classify(own.xy[0], own.psi0, own.speed0, t.xy[0], t.psi0, t.speed0,
                           settings, require_closing=False)  # fmt: skip
            assert got.value == title, (path.name, got, title)


def test_a_canal_situation_keeps_its_scale_and_gets_a_froude_scaled_config():
    situation, cfg = prepare(CANAL_01, "roboat2")
    k = 2.0 / 122.0
    assert situation.own_ship.xy == pytest.approx(load_situation(CANAL_01).own_ship.xy, abs=1e-6)
    assert cfg.safety_distance_m == pytest.approx(926.0 * k)
    assert cfg.length_scale == pytest.approx(k)
    assert cfg.ais_noise().position_m == pytest.approx(10.0 * k)
    # a DNV situation run with Roboat II ends at the same scale
    _, dnv = prepare(situation_paths(["traffic_situation_01"])[0], "roboat2")
    assert dnv.length_scale == pytest.approx(k) and dnv.safety_distance_m == cfg.safety_distance_m


def test_placed_moves_the_situation_rigidly_to_the_start_pose():
    s = load_situation(situation_paths(["canal_situation_16"])[0])
    x0, y0, psi0 = 30.0, -12.0, 1.0
    w = placed(s, x0, y0, psi0)
    assert w.own_ship.xy[0] == pytest.approx([x0, y0])
    assert w.own_ship.psi0 == pytest.approx(psi0)
    turn = psi0 - s.own_ship.psi0
    for a, b in zip(s.targets, w.targets, strict=True):
        rel_a = a.xy - s.own_ship.xy[0]
        rel_b = b.xy - w.own_ship.xy[0]
        assert np.linalg.norm(rel_b, axis=1) == pytest.approx(np.linalg.norm(rel_a, axis=1))
        ang = np.arctan2(rel_b[:, 1], rel_b[:, 0]) - np.arctan2(rel_a[:, 1], rel_a[:, 0])
        assert np.allclose(np.angle(np.exp(1j * (ang - turn))), 0.0, atol=1e-9)
        dpsi = np.angle(np.exp(1j * (b.psi0 - a.psi0 - turn)))
        assert abs(dpsi) < 1e-9  # every course turned with the frame


def test_traffic_metrics_finds_the_nearest_target_and_when():
    t = np.arange(5.0)
    own = np.column_stack([t, np.zeros(5)])
    # target 0 passes 3 m away at t = 2; target 1 stays 10 m away
    tgt = np.column_stack([
        t, np.full(5, 3.0), np.zeros(5), np.ones(5),
        t + 0.0, np.full(5, -10.0), np.zeros(5), np.ones(5),
    ])  # fmt: skip
    tgt[:, 0] = 2.0
    m = traffic_metrics(t, own, tgt)
    assert m["traffic_targets"] == 2
    assert m["traffic_min_distance_m"] == pytest.approx(3.0)
    assert m["traffic_min_distance_t_s"] == 2.0 and m["traffic_nearest_target"] == 0


def test_sector_roles_call_a_shallow_starboard_crossing_a_give_way_crossing():
    # own east at 1 m/s; a faster target from the south-south-west heading north-east, on our
    # starboard bow: the paper's angles see it overtaking us, DNV's sectors a crossing (CR-GW)
    v0 = np.array([1.0, 0.0])
    rel = np.array([[5.0, -83.0]])
    tv = 1.3 * np.array([[np.cos(np.pi / 4), np.sin(np.pi / 4)]])
    paper = classify_roles(SbmpcParams(), v0, rel, tv)
    sectors = classify_sectors(v0, rel, tv, 0.25)
    assert not paper[1][0] and paper[2][0]  # paper: stand-on (being overtaken)
    assert sectors[1][0] and not sectors[2][0]  # sectors: give-way crossing
    assert classify_roles(SbmpcParams(sector_roles=True), v0, rel, tv)[1][0]


def test_a_scenario_names_its_traffic_and_refuses_an_unknown_one(tmp_path):
    base = read_scenario("canal_demo")
    yaml = tmp_path / "with_traffic.yaml"
    s = dataclasses.replace(base, traffic=TrafficConfig(situation="canal_situation_02"))
    yaml.write_text(scenario_yaml(s))
    assert load_scenario(str(yaml)).traffic.situation == "canal_situation_02"
    bad = dataclasses.replace(base, traffic=TrafficConfig(situation="no_such_situation"))
    with pytest.raises(ConfigError, match="traffic.situation"):
        validate_scenario(bad)


def test_a_mission_meets_traffic_tracks_it_and_measures_the_nearest_pass(tmp_path):
    scenario = with_overrides(load_scenario("canal_demo"), duration=6.0, seed=0)
    scenario = dataclasses.replace(scenario, traffic=TrafficConfig(situation="canal_situation_06"))
    vessel = load_vessel(scenario.vessel)
    diagram = build_vessel_diagram(scenario, vessel=vessel)
    for port in ("target_states", "tracks", "track_states"):
        assert diagram.HasOutputPort(port)
    context = diagram.CreateDefaultContext()
    truth = diagram.GetOutputPort("target_states").Eval(context).reshape(-1, 4)
    world = mission_traffic("canal_situation_06", vessel, scenario.initial_state)
    assert truth[:, :2] == pytest.approx(np.array([t.xy[0] for t in world.targets]))
    result = run_mission(scenario, out_dir=tmp_path, record=False)
    m = result.metrics
    assert m["traffic_targets"] == 2
    # independently: the targets' planned states at the logged times against the vessel's
    d = [
        np.hypot(*(np.concatenate(t.state_at(ti))[:2] - q[:2]))
        for ti, q in zip(result.times, result.states, strict=True)
        for t in world.targets
    ]
    assert m["traffic_min_distance_m"] == pytest.approx(min(d), rel=1e-9)
    # the tracker has tracks by the end (AIS every second)
    assert "traffic_min_distance_m" in (tmp_path / "metrics.json").read_text()


def test_the_encounter_replay_draws_every_ship_and_animates(tmp_path):
    r = run_encounter(CANAL_01, tmp_path, duration=20.0, own="roboat2", replay=True, plot=False)
    html = (tmp_path / "replay.html").read_text()
    data = drawn_paths(html)
    assert r["files"]["replay.html"] == tmp_path / "replay.html"
    for path in (b"/encounter/own/ship/hull", b"/encounter/own/ship/safety",
                 b"/encounter/targets/2/ship/hull", b"/encounter/targets/2/track",
                 b"/encounter/route"):  # fmt: skip
        assert path in data, path
    assert b"set_animation" in data
