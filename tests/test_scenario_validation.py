"""Validation that cannot be slipped past: every number finite and within the ranges of
``usvdrake.scenario_ranges.RANGES``, YAML 1.2 numbers, duplicate keys, names kept inside their
folders, empty files, ``--out`` a file — each a one-line ConfigError (exit 2 on the command
line)."""

import math
import re
import subprocess
import sys

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from usvdrake import ConfigError, load_scenario
from usvdrake.cli import main
from usvdrake.diagrams import with_overrides
from usvdrake.scenario import (
    NMPC_MAX_STEPS,
    available_scenarios,
    in_range,
    number_leaves,
    range_of,
    scenario_yaml,
)
from usvdrake.typed_yaml import _StrictLoader

GOOD = """
vessel: roboat2
world: canal_demo
duration: 10.0
mission:
  waypoints: [[10.0, 0.0]]
"""
FINITE = "a finite number"


def write(tmp_path, text, name="s.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def add(text):
    return GOOD + text


def dur(value):
    return GOOD.replace("duration: 10.0", f"duration: {value}")


def wp(value):
    return GOOD.replace("[[10.0, 0.0]]", value)


BAD = [
    # NaN / inf anywhere (the generic walk of the dataclass tree)
    (add("environment: {wind: {mean_speed: .nan}}\n"), "environment.wind.mean_speed", FINITE),
    (add("environment: {wind: {gust_std: .nan}}\n"), "environment.wind.gust_std", FINITE),
    (add("environment: {wind: {direction_deg: .inf}}\n"), "environment.wind.direction_deg", FINITE),
    (add("environment: {current: {speed: .NaN}}\n"), "environment.current.speed", FINITE),
    (
        add("environment: {current: {direction_deg: .nan}}\n"),
        "environment.current.direction_deg",
        FINITE,
    ),
    (
        add("environment: {waves: {direction_deg: -.inf}}\n"),
        "environment.waves.direction_deg",
        FINITE,
    ),
    (add("initial_state: [0, 0, 0, .nan, 0, 0]\n"), "initial_state[3]", FINITE),
    (add("initial_state: [0, 0, 0, 0, 0, .inf]\n"), "initial_state[5]", FINITE),
    (add("initial_state: [.nan, 0, 0, 0, 0, 0]\n"), "initial_state[0]", FINITE),
    (dur(".inf"), "duration", FINITE),
    (dur(".nan"), "duration", FINITE),
    (wp("[[.nan, 0.0]]"), "mission.waypoints[0][0]", FINITE),
    (wp("[[10.0, 0.0], [5.0, -.inf]]"), "mission.waypoints[1][1]", FINITE),
    (wp("[[10.0, 0.0]]\n  speed: .nan"), "mission.speed", FINITE),
    (add("nmhe: {disturbance_std: [.nan, 2.0, 0.5]}\n"), "nmhe.disturbance_std[0]", FINITE),
    (add("nmpc: {Wq: [.nan, 1, 1, 1, 1, 1]}\n"), "nmpc.Wq[0]", FINITE),
    (add("sensors: {gps: {horizontal_std: .inf}}\n"), "sensors.gps.horizontal_std", FINITE),
    (
        add("fleet: {vessels: [{name: a, initial_state: [0, 0, 0, .nan, 0, 0]}]}\n"),
        "fleet.vessels[0].initial_state[3]",
        FINITE,
    ),
    (add("fleet: {requests: [{time: .nan}]}\n"), "fleet.requests[0].time", FINITE),
    # ranges that stall the integrator or need too much memory
    (dur("1e6"), "duration", "(0, 86400]"),
    (dur("1.0e6"), "duration", "(0, 86400]"),
    (dur("-5"), "duration", "a positive number"),
    (add("simulation: {max_step: 1e-12}\n"), "simulation.max_step", "[0.0001, 60]"),
    (add("simulation: {accuracy: 0}\n"), "simulation.accuracy", "a number in"),
    (add("environment: {update_period: 1e-9}\n"), "environment.update_period", "[0.001"),
    (add("control: {rate_hz: 1e9}\n"), "control.rate_hz", "(0, 1000]"),
    (add("control: {rate_hz: 0}\n"), "control.rate_hz", "(0, 1000]"),
    (add("sensors: {imu: {rate_hz: 1.0e9}}\n"), "sensors.imu.rate_hz", "(0, 1000]"),
    (add("nmhe: {rate_hz: -10}\n"), "nmhe.rate_hz", "(0, 1000]"),
    (add("visualization: {rate_hz: 1e9}\n"), "visualization.rate_hz", "(0, 1000]"),
    (add("sensors: {lidar2d: {rate_hz: 1e9}}\n"), "sensors.lidar2d.rate_hz", "[0, 1000]"),
    (add("model_error: [1e-12, 1, 1, 1, 1, 1]\n"), "model_error[0]", "[0.1, 10]"),
    (add("model_error: [1, 1, 1, 1, 1, 100]\n"), "model_error[5]", "[0.1, 10]"),
    (add("initial_state: [0, 0, 0, 1e6, 0, 0]\n"), "initial_state[3]", "[-20, 20]"),
    (add("initial_state: [0, 0, 0, 0, -30, 0]\n"), "initial_state[4]", "[-20, 20]"),
    (add("initial_state: [0, 0, 0, 0, 0, 11]\n"), "initial_state[5]", "[-10, 10]"),
    (add("environment: {wind: {mean_speed: 1e6}}\n"), "environment.wind.mean_speed", "[0, 60]"),
    (add("environment: {wind: {mean_speed: -1}}\n"), "environment.wind.mean_speed", "[0, 60]"),
    (
        add("environment: {waves: {significant_height: 1e6}}\n"),
        "environment.waves.significant_height",
        "[0, 10]",
    ),
    (
        add("environment: {waves: {peak_period: 1e-9}}\n"),
        "environment.waves.peak_period",
        "[0.5, 30]",
    ),
    (add("environment: {current: {speed: 50}}\n"), "environment.current.speed", "[0, 10]"),
    (
        add("environment: {waves: {components: 100000000}}\n"),
        "environment.waves.components",
        "[1, 1000]",
    ),
    (add("nmpc: {horizon: 1.0e6}\n"), "nmpc.horizon", "(0, 60]"),
    (add("nmpc: {horizon: 30.0}\n"), "nmpc.horizon", f"at most {NMPC_MAX_STEPS} intervals"),
    (add("nmpc: {dt: 1e-9}\n"), "nmpc.dt", "[0.01, 10]"),
    (add("nmhe: {horizon: 1000000}\n"), "nmhe.horizon", "[2, 200]"),
    (add("nmhe: {disturbance_std: [0, 2.0, 0.5]}\n"), "nmhe.disturbance_std[0]", "(0, "),
    (add("nmhe: {gyro_std: -1}\n"), "nmhe.gyro_std", "(0, "),
    (add("seed: -1\n"), "seed", "[0, "),
    (
        add("environment: {wind: {air_density: -1000}}\n"),
        "environment.wind.air_density",
        "(0, 100]",
    ),
    (add("slam: {hector: {resolution: 1e-9}}\n"), "slam.hector.resolution", "[0.01, 10]"),
    (add("hardware: {poll_period: 1e-9}\n"), "hardware.poll_period", "[0.0001, 10]"),
    # sizes nothing physical has: coordinates and directions of 1e300 overflow downstream
    (wp("[[1.0e300, 0.0]]"), "mission.waypoints[0][0]", "[-1e+06, 1e+06]"),
    (add("initial_state: [0, -2.0e6, 0, 0, 0, 0]\n"), "initial_state[1]", "[-1e+06, 1e+06]"),
    (add("initial_state: [0, 0, 1.0e300, 0, 0, 0]\n"), "initial_state[2]", "[-1000, 1000]"),
    (
        add("environment: {wind: {direction_deg: 1.0e300}}\n"),
        "environment.wind.direction_deg",
        "[-3600, 3600]",
    ),
    (
        add("sensors: {lidar3d: {mount: [1.0e300, 0, 1, 0]}}\n"),
        "sensors.lidar3d.mount[0]",
        "[-1000, 1000]",
    ),
    (add("slam: {hector: {map_origin: [0, -1.0e300]}}\n"), "slam.hector.map_origin[1]", "[-1e+06"),
    (
        add("slam: {hector: {map_size: [9000, 9000]}}\n"),
        "slam.hector.map_size",
        "at most 1e+08 cells",
    ),
    (
        add("fleet: {requests: [{time: 0, pickup: [1.0e300, 0], destination: [0, 0]}]}\n"),
        "fleet.requests[0].pickup[0]",
        "[-1e+06, 1e+06]",
    ),
    (add("sensors: {gps: {horizontal_std: -1}}\n"), "sensors.gps.horizontal_std", "[0, 1e+06]"),
    (add("sensors: {lidar2d: {dropout: 2}}\n"), "sensors.lidar2d.dropout", "[0, 1]"),
    (add("nmpc: {nlp_tolerance: 1.0e300}\n"), "nmpc.nlp_tolerance", "[-1e+09, 1e+09]"),
    # duplicate keys
    (add("seed: 1\nseed: 2\n"), "seed", "each key once"),
    (add("environment: {wind: {mean_speed: 1, mean_speed: 2}}\n"), "mean_speed", "each key once"),
    # names only inside their folders
    (GOOD.replace("roboat2", "../scenarios/canal_demo"), "vessel", "one of ntnu_round"),
    (GOOD.replace("roboat2", "/etc/passwd"), "vessel", "one of ntnu_round"),
    (GOOD.replace("roboat2", "roboat2/../roboat2"), "vessel", "one of ntnu_round"),
    (GOOD.replace("roboat2", "/no/such/boat.yaml"), "vessel", "an existing vessel YAML file"),
    # strings are still not numbers
    (dur("'1e6'"), "duration", "a number"),
    (dur("nan"), "duration", "a number"),
]


def test_the_table_is_large():
    assert len(BAD) >= 40


@pytest.mark.parametrize("text, key, expected", BAD)
def test_bad_scenario_one_line(tmp_path, text, key, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert "\n" not in msg
    assert str(path) in msg and f"'{key}'" in msg and expected in msg and "got" in msg


@pytest.mark.parametrize(
    "text, key",
    [
        (add("environment: {wind: {mean_speed: .nan}}\n"), "environment.wind.mean_speed"),
        (add("nmpc: {horizon: 1.0e6}\n"), "nmpc.horizon"),
        (add("seed: 1\nseed: 2\n"), "seed"),
        (wp("[[.nan, 0.0]]"), "mission.waypoints[0][0]"),
    ],
)
def test_cli_exit_2_one_line(tmp_path, capsys, text, key):
    path = write(tmp_path, text)
    assert main(["run", str(path), "--quiet", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usvdrake: error:") and err.count("\n") == 1 and f"'{key}'" in err
    assert not (tmp_path / "o").exists()


def test_cli_subprocess_duration_inf(tmp_path):
    path = write(tmp_path, dur(".inf"))
    r = subprocess.run(
        [sys.executable, "-m", "usvdrake.cli", "run", str(path), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "'duration'" in r.stderr and FINITE in r.stderr


def test_a_huge_file_is_refused_before_it_is_parsed(tmp_path):
    path = write(tmp_path, GOOD + "".join(f"k{i}: {i}\n" for i in range(200_000)))
    with pytest.raises(ConfigError, match="at most 1 MB of YAML"):
        load_scenario(path)


def test_a_bad_command_line_is_one_line(capsys):
    with pytest.raises(SystemExit) as e:
        main(["run", "canal_demo", "--duration", "abc"])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and "invalid float value" in err


def test_cli_out_is_a_file(tmp_path, capsys):
    out = write(tmp_path, "not a folder", "out.txt")
    assert main(["run", "canal_demo", "--quiet", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'--out'" in err and str(out) in err
    assert out.read_text() == "not a folder"


@pytest.mark.parametrize("value", [math.inf, math.nan, 1e9, -1.0])
def test_command_line_duration_override(value):
    with pytest.raises(ConfigError, match="'duration'"):
        with_overrides(load_scenario("canal_demo"), duration=value)


@pytest.mark.parametrize("text", ["", "# only a comment\n", "---\n"])
def test_empty_document_one_line(tmp_path, text):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError, match="an empty document") as err:
        load_scenario(path)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name", ["../scenarios/canal_demo", "/etc/passwd", "a/../canal_demo", ""])
def test_scenario_names_stay_in_their_folder(name):
    with pytest.raises(ConfigError, match="one of") as err:
        load_scenario(name)
    assert "\n" not in str(err.value)


def test_yaml_1_2_numbers_are_numbers(tmp_path):
    text = GOOD.replace("duration: 10.0", "duration: 1e2") + (
        "environment: {wind: {mean_speed: 5.0e0, gust_std: .5}}\nsimulation: {accuracy: 1e-5}\n"
    )
    s = load_scenario(write(tmp_path, text))
    assert s.duration == 100.0 and s.environment.wind.mean_speed == 5.0
    assert s.environment.wind.gust_std == 0.5 and s.simulation.accuracy == 1e-5


def test_anchors_and_merge_keys_are_not_duplicates(tmp_path):
    text = GOOD + "_wind: &w {mean_speed: 2.0, gust_std: 0.5}\n"
    text += "environment: {wind: {<<: *w, mean_speed: 3.0}}\n"
    s = load_scenario(write(tmp_path, text))
    assert (s.environment.wind.mean_speed, s.environment.wind.gust_std) == (3.0, 0.5)


def _assert_within_table(s):
    for key, value in number_leaves(s):
        assert math.isfinite(value), key
        rule = range_of(key)
        assert rule is None or in_range(value, rule), (key, value, rule)
    assert s.nmpc.horizon / s.nmpc.dt <= NMPC_MAX_STEPS


def test_every_shipped_scenario_loads_within_the_table():
    for name in available_scenarios():
        s = load_scenario(name)
        assert s.name == name
        _assert_within_table(s)


# ---- property: any value at any key is loaded in range or refused with a ConfigError ----

BASE = load_scenario("canal_demo")
KEYS = sorted(key for key, _ in number_leaves(BASE))
VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**20), max_value=10**20),
    st.sampled_from([1e300, -1e300, 1e-300, 1e-12, 0.0, -1.0, 1e6, 1e9, math.nan, math.inf]),
    st.sampled_from(["fast", "1e6", ".nan", "", None, True, [1.0, 2.0]]),
    st.text(max_size=5),
)


def _set(tree, key, value):
    parts = [p for p in re.split(r"\.|(\[\d+\])", key) if p]
    node = tree
    for part, last in zip(parts, [False] * (len(parts) - 1) + [True], strict=True):
        index = int(part[1:-1]) if part.startswith("[") else part
        if last:
            node[index] = value
        else:
            node = node[index]


@settings(
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(changes=st.lists(st.tuples(st.sampled_from(KEYS), VALUES), min_size=1, max_size=3))
def test_any_value_loads_in_range_or_is_refused(tmp_path, changes):
    tree = yaml.load(scenario_yaml(BASE), Loader=_StrictLoader)  # noqa: S506 (a fresh copy)
    for key, value in changes:
        _set(tree, key, value)
    path = write(tmp_path, yaml.safe_dump(tree))
    try:
        s = load_scenario(path)
    except ConfigError as e:
        assert "\n" not in str(e)
        return
    _assert_within_table(s)
