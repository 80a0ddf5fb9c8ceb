"""End-to-end: the demo mission, its files, and the Meshcat replay."""

import base64
import json
import re

import pytest

from usvdrake import load_scenario, make_meshcat, run_mission
from usvdrake.cli import main


def replay_commands(html: str) -> bytes:
    """The Meshcat commands embedded (msgpack, base64) in a StaticHtml replay."""
    blobs = re.findall(r'fetch\("data:application/octet-binary;base64,([A-Za-z0-9+/=]+)"\)', html)
    assert blobs, "no embedded Meshcat commands"
    return b"".join(base64.b64decode(b) for b in blobs)


@pytest.mark.slow
def test_demo_mission_completes_safely(tmp_path):
    result = run_mission(load_scenario("canal_demo"), out_dir=tmp_path)
    m = result.metrics
    assert m["mission_complete"]
    assert m["collision_samples"] == 0 and m["min_clearance_m"] > 1.0
    assert m["final_distance_to_goal_m"] < 2.5
    assert m["cross_track_rmse_m"] < 0.5
    assert 100.0 < m["path_length_m"] < 130.0
    on_disk = json.loads((tmp_path / "metrics.json").read_text())
    for key in ("sim_time_s", "wall_time_s", "realtime_factor", "path_length_m"):
        assert key in on_disk
    commands = replay_commands((tmp_path / "replay.html").read_text())
    # a standalone replay: the world, the hull, and an animation whose tracks move the hull,
    # scale the thrust arrows and reveal the trail piece by piece
    assert b"/world/quay" in commands and b"/vessels/roboat2/hull" in commands
    assert b"set_animation" in commands and b".visible" in commands and b".scale" in commands
    assert (tmp_path / "ground_truth.tum").read_text().startswith("# t x y z qx qy qz qw")


@pytest.mark.slow
def test_round_vessel_mission_with_azimuths_completes():
    m = run_mission(load_scenario("ntnu_round_open_water")).metrics
    assert m["mission_complete"] and m["final_distance_to_goal_m"] < 0.35


def test_meshcat_is_bound_to_localhost():
    meshcat = make_meshcat()
    assert meshcat.web_url().startswith("http://localhost:")


def test_cli_run_writes_outputs(tmp_path, capsys):
    assert main(["run", "canal_demo", "--duration", "3", "--out", str(tmp_path), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "simulated 3.0 s" in out and "replay" in out
    assert (tmp_path / "replay.html").is_file()
    assert json.loads((tmp_path / "metrics.json").read_text())["sim_time_s"] == pytest.approx(3.0)


@pytest.mark.slow
def test_basin_exploration_meets_ueland_2017(tmp_path):
    """The exploration issue's numbers, end to end: Hector SLAM, frontiers, A*, velocity law,
    observer + PD + reference model + allocation, from no map to finished (~20 s wall)."""
    m = run_mission(load_scenario("basin_explore"), out_dir=tmp_path, record=False).metrics
    assert m["exploration_finished"] and m["mission_complete"]
    assert m["explored_fraction"] >= 0.95
    assert m["collisions"] == 0 and m["min_clearance_m"] >= 0.1
    assert m["speed_narrow_mps"] <= 0.10 and m["narrow_passage_samples"] > 50
    assert m["speed_open_mps"] >= 0.25 and m["open_water_samples"] > 50
    assert m["map_source"] == "slam:hector"
    assert 0 < m["exploration_time_s"] <= m["sim_time_s"] + 1e-9
    assert (tmp_path / "metrics.json").is_file() and (tmp_path / "report.html").is_file()
