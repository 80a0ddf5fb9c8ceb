"""Offline 3D SLAM (Roboat II §V) on a recorded mission log, and Roboat II §VI-A's ablation on
it."""

import copy
import json

import numpy as np
import pytest

from usvdrake.cli import main
from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.diagrams.slam import settings_from_scenario
from usvdrake.logs.mission_log import read_log_vectors
from usvdrake.logs.sensor_stream import SensorMessage
from usvdrake.run.mission import run_mission
from usvdrake.run.slam3d import (
    _ticks,
    ablation,
    ablation_rows,
    format_table,
    plot_ablation,
    run_ablation,
    run_slam3d,
)
from usvdrake.typed_yaml import ConfigError


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    """12 s of the canal survey, live SLAM on, its sensors recorded in log.mcap (~6 s)."""
    scenario = with_overrides(load_scenario("canal_survey"), duration=12.0)
    result = run_mission(scenario, out_dir=tmp_path_factory.mktemp("survey"), record=False)
    return scenario, result


@pytest.fixture(scope="module")
def offline(survey):
    scenario, result = survey
    config, mount, datum = settings_from_scenario(scenario)
    return run_slam3d(result.files["log"], config, mount=mount, datum=datum)


@pytest.fixture(scope="module")
def variants(survey):
    scenario, result = survey
    config, mount, datum = settings_from_scenario(scenario)
    before = copy.deepcopy(config)
    results = run_ablation(result.files["log"], config, mount=mount, datum=datum)
    assert config == before  # the caller's config is left alone
    return results


def test_same_instant_is_imu_then_gps_then_lidar():
    stream = [
        SensorMessage(0.1, "lidar", "c"),
        SensorMessage(0.1 + 1e-9, "gps", "g"),
        SensorMessage(0.1, "imu", "i1"),
        SensorMessage(0.12, "imu", "i2"),
    ]
    groups = list(_ticks(iter(stream)))
    assert [[m.msg for m in g] for _, g in groups] == [["i1", "g", "c"], ["i2"]]


def test_offline_run_reproduces_the_live_run(survey, offline):
    _, live = survey
    m = offline.metrics
    assert offline.initial_pose_source == "ground_truth"
    assert m["slam_sweeps"] == live.metrics["slam_sweeps"]
    assert abs(m["slam_keyframes"] - live.metrics["slam_keyframes"]) <= 1
    assert len(offline.keyframe_times) == m["slam_keyframes"]
    assert offline.keyframe_poses.shape == (m["slam_keyframes"], 4, 4)
    # the live run's last slam_pose and the offline online pose at that time
    t, pose, names = read_log_vectors(live.files["log"], "/slam_pose")
    assert names == ["x", "y", "psi"]
    i = int(np.argmin(np.abs(offline.truth[0] - t[-1])))
    assert abs(offline.truth[0][i] - t[-1]) < 1e-6
    err = offline.online[i] - pose[-1]
    # The log stores ranges in 2 mm steps, so the replay registers slightly different clouds;
    # the IMU velocity, corrected from each registration over the ~0.7 s between keyframes,
    # carries that into the online pose (measured 5 cm at the floors of this config, 1 cm with
    # a 10x looser rotation floor). Keyframes and GPS factors must agree exactly.
    assert np.hypot(err[0], err[1]) < 0.1  # [m]
    assert abs(err[2]) < 0.01  # [rad]
    assert m["ate_m"] == pytest.approx(live.metrics["ate_m"], abs=0.03)
    assert m["gps_factors"] == live.metrics["gps_factors"]


def test_ablation_has_the_three_variants_and_the_water_level_graph(variants, tmp_path):
    rows = ablation_rows(variants)
    names = ["lidar", "lidar+gps", "lidar+gps+loop", "lidar+gps+loop+water"]
    assert [r["variant"] for r in rows] == names
    assert [(r["use_gps"], r["use_loop_closure"], r["water_level"]) for r in rows] == [
        (False, False, False),
        (True, False, False),
        (True, True, False),
        (True, True, True),  # canal_survey's configured graph
    ]
    assert rows[0]["gps_factors"] == 0 and rows[1]["gps_factors"] >= 1
    assert rows[0]["loop_closures"] == 0 and rows[1]["loop_closures"] == 0
    for r in rows:
        for key in ("ate_m", "ate_final_m", "vertical_error_max_m", "keyframe_ms_p95"):
            assert np.isfinite(r[key])
        assert r["ate_m"] < 0.5
    json.dumps(rows)  # plain values
    table = format_table(rows)
    assert len(table.splitlines()) == 6 and "lidar+gps+loop+water" in table
    png = plot_ablation(variants, variants[0].truth, tmp_path / "ablation.png")
    assert png.stat().st_size > 10_000


def test_cli_slam3d_prints_metrics_json(survey, tmp_path, capsys):
    """--json prints the metrics as JSON; without it, one aligned line per metric."""
    _, live = survey
    out = tmp_path / "out"
    code = main(["slam3d", str(live.files["log"]), "--scenario", "canal_survey", "--quiet"]
                + ["--no-loop", "--out", str(out), "--json"])  # fmt: skip
    assert code == 0
    m = json.loads(capsys.readouterr().out)
    assert m["ate_m"] < 0.5 and m["use_loop_closure"] is False and m["use_gps"] is True
    assert json.loads((out / "metrics.json").read_text())["ate_m"] == m["ate_m"]
    tum = np.loadtxt(out / "trajectory.tum")
    assert tum.shape == (m["slam_keyframes"], 8)
    assert (
        main(["slam3d", str(live.files["log"]), "--scenario", "amsterdam_sensors", "--quiet"]) == 0
    )
    text = capsys.readouterr().out
    assert text.startswith("usvdrake slam3d") and "ate_m" in text and "{" not in text


def test_missing_file_is_a_clear_error(tmp_path, capsys):
    missing = tmp_path / "nothing.mcap"
    with pytest.raises(ConfigError, match="nothing.mcap"):
        ablation(missing, load_scenario("canal_survey").slam.factor_graph)
    assert main(["slam3d", str(missing)]) == 2
    err = capsys.readouterr().err
    assert "nothing.mcap" in err and "no such file" in err
    assert main(["slam3d-ablation", str(missing), "--out", str(tmp_path / "ab")]) == 2
    assert "no such file" in capsys.readouterr().err
