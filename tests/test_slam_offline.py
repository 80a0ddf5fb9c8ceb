"""Offline 2D SLAM on a real CARMEN log piece (tests/data/carmen: Intel lab, CC-BY 3.0)."""

import bz2
import gzip
import json
import re
from dataclasses import replace
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
from usvdrake.run.slam2d import LOG_CONFIG, replay_lag, run_slam2d

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
    args = ["slam2d", str(LOG), "--out", str(inline), "--quiet", "--inline", "--scan-only"]
    assert main(args) == 0
    here = json.loads((inline / "metrics.json").read_text())
    assert not here["full_in_worker"] and here["full_wait_s"] < 0.01
    assert here["full_optimisation_s"] < here["wall_time_s"]
    assert here["slam_nodes"] == metrics["slam_nodes"]


def test_replay_lag_queues_scans_behind_slow_ones():
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


def test_slam2d_uses_the_logs_wheel_odometry_by_default(tmp_path):
    """A raw log's odometry (its FLASER pose fields) ties the nodes (every metre it went)
    beside the scans by default; the metrics and the summary say so and give the calibration
    the scans made of it (1 until the odometry has gone 5 m over well-measured steps).
    ``--scan-only`` has none of those constraints; ``--odometry`` (the old switch) is the
    default."""
    plain, odo, old = tmp_path / "plain", tmp_path / "odo", tmp_path / "old"
    assert main(["slam2d", str(LOG), "--out", str(plain), "--quiet", "--scan-only"]) == 0
    assert main(["slam2d", str(LOG), "--out", str(odo), "--quiet"]) == 0
    assert main(["slam2d", str(LOG), "--out", str(old), "--quiet", "--odometry"]) == 0
    scan_only = json.loads((plain / "metrics.json").read_text())
    assert scan_only["odometry"] is False and scan_only["odometry_scale"] is None
    assert scan_only["motion_prior"] == "scan-only (--scan-only)"
    assert scan_only["odometry_constraints"] == 0
    # the same configuration without the odometry (a CARMEN log runs LOG_CONFIG either way)
    without = run_slam2d(LOG, tmp_path / "same", progress=False, config=LOG_CONFIG, odometry=False)
    metrics = json.loads((odo / "metrics.json").read_text())
    assert metrics["odometry"] is True and len(metrics["odometry_scale"]) == 2
    assert all(0.5 < k < 2.0 for k in metrics["odometry_scale"])
    # the odometry only tying nodes (not seeding the matches too, as LOG_CONFIG has it): the
    # scans alone make the nodes, and every odometry constraint was either added or gated out
    # (odometry_gate), none counted twice
    tied = run_slam2d(
        LOG, tmp_path / "tied", progress=False, config=replace(LOG_CONFIG, odometry_seed=False)
    )
    assert tied["odometry"] is True and tied["slam_nodes"] == without["slam_nodes"]
    added = tied["slam_constraints"] - without["slam_constraints"]
    assert tied["odometry_constraints"] == added > 0 and without["odometry_constraints"] == 0
    assert without["odometry_rejected"] == 0  # scan-only: nothing to gate
    assert metrics["odometry_constraints"] > 0
    assert metrics["motion_prior"] == (
        f"wheel odometry ({metrics['odometry_constraints']} constraints, "
        f"{metrics['odometry_rejected']} gated out)"
    )
    again = json.loads((old / "metrics.json").read_text())
    assert again["motion_prior"] == metrics["motion_prior"]
    # --fast: LOG_ODOMETRY_CONFIG, a node every 0.15 m instead of every 5 cm
    fast = run_slam2d(LOG, tmp_path / "fast", progress=False, fast=True)
    assert fast["odometry"] is True and fast["slam_nodes"] < metrics["slam_nodes"]
    t, xyz, _ = read_tum(odo / "trajectory.tum")
    assert len(t) == 200 and np.all(np.isfinite(xyz))


def test_slam2d_reads_no_odometry_from_a_corrected_log_or_a_log_without_it(tmp_path, capsys):
    """A corrected log's pose fields are its reference (the scan matcher's NEFF lines say it
    is one), and so are a log's own when it is its reference; a log whose pose fields never
    move has no odometry. Each runs scan-only, and the one-screen summary says why."""
    lines = list(bz2.open(LOG, "rt"))
    corrected = tmp_path / "corrected.log"
    corrected.write_text("".join(lines[:120]) + "NEFF 30.0 0.0 pippo 0.0\n")
    still = tmp_path / "still.clf"
    flaser = [ln.split() for ln in lines if ln.startswith("FLASER")][:60]
    for tokens in flaser:
        n = int(tokens[1])
        tokens[2 + n : 8 + n] = ["0"] * 6  # no odometer: every pose 0 0 0
    still.write_text("".join(" ".join(tokens) + "\n" for tokens in flaser))
    cases = [
        (corrected, [], "scan-only (a corrected log: its poses are the reference)"),
        (
            LOG,
            ["--reference", str(LOG)],
            "scan-only (a corrected log: its poses are the reference)",
        ),
        (still, [], "scan-only (log has no odometry)"),
    ]
    for k, (log, extra, prior) in enumerate(cases):
        out = tmp_path / f"run{k}"
        capsys.readouterr()
        assert main(["slam2d", str(log), "--out", str(out), "--quiet", *extra]) == 0
        metrics = json.loads((out / "metrics.json").read_text())
        assert metrics["motion_prior"] == prior and metrics["odometry"] is False
        assert metrics["odometry_constraints"] == 0
        assert re.search(r"motion_prior +" + re.escape(prior), capsys.readouterr().out)


def test_bag_odometry_is_read_interpolated_and_used(tmp_path):
    """A bag's /odom (nav_msgs/Odometry) is interpolated to each scan's time and used; a bag
    without one runs scan-only."""
    from usvdrake.logs.rosbag import odometry_at, read_bag_scans

    with_odom, plain = tmp_path / "odom.bag", tmp_path / "plain.bag"
    truth = write_bag(with_odom, odometry=True)
    write_bag(plain)
    scans = list(read_bag_scans(with_odom))
    # the odometry runs at twice the scans' rate: interpolated exactly on the straight line it
    # follows (the last scan is past its last reading: none)
    got = np.array([s.odometry_pose for s in scans[:-1]])
    np.testing.assert_allclose(got, truth[:-1], atol=1e-9)
    assert scans[-1].odometry_pose is None
    assert all(s.odometry_pose is None for s in read_bag_scans(plain))
    # yaw is interpolated the short way round across ±π
    odom = np.array([[0.0, 0.0, 0.0, 3.1], [1.0, 1.0, 0.0, -3.1]])
    at = odometry_at(odom, np.array([-1.0, 0.5, 1.0]))
    assert np.isnan(at[0]).all() and at[1, 0] == pytest.approx(0.5)
    assert abs(np.angle(np.exp(1j * at[1, 2]))) == pytest.approx(np.pi, abs=1e-9)
    for bag, prior in ((with_odom, "wheel odometry"), (plain, "scan-only (log has no odometry)")):
        out = tmp_path / bag.stem
        assert main(["slam2d", str(bag), "--out", str(out), "--quiet", "--inline"]) == 0
        assert json.loads((out / "metrics.json").read_text())["motion_prior"].startswith(prior)


def test_slam2d_missing_log_is_one_line(tmp_path, capsys):
    assert main(["slam2d", str(tmp_path / "nope.clf"), "--out", str(tmp_path)]) == 2
    assert "no such file" in capsys.readouterr().err


def write_bag(path: Path, n: int = 40, odometry: bool = False) -> np.ndarray:
    """A ROS 1 bag of Hokuyo scans cast while moving through the synthetic room (the truth);
    with ``odometry``, the true poses also on /odom (nav_msgs/Odometry) at twice the scans'
    rate, from the first scan to half a scan before the last."""
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
        if odometry:
            _write_odometry(writer, store, truth, header_t, time_t)
    return truth


def _write_odometry(writer, store, truth, header_t, time_t) -> None:
    """``truth``'s poses (one per second from 100 s) on /odom every 0.5 s from 100 s to half
    a second before the last pose."""
    names = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseWithCovariance")
    odom_t, pwc_t = (store.types[k] for k in names)
    pose_t, point_t, quat_t = (
        store.types[f"geometry_msgs/msg/{k}"] for k in ("Pose", "Point", "Quaternion")
    )
    twc_t, twist_t, vec_t = (
        store.types[f"geometry_msgs/msg/{k}"] for k in ("TwistWithCovariance", "Twist", "Vector3")
    )
    conn = writer.add_connection("/odom", odom_t.__msgtype__, typestore=store)
    k = np.arange(0.0, len(truth) - 1, 0.5)
    x, y, yaw = (np.interp(k, np.arange(len(truth)), truth[:, i]) for i in range(3))
    for kk, xi, yi, yawi in zip(k, x, y, yaw, strict=True):
        t = 100.0 + kk
        stamp = time_t(sec=int(np.floor(t)), nanosec=int(round((t % 1) * 1e9)))
        msg = odom_t(
            header=header_t(seq=0, stamp=stamp, frame_id="odom"),
            child_frame_id="base_link",
            pose=pwc_t(
                pose=pose_t(
                    position=point_t(x=xi, y=yi, z=0.0),
                    orientation=quat_t(x=0.0, y=0.0, z=np.sin(yawi / 2), w=np.cos(yawi / 2)),
                ),
                covariance=np.zeros(36),
            ),
            twist=twc_t(
                twist=twist_t(
                    linear=vec_t(x=0.0, y=0.0, z=0.0), angular=vec_t(x=0.0, y=0.0, z=0.0)
                ),
                covariance=np.zeros(36),
            ),
        )
        writer.write(conn, int(round(t * 1e9)), store.serialize_ros1(msg, odom_t.__msgtype__))


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
