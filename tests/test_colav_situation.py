"""Reading DNV trafficgen traffic situations and classifying their encounters (plain numpy)."""

import json
from pathlib import Path

import numpy as np
import pytest

from usvdrake.errors import ConfigError
from usvdrake.systems.colav.encounter import (
    EncounterType,
    classify,
    classify_bearings,
    relative_bearings,
)
from usvdrake.systems.colav.situation import (
    DATA_DIR,
    DEFAULT_SETTINGS_PATH,
    KNOT,
    heading_deg_true_to_psi,
    knots_to_mps,
    load_encounter_settings,
    load_situation,
    mps_to_knots,
    parse_situation,
    psi_to_heading_deg_true,
    situation_files,
)

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data" / "traffic_situations"
SETTINGS = load_encounter_settings()


def _classify_at_start(sit):
    own = sit.own_ship
    return [
        classify(own.xy[0], own.psi0, own.speed0, t.xy[0], t.psi0, t.speed0, SETTINGS)
        for t in sit.targets
    ]


def test_unit_conversions():
    assert heading_deg_true_to_psi(0.0) == pytest.approx(np.pi / 2)  # north
    assert heading_deg_true_to_psi(90.0) == pytest.approx(0.0)  # east
    assert heading_deg_true_to_psi(180.0) == pytest.approx(-np.pi / 2)
    assert abs(heading_deg_true_to_psi(270.0)) == pytest.approx(np.pi)
    h = np.linspace(0.0, 359.0, 50)
    assert np.allclose(psi_to_heading_deg_true(heading_deg_true_to_psi(h)), h)
    assert psi_to_heading_deg_true(np.pi / 2) == pytest.approx(0.0)
    assert psi_to_heading_deg_true(-np.pi / 2) == pytest.approx(180.0)
    assert knots_to_mps(10.0) == pytest.approx(5.144444, abs=1e-6)
    assert mps_to_knots(knots_to_mps(np.array([1.0, 12.1])))[1] == pytest.approx(12.1)
    assert KNOT == pytest.approx(1852 / 3600)


def test_settings_default_copy_matches_trafficgen():
    s = load_encounter_settings()
    assert s.source == DEFAULT_SETTINGS_PATH
    assert (s.theta13_criteria, s.theta14_criteria, s.theta15_criteria) == (67.5, 5.0, 5.0)
    assert s.theta15 == (112.5, 247.5)
    assert s.relative_speed["overtakingStandOn"] == (1.5, 2.0)
    assert s.situation_length == 30.0


def test_situation_01_head_on():
    sit = load_situation(DATA_DIR / "traffic_situation_01.json")
    assert sit.title == "HO" and sit.target_titles == ("HO",)
    own, (tgt,) = sit.own_ship, sit.targets
    assert own.name == "BASTO VI" and own.mmsi == 257847600 and own.id == 1
    assert (own.length, own.width, own.a, own.b, own.c, own.d) == (122, 20, 61, 61, 10, 10)
    assert own.heading_deg == 0.0 and own.psi0 == pytest.approx(np.pi / 2)
    assert own.speed0 == pytest.approx(10 * KNOT)
    assert np.allclose(own.xy[0], 0.0, atol=1e-6)  # origin at the own ship's first waypoint
    # Due north 0.0831234° of latitude ≈ 9259 m.
    assert own.xy[1, 0] == pytest.approx(0.0, abs=1e-3)
    assert own.xy[1, 1] == pytest.approx(9259.3, abs=1.0)
    assert own.route_length() == pytest.approx(9259.3, abs=1.0)
    # Target ahead (≈ 10.2 km north, a little east), heading ≈ south.
    assert tgt.mmsi is None and tgt.length == 50.0
    assert tgt.xy[0, 1] > 10000 and abs(tgt.xy[0, 0]) < 500
    assert tgt.psi0 == pytest.approx(heading_deg_true_to_psi(183.63))
    assert sit.start_time is None and sit.source.name == "traffic_situation_01.json"
    # Back to geodetic.
    lat, lon = sit.to_geodetic(*tgt.xy[0])
    assert (lat, lon) == pytest.approx((58.85500037, 10.49680582), abs=1e-8)


def test_ship_state_follows_waypoints():
    sit = load_situation(DATA_DIR / "traffic_situation_01.json")
    own = sit.own_ship
    x, y, psi, v = own.state_at([0.0, 100.0, 1e6])
    assert y[1] == pytest.approx(100 * 10 * KNOT, rel=1e-6)
    assert np.allclose(psi, np.pi / 2) and np.allclose(v, 10 * KNOT)
    assert y[2] > own.xy[1, 1]  # keeps going past the last waypoint


def test_shipped_situations_classify_as_titled():
    files = situation_files(DATA_DIR)
    assert [p.stem[-2:] for p in files] == [f"{i:02d}" for i in range(1, 41)]  # DNV's whole set
    for p in files:
        sit = load_situation(p)
        got = tuple(e.value for e in _classify_at_start(sit))
        assert got == sit.target_titles, p.name
    assert len(load_situation(DATA_DIR / "traffic_situation_27.json").targets) == 3


@pytest.mark.skipif(not SHARED.is_dir(), reason="no ../shared/data/traffic_situations")
def test_all_40_standard_situations():
    files = situation_files(SHARED)
    assert len(files) == 40
    for k, p in enumerate(files, start=1):
        sit = load_situation(p)
        n_expected = 1 if k <= 5 else 2 if k <= 20 else 3
        assert len(sit.targets) == n_expected, p.name
        assert np.allclose(sit.own_ship.xy[0], 0.0, atol=1e-6)
        assert sit.own_ship.length == 122.0
        got = tuple(e.value for e in _classify_at_start(sit))
        assert got == sit.target_titles, p.name


def test_bearing_sectors():
    s = SETTINGS
    # Own at origin heading north (ψ = π/2).
    north = np.pi / 2
    beta, alpha = relative_bearings((0, 0), north, (0, 1000), -north)
    assert (beta, alpha) == pytest.approx((0.0, 0.0))
    assert classify_bearings(beta, alpha, s) is EncounterType.HEAD_ON
    # Target to starboard (east) heading west: crossing, own gives way.
    beta, alpha = relative_bearings((0, 0), north, (1000, 1000), np.pi)
    assert beta == pytest.approx(45.0) and alpha == pytest.approx(-45.0)
    assert classify_bearings(beta, alpha, s) is EncounterType.CROSSING_GIVE_WAY
    # Mirror: target to port heading east → stand-on.
    assert classify((0, 0), north, 5, (-1000, 1000), 0.0, 5, s) is EncounterType.CROSSING_STAND_ON
    # Slower target ahead on the same course → own overtakes (gives way).
    assert classify((0, 0), north, 5, (0, 1000), north, 2, s) is EncounterType.OVERTAKING_GIVE_WAY
    # Faster target astern on the same course → it overtakes us.
    assert classify((0, 0), north, 5, (0, -1000), north, 8, s) is EncounterType.OVERTAKING_STAND_ON
    # The same geometry with the range opening is no risk.
    assert classify((0, 0), north, 5, (0, -1000), north, 2, s) is EncounterType.SAFE
    # Reciprocal but 20° off the bow: not head-on (θ14 = 5°) → crossing give-way.
    beta, alpha = 20.0, -20.0
    assert classify_bearings(beta, alpha, s) is EncounterType.CROSSING_GIVE_WAY
    assert classify_bearings(-20.0, 20.0, s) is EncounterType.CROSSING_STAND_ON
    # Target abeam to starboard on a parallel course: crossing by geometry alone (trafficgen),
    # no risk once the (constant) range is taken into account.
    assert classify_bearings(90.0, -90.0, s) is EncounterType.CROSSING_GIVE_WAY
    assert classify((0, 0), north, 5, (1000, 0), north, 5, s) is EncounterType.SAFE
    # Target astern, on a crossing course well abaft the beam, heading away: no situation.
    assert classify_bearings(180.0, 90.0, s) is EncounterType.SAFE
    assert EncounterType.HEAD_ON.give_way and EncounterType.OVERTAKING_STAND_ON.stand_on
    assert EncounterType.SAFE.role == "none"


def _write(tmp_path, doc, name="s.json"):
    p = tmp_path / name
    p.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return p


def test_tolerant_of_missing_optional_fields(tmp_path):
    doc = {
        "ownShip": {
            "waypoints": [
                {"position": {"lat": 58.0, "lon": 10.0}, "leg": {"sog": 8.0}},
                {"position": {"lat": 58.01, "lon": 10.0}},
            ],
            "static": {"dimensions": {"a": 30.0, "b": 10.0, "c": 4.0, "d": 4.0}},
        },
        "targetShips": [
            {
                "initial": {"heading": 180.0, "sog": 6.0},
                "waypoints": [{"position": {"latitude": 58.02, "longitude": 10.0}}],
                "static": {"dimensions": {"length": 20.0, "width": 5.0}},
            }
        ],
    }
    sit = load_situation(_write(tmp_path, doc))
    own, tgt = sit.own_ship, sit.targets[0]
    assert sit.title == "" and own.name == "ship_1" and own.mmsi is None
    assert own.length == 40.0 and own.width == 8.0
    assert own.psi0 == pytest.approx(np.pi / 2, abs=1e-9)  # heading from the first leg
    assert own.sog_kn == (8.0, 8.0)
    assert tgt.id == 2 and tgt.sog_kn == (6.0,) and tgt.a is None
    x, y, psi, v = tgt.state_at([0.0, 10.0])
    assert y[0] - y[1] == pytest.approx(10 * 6 * KNOT) and psi[0] == pytest.approx(-np.pi / 2)
    assert classify(own.xy[0], own.psi0, own.speed0, tgt.xy[0], tgt.psi0, tgt.speed0, SETTINGS) is (
        EncounterType.HEAD_ON
    )


@pytest.mark.parametrize(
    "content, key",
    [
        ("{not json", "document"),
        ({"title": "x"}, "ownShip"),
        ({"ownShip": {"waypoints": [{"position": {"lat": 58.0}}]}}, "lon"),
        ({"ownShip": {"waypoints": [{"position": {"lat": 58, "lon": 10}}]}}, "sog"),
        (
            {
                "ownShip": {
                    "waypoints": [{"position": {"lat": 58, "lon": 10}, "leg": {"sog": "fast"}}]
                }
            },
            "sog",
        ),
        (
            {"ownShip": {"waypoints": [{"position": {"lat": 58, "lon": 10}, "leg": {"sog": 5}}]}},
            "dimensions",
        ),
    ],
)
def test_broken_files_give_one_line_config_error(tmp_path, content, key):
    p = _write(tmp_path, content)
    with pytest.raises(ConfigError) as e:
        load_situation(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and key in msg


def test_missing_file_and_bad_settings(tmp_path):
    with pytest.raises(ConfigError):
        load_situation(tmp_path / "nope.json")
    p = _write(tmp_path, {"classification": {"theta15": [112.5]}}, "settings.json")
    with pytest.raises(ConfigError, match="theta15"):
        load_encounter_settings(p)
    with pytest.raises(ConfigError):
        parse_situation([1, 2, 3])
