"""Metrics from the mission log: a live run and a replay of its ``log.mcap`` are measured by the
same function (``usvdrake.run.measure.measure_mission``) and agree."""

import math

import pytest

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.run.campaign import is_timing_key
from usvdrake.run.measure import metrics_from_log
from usvdrake.run.mission import run_mission


def _same(a, b, key=""):
    if isinstance(a, dict):
        assert set(a) == set(b), key
        for k in a:
            if not is_timing_key(k):
                _same(a[k], b[k], f"{key}.{k}")
    elif isinstance(a, float) and not isinstance(a, bool):
        assert math.isclose(a, b, rel_tol=1e-12, abs_tol=1e-12), f"{key}: {a} != {b}"
    else:
        assert a == b, f"{key}: {a!r} != {b!r}"


@pytest.mark.slow
@pytest.mark.parametrize(
    "name, duration",
    [
        ("river_tracking", 15.0),  # NMPC + NMHE on pose and IMU
        ("valley_survey", 10.0),  # 2D graph SLAM
        ("canal_survey", 12.0),  # 3D factor-graph SLAM
        ("basin_explore", 15.0),  # exploration: Hector map, observer, coverage
    ],
)
def test_a_replayed_log_measures_as_the_live_run(name, duration, tmp_path):
    scenario = with_overrides(load_scenario(name), duration=duration)
    live = run_mission(scenario, out_dir=tmp_path, record=False).metrics
    replay = metrics_from_log(tmp_path / "log.mcap")
    live = {k: v for k, v in live.items() if k not in ("wall_time_s", "realtime_factor")}
    _same(live, replay)


def test_a_log_without_its_summary_is_refused(tmp_path):
    from usvdrake.logs.mission_log import MissionLogWriter

    with MissionLogWriter(tmp_path / "log.mcap") as writer:
        writer.write_state("/ground_truth", 0.0, [0.0] * 6)
    with pytest.raises(ValueError, match="no scenario or run summary"):
        metrics_from_log(tmp_path / "log.mcap")


def test_usvdrake_metrics_prints_and_writes_the_replayed_metrics(tmp_path, capsys):
    import json

    from usvdrake.cli import main

    scenario = with_overrides(load_scenario("canal_demo"), duration=10.0)
    live = run_mission(scenario, out_dir=tmp_path / "run", record=False).metrics
    assert main(["metrics", str(tmp_path / "run"), "--out", str(tmp_path / "again")]) == 0
    assert "canal_demo" in capsys.readouterr().out
    replay = json.loads((tmp_path / "again" / "metrics.json").read_text())
    assert replay["path_length_m"] == live["path_length_m"]
    assert main(["metrics", str(tmp_path / "missing")]) == 2


def test_slam3d_on_a_log_without_3d_sweeps_is_one_clear_line(tmp_path, capsys):
    """A 2D-lidar recording: refused in one line, not 0 keyframes and exit 0."""
    from usvdrake.cli import main

    scenario = with_overrides(load_scenario("basin_rplidar"), duration=3.0)
    run_mission(scenario, out_dir=tmp_path, record=False)
    assert main(["slam3d", str(tmp_path / "log.mcap"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "3D lidar sweeps" in err
