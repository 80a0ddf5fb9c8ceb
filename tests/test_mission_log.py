"""Mission logs (MCAP): run writes them, readers decode them, slam2d runs on them."""

import dataclasses
import json

import numpy as np

from usvdrake import load_scenario, run_mission
from usvdrake.cli import main
from usvdrake.logs.mission_log import decode_scan, encode_scan, read_log_scans, read_log_states
from usvdrake.sensors.messages import LaserScan


def test_scan_codec_round_trip():
    r = np.array([1.5, np.inf, 2.25, 29.0])
    scan = LaserScan(
        time=3.5,
        angle_min=-1.0,
        angle_increment=0.01,
        range_min=0.1,
        range_max=30.0,
        scan_time=0.025,
        ranges=r,
        valid=np.isfinite(r),
    )
    back = decode_scan(encode_scan(scan))
    np.testing.assert_array_equal(back.ranges, r.astype(np.float32))
    np.testing.assert_array_equal(back.valid, np.isfinite(r))
    assert (back.time, back.angle_increment, back.range_max) == (3.5, 0.01, 30.0)


def test_run_records_and_slam2d_replays(tmp_path):
    s = dataclasses.replace(load_scenario("valley_survey"), duration=8.0)
    run_mission(s, out_dir=tmp_path / "run", record=False)
    log = tmp_path / "run" / "log.mcap"
    scans = read_log_scans(log)
    t, states = read_log_states(log)
    assert len(scans) >= 8 * 40 - 2 and len(t) >= 80
    assert np.all(np.diff([s.timestamp for s in scans]) > 0)
    np.testing.assert_allclose(states[0], s.initial_state, atol=1e-9)
    out = tmp_path / "slam"
    assert (
        main(
            [
                "slam2d",
                str(log),
                "--out",
                str(out),
                "--quiet",
                "--reference",
                str(log),
                "--resolution",
                "0.4",
            ]
        )
        == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["scans"] == len(scans)
    assert metrics["ate_m"] < 0.2  # SE(2)-aligned against the log's own ground truth (~7 m path)
