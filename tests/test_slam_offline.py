"""Offline 2D SLAM on a real CARMEN log piece (tests/data/carmen: Intel lab, CC-BY 3.0)."""

import bz2
import gzip
import json
from pathlib import Path

import numpy as np
import pytest

from usvdrake.analysis.trajectory_metrics import (
    ate,
    read_trajectory,
    read_tum,
    se3_to_planar,
    trajectory_from_planar,
)
from usvdrake.cli import main
from usvdrake.logs.carmen import read_poses

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
    assert metrics["ate_m"] <= metrics["ate_max_m"]
    assert (tmp_path / "ate.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # played back at its pace (Intel's scans ~0.2 s apart) every scan's lag is at least its
    # own processing time (> 0) and at most the whole run's wall time
    assert 0.0 < metrics["lag_p95_s"] <= metrics["lag_max_s"] <= metrics["wall_time_s"]
    # the full optimisations' time: each no longer than the longest; by default they ran in
    # the worker process, and the scans waited for them no longer than the run took
    n_full, full_s = metrics["full_optimisations"], metrics["full_optimisation_s"]
    assert 0.0 <= full_s <= n_full * metrics["full_optimisation_ms_max"] / 1e3 + 1e-12
    assert metrics["full_in_worker"] and 0.0 <= metrics["full_wait_s"] < metrics["wall_time_s"]
    # --inline: solved in this process as they start, nothing waited for (the solves are in
    # the wall time instead); the same nodes (made by the motion between scans alone)
    inline = tmp_path / "inline"
    assert main(["slam2d", str(LOG), "--out", str(inline), "--quiet", "--inline"]) == 0
    here = json.loads((inline / "metrics.json").read_text())
    assert not here["full_in_worker"] and here["full_wait_s"] < 0.01
    assert here["full_optimisation_s"] < here["wall_time_s"]
    assert here["slam_nodes"] == metrics["slam_nodes"]


def test_replay_lag_queues_scans_behind_slow_ones():
    from usvdrake.run.slam2d import replay_lag

    # arrivals 0, 1, 2, 2, 3 (the fourth, stamped back in time, counts as arriving at 2); a
    # 2.5 s step on the second delays all after it: they end at 0.5, 3.5, 4.0, 4.5, 5.0
    lag = replay_lag([0.0, 1.0, 2.0, 1.5, 3.0], [0.5, 2.5, 0.5, 0.5, 0.5])
    np.testing.assert_allclose(lag, [0.5, 2.5, 2.0, 2.5, 2.0])
    with pytest.raises(ValueError, match="2 stamps but 3"):
        replay_lag([0.0, 1.0], [0.1, 0.1, 0.1])


def test_slam2d_scores_a_raw_log_against_its_corrected_log_scan_by_scan(tmp_path):
    """A corrected log re-stamps a subset of the raw log's scans from 0 (no stamp matches):
    its scans are found in the raw run by their ranges and scored pose against pose."""
    lines = [ln for ln in bz2.open(LOG, "rt") if ln.startswith("FLASER")]
    corrected, picked = [], range(0, 200, 4)
    for k, i in enumerate(picked):
        tokens = lines[i].split()
        n = int(tokens[1])
        tokens[2 + n] = f"{0.5 + 0.01 * k:.3f}"  # a "corrected" laser pose: drifting in x
        tokens[8 + n] = f"{0.2 * k:.3f}"  # stamped from 0
        corrected.append(" ".join(tokens) + "\n")
    ref = tmp_path / "corrected.log.gz"
    with gzip.open(ref, "wt") as f:
        f.writelines(corrected)
    out = tmp_path / "run"
    assert main(["slam2d", str(LOG), "--out", str(out), "--quiet", "--reference", str(ref)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["ate_association"] == "scan" and metrics["ate_pairs"] == len(picked)
    # the same number from the written trajectory at the picked rows, against the new poses
    est = se3_to_planar(read_trajectory(out / "trajectory.tum").poses)[list(picked)]
    _, poses = read_poses(ref)
    k = np.arange(len(picked), dtype=float)
    expected = ate(trajectory_from_planar(k, est), trajectory_from_planar(k, poses), align="se2")
    assert metrics["ate_m"] == pytest.approx(expected["ate_rmse_m"], rel=1e-6)
    assert metrics["ate_m"] > 0.05  # the drift the corrected poses carry is seen
    # the poses drift 1 cm a scan along x: the similarity fit reads a scale, and takes out
    # what the scale explains
    similar = ate(
        trajectory_from_planar(k, est), trajectory_from_planar(k, poses), "se2", with_scale=True
    )
    assert metrics["ate_scale"] == pytest.approx(similar["ate_scale"], rel=1e-9)
    assert metrics["ate_sim2_m"] == pytest.approx(similar["ate_rmse_m"], rel=1e-6)
    assert metrics["ate_sim2_m"] <= metrics["ate_m"]


def test_slam2d_relink_links_the_final_estimate_and_refuses_a_negative_radius(tmp_path, capsys):
    """``--relink RADIUS``: after the last scan the nodes are linked to the older ones within
    the radius and the graph optimised again; the links and their time are in the metrics (the
    time inside the wall time); a negative radius is a one-line error."""
    out = tmp_path / "relinked"
    assert main(["slam2d", str(LOG), "--out", str(out), "--quiet", "--relink", "3"]) == 0
    assert not (out / "ate.png").exists()  # no reference, no error plot
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["slam_nodes"] >= 3 and metrics["relinks"] >= 1
    assert 0.0 < metrics["relink_s"] < metrics["wall_time_s"]
    t, xyz, _ = read_tum(out / "trajectory.tum")
    assert len(t) == 200 and np.all(np.isfinite(xyz))
    assert main(["slam2d", str(LOG), "--out", str(out), "--quiet", "--relink", "-1"]) == 2
    assert "--relink" in capsys.readouterr().err


def test_slam2d_odometry_ties_the_nodes_by_the_logs_wheel_odometry(tmp_path, capsys):
    """``--odometry``: the raw log's odometry (its FLASER pose fields) ties the nodes (every
    metre it went) beside the scans; the metrics say so and give the calibration the scans
    made of it (1 until the odometry has gone 5 m over well-measured steps). The scan-only run
    has none of those constraints; a bag has no odometry to read: a one-line error."""
    plain, odo = tmp_path / "plain", tmp_path / "odo"
    assert main(["slam2d", str(LOG), "--out", str(plain), "--quiet"]) == 0
    assert main(["slam2d", str(LOG), "--out", str(odo), "--quiet", "--odometry"]) == 0
    without = json.loads((plain / "metrics.json").read_text())
    metrics = json.loads((odo / "metrics.json").read_text())
    assert without["odometry"] is False and without["odometry_scale"] is None
    assert metrics["odometry"] is True and len(metrics["odometry_scale"]) == 2
    assert all(0.5 < k < 2.0 for k in metrics["odometry_scale"])
    assert metrics["slam_nodes"] == without["slam_nodes"]  # the scans alone make the nodes
    assert metrics["slam_constraints"] > without["slam_constraints"]
    # every odometry constraint was either added or gated out (odometry_gate), none counted twice
    added = metrics["slam_constraints"] - without["slam_constraints"]
    assert metrics["odometry_constraints"] == added > 0 and without["odometry_constraints"] == 0
    assert without["odometry_rejected"] == 0  # scan-only: nothing to gate
    t, xyz, _ = read_tum(odo / "trajectory.tum")
    assert len(t) == 200 and np.all(np.isfinite(xyz))
    bag = tmp_path / "room.bag"
    write_bag(bag)
    assert main(["slam2d", str(bag), "--out", str(tmp_path / "b"), "--quiet", "--odometry"]) == 2
    assert "CARMEN" in capsys.readouterr().err


def test_slam2d_missing_log_is_one_line(tmp_path, capsys):
    assert main(["slam2d", str(tmp_path / "nope.clf"), "--out", str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err


def write_bag(path: Path, n: int = 40) -> np.ndarray:
    """A ROS 1 bag of Hokuyo scans cast while moving through the synthetic room (the truth)."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    from usvdrake.worlds.raycast import cast
    from usvdrake.worlds.synthetic import HOKUYO, cluttered_room

    store = get_typestore(Stores.ROS1_NOETIC)
    scan_t, header_t, time_t = (
        store.types[k]
        for k in ("sensor_msgs/msg/LaserScan", "std_msgs/msg/Header", "builtin_interfaces/msg/Time")
    )
    scene = cluttered_room()
    truth = np.column_stack(
        [np.linspace(-4.0, 4.0, n), np.linspace(-1.0, 1.0, n), np.linspace(0.0, 0.4, n)]
    )
    with Writer(path) as writer:
        conn = writer.add_connection("/scan", scan_t.__msgtype__, typestore=store)
        for k, (x, y, psi) in enumerate(truth):
            r = cast(scene, HOKUYO, [0.0], np.array([x, y]), 1.0, psi, 30.0)[0]
            stamp = time_t(sec=100 + k, nanosec=0)
            msg = scan_t(
                header=header_t(seq=k, stamp=stamp, frame_id="laser"),
                angle_min=HOKUYO.az0,
                angle_max=HOKUYO.az0 + HOKUYO.daz * (HOKUYO.count - 1),
                angle_increment=HOKUYO.daz,
                time_increment=0.0,
                scan_time=0.025,
                range_min=0.1,
                range_max=30.0,
                ranges=np.where(np.isfinite(r), r, np.inf).astype(np.float32),
                intensities=np.zeros(0, np.float32),
            )
            writer.write(conn, (100 + k) * 10**9, store.serialize_ros1(msg, scan_t.__msgtype__))
    return truth


def test_ros1_bag_scans_read_and_slam2d_tracks_them(tmp_path):
    from usvdrake.logs.rosbag import read_bag_scans

    bag = tmp_path / "room.bag"
    truth = write_bag(bag)
    scans = list(read_bag_scans(bag))
    assert len(scans) == len(truth) and scans[3].timestamp == 103.0
    assert scans[0].scan.valid.sum() > 1000 and np.all(
        scans[0].scan.ranges[~scans[0].scan.valid] == np.inf
    )
    assert (
        main(
            ["slam2d", str(bag), "--out", str(tmp_path / "out"), "--quiet", "--resolution", "0.05"]
        )
        == 0
    )
    t, xyz, quat = read_tum(tmp_path / "out" / "trajectory.tum")
    # the SLAM frame is the first scan's: compare the motion relative to the first pose
    rel_true = truth[:, :2] - truth[0, :2]
    c, s = np.cos(-truth[0, 2]), np.sin(-truth[0, 2])
    rel_true = rel_true @ np.array([[c, s], [-s, c]])
    assert np.max(np.hypot(*(xyz[:, :2] - rel_true).T)) < 0.02


def test_bag_without_laser_scans_is_one_clear_line(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "empty.bag"
    with Writer(bag) as writer:
        writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
    assert main(["slam2d", str(bag), "--out", str(tmp_path / "o")]) == 2
