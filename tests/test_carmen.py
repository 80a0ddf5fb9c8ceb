"""CARMEN log reader on the first 200 scans of the Intel Research Lab log (tests/data/carmen)."""

import bz2
import gzip
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from usvdrake.logs.carmen import (
    associate_scans,
    beam_increment,
    read_carmen,
    read_odometry,
    read_poses,
)
from usvdrake.sensors.messages import LaserScan

INTEL = Path(__file__).parent / "data" / "carmen" / "intel-first200.clf.bz2"


def test_reads_intel_scans():
    scans = list(read_carmen(INTEL))
    assert len(scans) == 200
    t, scan, pose = scans[0]
    assert isinstance(scan, LaserScan) and len(scan.ranges) == 180
    assert t == pytest.approx(976052857.337284) and scan.time == t
    assert scan.angle_min == pytest.approx(-np.pi / 2)
    assert scan.angle_increment == pytest.approx(np.deg2rad(1.0))
    assert scan.angles[-1] == pytest.approx(np.deg2rad(89.0))
    assert scan.ranges[0] == 1.07 and scan.ranges[1] == 1.07 and scan.ranges[179] == 1.05
    # No-return readings (81.83 m) follow the LaserScan convention.
    assert np.all(np.isinf(scan.ranges[~scan.valid])) and 0 < np.sum(~scan.valid) < 180
    assert np.all(scan.ranges[scan.valid] < 50.0)
    np.testing.assert_allclose(pose, [0.0, 0.0, -0.002458])
    t, scan, pose = scans[-1]
    assert t == pytest.approx(976052896.334553)
    np.testing.assert_allclose(pose, [0.702, 0.024, -2.214848])
    stamps = np.array([s.timestamp for s in scans])
    # File order; the ipc clock of the real log steps back now and then, by < 1 s.
    assert stamps[-1] - stamps[0] == pytest.approx(39.0, abs=0.1)
    assert -1.0 < np.min(np.diff(stamps)) < 0.0


def test_pose_choice_and_trajectory():
    stamps, laser = read_poses(INTEL, pose="laser")
    _, odom = read_poses(INTEL, pose="odometry")
    assert laser.shape == (200, 3) and stamps.shape == (200,)
    np.testing.assert_array_equal(laser, odom)  # intel: the laser pose is the odometry
    assert np.all(laser[:100, :2] == 0.0) and np.any(laser[150:, :2] != 0.0)
    with pytest.raises(ValueError):
        next(read_carmen(INTEL, pose="gps"))


def test_odometry_lines():
    stamps, poses = read_odometry(INTEL)
    assert poses.shape == (391, 3) and stamps.shape == (391,)
    np.testing.assert_allclose(poses[-1], [0.702, 0.024, -2.214848])


def test_opens_plain_and_gzip_by_magic_and_stops_at_truncation(tmp_path):
    text = bz2.decompress(INTEL.read_bytes())
    plain, gz = tmp_path / "intel.log", tmp_path / "intel.weird-name"
    plain.write_bytes(text)
    gz.write_bytes(gzip.compress(text))
    ref = [s.odometry_pose for s in read_carmen(INTEL)]
    for path in (plain, gz):
        got = [s.odometry_pose for s in read_carmen(path)]
        np.testing.assert_array_equal(np.array(got), np.array(ref))
    cut = tmp_path / "cut.log"
    cut.write_bytes(text[: text.rindex(b"FLASER") + 300])  # last FLASER line cut mid-ranges
    assert len(list(read_carmen(cut))) == 199


def test_corrected_log_poses(tmp_path):
    # The corrected logs (Radish via acschaefer/ple) are GPL-3.0, so not copied here: this is a
    # hand-written file in their format (gzip, FLASER x y θ = corrected pose, NEFF lines).
    ranges = " ".join(["2.5"] * 180)
    lines = [
        "# CARMEN Logfile",
        "ODOM 0 0 0 0 0 0 0.000246 pippo 0.000246",
        f"FLASER 180 {ranges} 0.600266 -0.0320327 -0.354665 0.6 -0.03 -0.35 32.9068 pippo 32.9",
        "NEFF 179.9 33.0 pippo 33.0",
        f"FLASER 180 {ranges} 0.68231 -0.100086 -0.938803 0.68 -0.1 -0.93 35.1051 pippo 35.1",
    ]
    path = tmp_path / "intel-corrected.log.gz"
    path.write_bytes(gzip.compress(("\n".join(lines) + "\n").encode()))
    stamps, poses = read_poses(path)
    np.testing.assert_allclose(stamps, [32.9068, 35.1051])
    np.testing.assert_allclose(
        poses, [[0.600266, -0.0320327, -0.354665], [0.68231, -0.100086, -0.938803]]
    )


def test_beam_increments():
    assert beam_increment(180) == pytest.approx(np.deg2rad(1.0))
    assert beam_increment(360) == pytest.approx(np.deg2rad(0.5))
    assert beam_increment(361) == pytest.approx(np.deg2rad(0.5))


def test_corrected_scans_are_found_in_the_raw_log_by_their_ranges():
    raw = list(read_carmen(INTEL))
    picked = [3, 10, 11, 57, 120, 199]
    # a corrected log: some raw scans, re-stamped from 0, with other poses
    corrected = [raw[i]._replace(timestamp=0.1 * k) for k, i in enumerate(picked)]
    np.testing.assert_array_equal(associate_scans(raw, corrected), picked)
    # a scan the raw log does not hold (one range moved by 2 cm) pairs with nothing
    moved = raw[57].scan.ranges.copy()
    moved[90] += 0.02
    odd = corrected[3]._replace(scan=replace(raw[57].scan, ranges=moved))
    assert list(associate_scans(raw, [corrected[2], odd, corrected[4]])) == [11, -1, 120]
    # the same scan twice (a robot at rest) pairs with the copies in order
    twice = raw[:5] + [raw[2]] + raw[5:]
    assert list(associate_scans(twice, [raw[2], raw[3], raw[2]])) == [2, 3, 5]


def test_a_flaser_line_without_beams_is_skipped_not_divided_by(tmp_path):
    """``FLASER 0 ...`` (no beams) used to divide by zero in the beam increment."""
    from usvdrake.logs.carmen import read_carmen

    good = "FLASER 4 1.0 2.0 3.0 4.0 0 0 0 0 0 0 1.5 host 1.5"
    log = tmp_path / "bad.clf"
    log.write_text(f"FLASER 0 0 0 0 0 0 0 1.0 host 1.0\n{good}\nFLASER 1 2.0 0 0 0 0 0 0 2.0 h 2\n")
    scans = list(read_carmen(log))
    assert [s.timestamp for s in scans] == [1.5]
