"""Mission logs (MCAP): run writes them, readers decode them, slam2d runs on them."""

import dataclasses
import json

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from usvdrake import load_scenario, run_mission
from usvdrake.cli import main
from usvdrake.logs.mission_log import (
    MissionLogWriter,
    add_mission_recorder,
    decode_scan,
    encode_scan,
    log_summary,
    read_log_scans,
    read_log_states,
    read_log_vectors,
    read_mission_log,
)
from usvdrake.logs.mission_log.codecs import _encode_imu_json, decode_imu, encode_imu
from usvdrake.sensors.messages import GpsFix, ImuSample, LaserScan

# the fields Foxglove's own schemas require (foxglove/schemas, jsonschema/*.json)
FOXGLOVE_REQUIRED = {
    "foxglove.LaserScan": [
        "timestamp",
        "frame_id",
        "pose",
        "start_angle",
        "end_angle",
        "ranges",
        "intensities",
    ],
    "foxglove.LocationFix": [
        "timestamp",
        "frame_id",
        "latitude",
        "longitude",
        "altitude",
        "position_covariance",
        "position_covariance_type",
        "metadata",
    ],
    "foxglove.PoseInFrame": ["timestamp", "frame_id", "pose"],
}


def _scan(t=3.5, r=(1.5, np.inf, 2.25, 29.0)):
    r = np.asarray(r, float)
    return LaserScan(
        time=t,
        angle_min=-1.0,
        angle_increment=0.01,
        range_min=0.1,
        range_max=30.0,
        scan_time=0.025,
        ranges=r,
        valid=np.isfinite(r),
    )


def test_imu_encoder_writes_what_json_writes():
    """The written-out IMU encoder gives json.dumps's bytes; non-finite samples take the json
    path (null)."""
    rng = np.random.default_rng(4)
    for t in (0.0, 0.01, 123.456789, 1e5 + 1e-7):
        w, a, q = rng.normal(size=3), rng.normal(size=3) * 9.81, rng.normal(size=4)
        sample = ImuSample(time=t, angular_velocity=w, linear_acceleration=a, orientation=q)
        want = _encode_imu_json(
            t, list(map(float, w)), list(map(float, a)), list(map(float, q)), "imu"
        )
        assert encode_imu(sample) == want
        back = decode_imu(encode_imu(sample))
        assert back.time == t and np.array_equal(back.orientation, q)
    bad = ImuSample(time=1.0, angular_velocity=[np.nan, 0, 0], linear_acceleration=[0, 0, 9.8],
                    orientation=[0, 0, 0, 1])  # fmt: skip
    assert json.loads(encode_imu(bad))["angular_velocity"]["x"] is None


def test_scan_codec_round_trip():
    scan = _scan()
    data = encode_scan(scan)
    m = json.loads(data)  # foxglove.LaserScan: no return is 0 (JSON has no inf)
    assert m["ranges"] == [1.5, 0.0, 2.25, 29.0] and m["intensities"] == []
    assert m["timestamp"] == {"sec": 3, "nsec": 500_000_000}
    assert m["end_angle"] == pytest.approx(-0.97)
    back = decode_scan(data)
    np.testing.assert_array_equal(back.ranges, scan.ranges)
    np.testing.assert_array_equal(back.valid, scan.valid)
    assert (back.time, back.angle_min, back.angle_increment, back.range_max) == (
        3.5,
        -1.0,
        0.01,
        30.0,
    )


def _write_every_kind(path, n=5):
    """n messages of every kind the writer has, at t = 0.1 k; returns what was written."""
    written = []
    with MissionLogWriter(path) as w:
        for k in range(n):
            t = 0.1 * k
            q = np.arange(6.0) + k
            scan = _scan(t, [1.0 + k, np.inf, 2.0])
            fix = GpsFix(
                time=t,
                valid=k % 2 == 0,
                latitude=63.4 + 1e-6 * k,
                longitude=10.4,
                altitude=40.0,
                covariance_enu=np.diag([4.0, 4.0, 9.0]),
                hdop=0.9,
                satellites=9,
                speed=1.5,
                course=0.3,
            )
            imu = ImuSample(t, np.array([0.1, 0.2, k]), np.array([0.0, 0.1, 9.8]))
            w.write_state("/ground_truth", t, q)
            w.write_vector("/thruster_command", t, [k, 2, 3, 4], ["port", "stbd", "bow", "aft"])
            w.write_pose("/slam_pose", t, [1.0, 2.0, 0.3 * k])
            w.write_scan("/lidar_scan", scan)
            w.write_gps("/gps", fix)
            w.write_imu("/imu", imu)
            written.append((t, q, scan, fix, imu))
    return written


def test_every_channel_round_trips(tmp_path):
    log = tmp_path / "log.mcap"
    written = _write_every_kind(log)
    msgs = list(read_mission_log(log))
    assert [t for _, t, _ in msgs] == sorted(t for _, t, _ in msgs)
    by_topic = {}
    for topic, t, m in msgs:
        by_topic.setdefault(topic, []).append((t, m))
    assert set(by_topic) == {
        "/ground_truth",
        "/thruster_command",
        "/slam_pose",
        "/lidar_scan",
        "/gps",
        "/gps/no_fix",
        "/imu",
    }
    t, states = read_log_states(log)
    np.testing.assert_allclose(t, [w[0] for w in written])
    np.testing.assert_array_equal(states, [w[1] for w in written])
    t, v, names = read_log_vectors(log, "/thruster_command")
    assert names == ["port", "stbd", "bow", "aft"] and v[:, 0].tolist() == [0, 1, 2, 3, 4]
    _, poses, names = read_log_vectors(log, "/slam_pose")
    assert names == ["x", "y", "psi"] and poses[4].tolist() == pytest.approx([1.0, 2.0, 1.2])
    # a topic with no messages yet (a log being written) reads as empty, not an error
    t, v, names = read_log_vectors(log, "/hil/clock")
    assert t.shape == (0,) and v.shape == (0, 0) and names == []
    pose_msg = by_topic["/slam_pose"][1][1]
    assert pose_msg["pose"]["orientation"]["z"] == pytest.approx(np.sin(0.15))
    scans = read_log_scans(log)
    assert len(scans) == 5
    for rec, w in zip(scans, written, strict=True):
        assert rec.timestamp == w[0] == rec.scan.time
        np.testing.assert_array_equal(rec.scan.ranges, w[2].ranges)
        np.testing.assert_array_equal(rec.scan.valid, w[2].valid)
    fixes = [m for _, m in by_topic["/gps"] + by_topic["/gps/no_fix"]]
    fixes.sort(key=lambda f: f.time)
    for f, w in zip(fixes, written, strict=True):
        assert (f.time, f.valid, f.satellites) == (w[3].time, w[3].valid, 9)
        if f.valid:
            assert (f.latitude, f.longitude, f.altitude, f.hdop) == (w[3].latitude, 10.4, 40, 0.9)
            np.testing.assert_array_equal(f.covariance_enu, w[3].covariance_enu)
    for (_, m), w in zip(by_topic["/imu"], written, strict=True):
        assert m.time == w[4].time
        np.testing.assert_array_equal(m.angular_velocity, w[4].angular_velocity)
        np.testing.assert_array_equal(m.orientation, [0, 0, 0, 1])
    summary = log_summary(log)
    assert summary["complete"] and summary["messages"] == len(msgs) == 30
    assert summary["topics"]["/gps"]["messages"] == 3
    assert summary["topics"]["/lidar_scan"]["schema"] == "foxglove.LaserScan"
    assert (summary["first_time"], summary["last_time"]) == (0.0, 0.4)


def test_every_schema_and_message_is_valid_json(tmp_path):
    jsonschema = pytest.importorskip("jsonschema")
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    log = tmp_path / "log.mcap"
    _write_every_kind(log)
    schemas, channels, seen = {}, {}, set()
    with open(log, "rb") as f:
        for record in StreamReader(f).records:
            if isinstance(record, Schema):
                assert record.encoding == "jsonschema"
                schema = json.loads(record.data)
                assert schema["title"] == record.name
                jsonschema.Draft202012Validator.check_schema(schema)
                schemas[record.id] = schema
            elif isinstance(record, Channel):
                assert record.message_encoding == "json"
                channels[record.id] = schemas[record.schema_id]
            elif isinstance(record, Message):
                schema = channels[record.channel_id]
                m = json.loads(record.data)  # strict JSON: no NaN / Infinity
                jsonschema.validate(m, schema, cls=jsonschema.Draft202012Validator)
                for field in FOXGLOVE_REQUIRED.get(schema["title"], []):
                    assert field in m, (schema["title"], field)
                seen.add(schema["title"])
    assert {"foxglove.LaserScan", "foxglove.LocationFix", "foxglove.PoseInFrame"} <= seen
    assert {"usvdrake.VesselState", "usvdrake.Imu", "usvdrake.GpsNoFix"} <= seen


def test_logs_of_the_first_encoding_still_read(tmp_path):
    """usvdrake/state-v1 and usvdrake/laserscan-v1 (chunked, as the first writer made them)."""
    from mcap.writer import Writer

    log = tmp_path / "old.mcap"
    with open(log, "wb") as f:
        w = Writer(f)
        w.start(profile="usvdrake", library="usvdrake")
        schema = w.register_schema(name="usvdrake", encoding="", data=b"")
        state = w.register_channel("/ground_truth", "usvdrake/state-v1", schema)
        scan_ch = w.register_channel("/lidar_scan", "usvdrake/laserscan-v1", schema)
        for k in range(3):
            t, ns = 0.1 * k, int(1e8 * k)
            q = [float(k), 1.0, 2.0, 3.0, 4.0, 5.0]
            w.add_message(state, ns, json.dumps({"t": t, "q": q}).encode(), ns)
            scan = _scan(t, [1.0, np.inf, 2.5])
            head = {
                "t": t,
                "angle_min": scan.angle_min,
                "angle_increment": scan.angle_increment,
                "range_min": scan.range_min,
                "range_max": scan.range_max,
                "scan_time": scan.scan_time,
                "n": 3,
            }
            data = json.dumps(head).encode() + b"\n" + np.asarray(scan.ranges, "<f4").tobytes()
            w.add_message(scan_ch, ns, data, ns)
        w.finish()
    t, states = read_log_states(log)
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2])
    assert states[:, 0].tolist() == [0.0, 1.0, 2.0] and states.shape == (3, 6)
    scans = read_log_scans(log)
    assert len(scans) == 3
    np.testing.assert_array_equal(scans[2].scan.ranges, [1.0, np.inf, 2.5])
    np.testing.assert_array_equal(scans[2].scan.valid, [True, False, True])
    assert log_summary(log)["complete"]


def test_a_log_cut_anywhere_reads_up_to_the_cut(tmp_path):
    log = tmp_path / "log.mcap"
    _write_every_kind(log, n=2)
    data = log.read_bytes()
    full = list(read_mission_log(log, log_time_order=False))
    cut = tmp_path / "cut.mcap"
    rng = np.random.default_rng(0)
    offsets = sorted({0, 7, 8, 9, len(data) - 1, *rng.integers(0, len(data), 150).tolist()})
    previous = 0
    for n in offsets:
        cut.write_bytes(data[:n])
        got = list(read_mission_log(cut, log_time_order=False))
        assert len(got) >= previous  # a prefix of the messages, growing with the file
        previous = len(got)
        for (topic, t, _), (topic2, t2, _) in zip(got, full, strict=False):
            assert (topic, t) == (topic2, t2)
        s = log_summary(cut)
        assert s["messages"] == len(got)
        assert not s["complete"] or n >= len(data) - 8  # only the footer's trailing magic cut
    assert log_summary(log)["complete"]


def test_the_writer_flushes_on_log_time_and_on_wall_time(tmp_path):
    import time

    log = tmp_path / "log.mcap"
    w = MissionLogWriter(log, flush_period=0.5)
    try:
        for k in range(8):  # 0.7 s of log time written in a moment: flushed by the log clock
            w.write_vector("/k", 0.1 * k, [k], ["k"])
        got = [m["k"] for _, _, m in read_mission_log(log)]
        assert got[:6] == [0, 1, 2, 3, 4, 5]
        assert not log_summary(log)["complete"]
        w.write_vector("/k", 0.75, [8], ["k"])  # then nothing: the timer flushes it
        time.sleep(1.0)
        assert [m["k"] for _, _, m in read_mission_log(log)] == list(range(9))
    finally:
        w.close()
    assert log_summary(log)["complete"]


class _Sensors(LeafSystem):
    """Every 0.1 s a new scan, fix and IMU sample stamped with the update time."""

    def __init__(self):
        super().__init__()
        self._scan = self.DeclareAbstractState(AbstractValue.Make(LaserScan()))
        self._gps = self.DeclareAbstractState(AbstractValue.Make(GpsFix()))
        self._imu = self.DeclareAbstractState(AbstractValue.Make(ImuSample()))
        self.DeclarePeriodicUnrestrictedUpdateEvent(0.1, 0.0, self._update)
        self.DeclareStateOutputPort("lidar_scan", self._scan)
        self.DeclareStateOutputPort("gps", self._gps)
        self.DeclareStateOutputPort("imu", self._imu)

    def _update(self, context, state):
        t = context.get_time()
        state.get_mutable_abstract_state(self._scan).set_value(_scan(t, [1.0 + t, 2.0]))
        fix = GpsFix(time=t, valid=t < 0.55, latitude=63.0 + t, longitude=10.0, satellites=7)
        state.get_mutable_abstract_state(self._gps).set_value(fix)
        imu = ImuSample(t, np.array([0.0, 0.0, 1.0 + t]), np.array([0.0, 0.0, 9.8]))
        state.get_mutable_abstract_state(self._imu).set_value(imu)


def test_add_mission_recorder_records_what_the_system_has(tmp_path):
    inner = DiagramBuilder()
    sensors = inner.AddSystem(_Sensors())
    estimate = inner.AddSystem(ConstantVectorSource(np.arange(6.0)))
    command = inner.AddSystem(ConstantVectorSource([1.0, -1.0]))
    for port in ("lidar_scan", "gps", "imu"):
        inner.ExportOutput(sensors.GetOutputPort(port), port)
    inner.ExportOutput(estimate.get_output_port(), "state_estimate")
    inner.ExportOutput(command.get_output_port(), "thruster_command")
    vessel = inner.Build()

    log = tmp_path / "log.mcap"
    builder = DiagramBuilder()
    builder.AddSystem(vessel)
    with MissionLogWriter(log) as writer:
        recorder = add_mission_recorder(builder, vessel, writer, rate_hz=5.0)
        assert [p.port for p in recorder.recorded_ports] == [
            "state_estimate",
            "thruster_command",
            "lidar_scan",
            "gps",
            "imu",
        ]
        simulator = Simulator(builder.Build())
        simulator.AdvanceTo(1.0)
    s = log_summary(log)
    counts = {topic: c["messages"] for topic, c in s["topics"].items()}
    # vectors at 5 Hz from t = 0; each sensor message once (the t = 1.0 one is not out yet);
    # without ground truth, Foxglove's world → base_link (/tf) and /vessel_pose are the estimate
    # (no sensor systems or vessel plant in this diagram: no static frames, no hull)
    assert counts == {
        "/state_estimate": 6,
        "/thruster_command": 6,
        "/lidar_scan": 10,
        "/gps": 6,
        "/gps/no_fix": 4,
        "/imu": 10,
        "/tf": 6,
        "/vessel_pose": 6,
    }
    assert recorder.tf_port == "state_estimate" and recorder.frames == {}
    scans = read_log_scans(log)
    np.testing.assert_allclose([r.timestamp for r in scans], 0.1 * np.arange(10), atol=1e-9)
    imu = [m for topic, _, m in read_mission_log(log, ["/imu"])]
    np.testing.assert_allclose([m.angular_velocity[2] for m in imu], 1 + 0.1 * np.arange(10))
    t, v, names = read_log_vectors(log, "/thruster_command")
    assert names == ["thruster_0", "thruster_1"] and v.tolist() == [[1.0, -1.0]] * 6
    t, est = read_log_states(log, "/state_estimate")
    np.testing.assert_allclose(t, 0.2 * np.arange(6))


def test_run_records_and_slam2d_replays(tmp_path):
    s = dataclasses.replace(load_scenario("valley_survey"), duration=8.0)
    run_mission(s, out_dir=tmp_path / "run", record=False)
    log = tmp_path / "run" / "log.mcap"
    scans = read_log_scans(log)
    t, states = read_log_states(log)
    assert len(scans) >= 8 * 40 - 2 and len(t) >= 80
    assert np.all(np.diff([s.timestamp for s in scans]) > 0)
    np.testing.assert_allclose(states[0], s.initial_state, atol=1e-9)
    summary = log_summary(log)
    assert summary["complete"]
    assert {
        "/ground_truth",
        "/state_estimate",
        "/thruster_command",
        "/thrust_applied",
        "/reference",
        "/slam_pose",
        "/lidar_scan",
    } <= set(summary["topics"])
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
