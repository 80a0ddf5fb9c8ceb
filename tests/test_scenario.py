"""Scenario and vessel loading: shipped files load; bad files stop with one clear line."""

import subprocess
import sys

import pytest

from usvdrake import ConfigError, load_scenario, load_vessel
from usvdrake.cli import main
from usvdrake.diagrams import with_overrides
from usvdrake.scenario import available_scenarios
from usvdrake.vessel import available_vessels

GOOD = """
vessel: roboat2
world: canal_demo
duration: 10.0
mission:
  waypoints: [[10.0, 0.0]]
"""


def write(tmp_path, text, name="s.yaml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_every_shipped_scenario_and_vessel_loads():
    assert {"canal_demo", "usv2000_open_water", "ntnu_round_open_water"} <= set(
        available_scenarios()
    )
    for name in available_scenarios():
        s = load_scenario(name)
        assert s.name == name and s.duration > 0
    assert set(available_vessels()) == {"roboat2", "usv2000", "ntnu_round"}


def test_roboat2_parameters_are_the_papers():
    v = load_vessel("roboat2")
    h = v.hydrodynamics
    assert (h.m11, h.m22, h.m33, h.Xu, h.Yv, h.Nr) == (172, 188, 24, 38, 168, 16)
    assert (v.hull.length, v.hull.beam, v.hull.height) == (2.0, 1.0, 0.475)
    assert [t.max_force for t in v.thrusters] == [50.0] * 4
    assert [t.min_force for t in v.thrusters] == [-50.0] * 4


def test_ntnu_round_geometry():
    v = load_vessel("ntnu_round")
    assert v.hull.length == pytest.approx(0.548)
    for t in v.thrusters:
        assert t.azimuth and (t.x**2 + t.y**2) ** 0.5 == pytest.approx(0.138, abs=1e-4)


@pytest.mark.parametrize(
    "text, key, expected",
    [
        (GOOD + "speed_of_light: 3\n", "speed_of_light", "one of"),
        (GOOD.replace("duration: 10.0", "duration: fast"), "duration", "a number"),
        (GOOD.replace("duration: 10.0", "duration: -5"), "duration", "a positive number"),
        (GOOD.replace("roboat2", "titanic"), "vessel", "one of ntnu_round, roboat2"),
        (GOOD.replace("world: canal_demo", "world: atlantis"), "world", "one of"),
        (
            GOOD + "environment:\n  wind: {mean_speed: [1, 2]}\n",
            "environment.wind.mean_speed",
            "a number",
        ),
        (GOOD + "environment:\n  waves: {hight: 1}\n", "environment.waves.hight", "one of"),
        (GOOD.replace("[[10.0, 0.0]]", "[[10.0, 0.0, 3.0]]"), "mission.waypoints[0]", "[x, y]"),
        (GOOD + "initial_state: [1, 2]\n", "initial_state", "6 numbers"),
        (GOOD + "seed: 1.5\n", "seed", "an integer"),
        (GOOD + "sensors: {lidar2d: {preset: velodyne}}\n", "sensors.lidar2d.preset", "one of"),
        (
            GOOD + "sensors: {lidar3d: {preset: rplidar_a1}}\n",
            "sensors.lidar3d.preset",
            "a 3D lidar",
        ),
        (GOOD + "sensors: {enabled: [sonar]}\n", "sensors.enabled[0]", "one of gps, imu, lidar2d"),
        (GOOD + "sensors: {gps: {datum: mars}}\n", "sensors.gps.datum", "one of"),
        (GOOD.replace("[[10.0, 0.0]]", "[[30.0, 7.5]]"), "mission.waypoints[0]", "free water"),
        (GOOD + "initial_state: [30, -20, 0, 0, 0, 0]\n", "initial_state", "free water"),
        (GOOD + "estimator: slam\n", "estimator", "only with slam.method factor_graph"),
        (
            GOOD.replace("[[10.0, 0.0]]", "[[10.0, 0.0], [65.0, 30.0]]"),
            "mission.waypoints[1]",
            "a straight leg",
        ),
    ],
)
def test_bad_scenario_one_line(tmp_path, text, key, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as err:
        load_scenario(path)
    msg = str(err.value)
    assert "\n" not in msg
    assert str(path) in msg and f"'{key}'" in msg and expected in msg and "got" in msg


def test_malformed_yaml(tmp_path):
    path = write(tmp_path, "vessel: roboat2\nmission: {waypoints: [[1, 2]\n")
    with pytest.raises(ConfigError, match="well-formed YAML") as err:
        load_scenario(path)
    assert "\n" not in str(err.value)


def test_unknown_scenario_name():
    with pytest.raises(ConfigError, match="canal_demo"):
        load_scenario("no_such_mission")


def test_overrides_copy_and_validate():
    s = load_scenario("canal_demo")
    t = with_overrides(s, duration=3.0, seed=7)
    assert (t.duration, t.seed) == (3.0, 7) and s.duration != 3.0
    with pytest.raises(ConfigError, match="duration"):
        with_overrides(s, duration=-1.0)


def test_cli_exit_code_2_without_traceback(tmp_path, capsys):
    path = write(tmp_path, GOOD.replace("duration: 10.0", "duration: -1"))
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usvdrake: error:") and "Traceback" not in err and err.count("\n") == 1


def test_cli_subprocess_exit_code(tmp_path):
    path = write(tmp_path, "vessel: [oops\n")
    r = subprocess.run(
        [sys.executable, "-m", "usvdrake.cli", "run", str(path)], capture_output=True, text=True
    )
    assert r.returncode == 2
    assert "Traceback" not in r.stderr and str(path) in r.stderr
