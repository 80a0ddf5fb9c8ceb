"""Offline 2D SLAM on a real CARMEN log piece (tests/data/carmen: Intel lab, CC-BY 3.0)."""

import json
from pathlib import Path

import numpy as np

from usvdrake.analysis.trajectory_metrics import read_tum
from usvdrake.cli import main

LOG = Path(__file__).parent / "data" / "carmen" / "intel-first200.clf.bz2"


def test_slam2d_cli_runs_a_real_log_piece(tmp_path):
    assert (
        main(["slam2d", str(LOG), "--out", str(tmp_path), "--quiet", "--reference", str(LOG)]) == 0
    )
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["scans"] == 200 and metrics["slam_nodes"] >= 1
    t, xyz, _ = read_tum(tmp_path / "trajectory.tum")
    assert len(t) == 200 and np.all(np.isfinite(xyz))
    assert (tmp_path / "map.png").stat().st_size > 1000
    # scored against the log's own (odometry) poses: the robot barely moves in these 200 scans
    assert metrics["ate_m"] < 0.5


def test_slam2d_missing_log_is_one_line(tmp_path, capsys):
    assert main(["slam2d", str(tmp_path / "nope.clf"), "--out", str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err
