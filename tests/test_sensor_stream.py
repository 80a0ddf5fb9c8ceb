"""Offline 3D SLAM input: the cloud encoding of mission logs, and read_sensor_stream over mission
logs and ROS 2 bags (PointCloud2, Imu, NavSatFix)."""

import json

import numpy as np
import pytest
from _worlds import ROOM
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from usvdrake.logs.mission_log import (
    CLOUD_ENCODING,
    CLOUD_SCHEMA,
    MISSION_PORTS,
    RANGE_LIMIT,
    MissionLogWriter,
    MissionRecorder,
    RecordedPort,
    decode_cloud,
    encode_cloud,
    log_summary,
    quantise_ranges,
    read_mission_log,
)
from usvdrake.logs.sensor_stream import (
    UNKNOWN_COVARIANCE,
    SensorMessage,
    read_ground_truth,
    read_sensor_stream,
    vlp16_elevations,
)
from usvdrake.sensors.lidar3d import Lidar3D, range_image_to_cloud
from usvdrake.sensors.lidar_model import LidarConfig
from usvdrake.sensors.messages import GpsFix, ImuSample, PointCloud
from usvdrake.typed_yaml import ConfigError

VLP16 = LidarConfig(preset="vlp16", mount=[0.0, 0.0, 1.0, 0.0], motion=True, noise=True)
STATE = np.array([1.0, 2.0, 0.5, 1.0, 0.0, 0.2])


def _vlp16_sweep(t_end=0.15) -> PointCloud:
    lidar = Lidar3D(VLP16, ROOM.scene, seed=0)
    sim = Simulator(lidar)
    lidar.GetInputPort("state").FixValue(sim.get_mutable_context(), STATE)
    sim.AdvanceTo(t_end)
    return lidar.GetOutputPort("lidar_points").Eval(sim.get_context())


def _synthetic_cloud(t=2.5, seed=1, azimuths=None) -> PointCloud:
    rng = np.random.default_rng(seed)
    elev = vlp16_elevations()
    az = np.linspace(np.pi, -np.pi, 1800, endpoint=False) if azimuths is None else azimuths
    img = rng.uniform(0.5, 120.0, (16, len(az)))
    img[rng.random(img.shape) < 0.3] = np.inf
    img[0, :5] = [RANGE_LIMIT + 0.01, 200.0, 0.0, np.nan, RANGE_LIMIT - 0.0005]
    col_t = np.arange(len(az)) / len(az) * 0.1
    return range_image_to_cloud(img, az, elev, col_t, t, 0.1, True)


# --- the cloud encoding -----------------------------------------------------------------------
def test_quantisation_error_is_at_most_1mm():
    r = np.random.default_rng(0).uniform(0.0, RANGE_LIMIT, 100_000)
    q = quantise_ranges(r)
    back = q * 0.002
    ok = q != 0xFFFF
    assert ok[r > 0.001].all()  # every return within the limit is kept
    assert np.max(np.abs(back[ok] - r[ok])) <= 0.001 + 1e-12
    # no return, ≤ 0, and beyond the limit → 0xFFFF; the limit itself is kept
    codes = quantise_ranges(np.array([np.inf, np.nan, -1.0, 0.0, RANGE_LIMIT + 0.0011, 131.0]))
    assert codes.tolist() == [0xFFFF] * 5 + [65500]


def test_cloud_round_trip_keeps_ranges_points_and_times():
    cloud = _synthetic_cloud()
    data = encode_cloud(cloud)
    head = json.loads(data.partition(b"\n")[0])
    assert head["rings"] == 16 and head["columns"] == 1800 and head["range_step"] == 0.002
    assert "azimuth_step" in head and "azimuths" not in head  # evenly spaced: start + step
    assert head["column_time_step"] == pytest.approx(0.1 / 1800)
    back = decode_cloud(data)
    a, b = cloud.range_image, back.range_image
    far = np.zeros_like(a, bool)
    far[0, :4] = True  # beyond the limit (2), r = 0, NaN: no return after the round trip
    assert np.isinf(b[far]).all()
    finite = np.isfinite(a) & ~far
    np.testing.assert_array_equal(np.isfinite(b), finite)  # inf preserved, nothing invented
    assert np.max(np.abs(b[finite] - a[finite])) <= 0.001 + 1e-9
    assert b[0, 4] == pytest.approx(RANGE_LIMIT, abs=1e-9)  # just within the limit: kept
    # the points are range_image_to_cloud's of the decoded image, and within 1 mm of the input
    ref = range_image_to_cloud(b, cloud.azimuths, cloud.elevations, np.arange(1800) * 0.1 / 1800)
    np.testing.assert_allclose(back.points, ref.points, atol=1e-12)
    np.testing.assert_array_equal(back.ring, ref.ring)
    np.testing.assert_array_equal(back.column, ref.column)
    keep = ~far[cloud.ring, cloud.column]
    np.testing.assert_array_equal(back.ring, cloud.ring[keep])
    np.testing.assert_array_equal(back.column, cloud.column[keep])
    np.testing.assert_allclose(back.points, cloud.points[keep], atol=0.001 + 1e-9, rtol=0)
    np.testing.assert_allclose(back.point_time, cloud.point_time[keep], atol=1e-12)
    np.testing.assert_allclose(back.azimuths, cloud.azimuths, atol=1e-12)
    np.testing.assert_array_equal(back.elevations, cloud.elevations)
    assert (back.time, back.sweep_time, back.motion_applied) == (2.5, 0.1, True)


def test_uneven_azimuths_are_listed_and_kept():
    az = np.sort(np.random.default_rng(3).uniform(-np.pi, np.pi, 900))
    cloud = _synthetic_cloud(azimuths=az)
    cloud.point_time = np.zeros(len(cloud.points))
    head = json.loads(encode_cloud(cloud).partition(b"\n")[0])
    assert len(head["azimuths"]) == 900 and "azimuth_step" not in head
    back = decode_cloud(encode_cloud(cloud))
    np.testing.assert_array_equal(back.azimuths, az)
    assert not back.point_time.any()


def test_a_vlp16_sweep_is_small():
    cloud = _vlp16_sweep()
    assert cloud.range_image.shape == (16, 1800) and len(cloud.points) > 10_000
    data = encode_cloud(cloud)
    assert len(data) < 25_000  # 16 × 1800 × 2 bytes raw = 57 600; JSON would be ~ 600 000
    back = decode_cloud(data)
    np.testing.assert_allclose(back.points, cloud.points, atol=0.001 + 1e-9, rtol=0)
    np.testing.assert_allclose(back.point_time, cloud.point_time, atol=1e-12)


def test_the_recorder_writes_each_sweep_once(tmp_path):
    assert ("lidar_points", "/lidar_points", "cloud", ()) in MISSION_PORTS
    builder = DiagramBuilder()
    lidar = builder.AddSystem(Lidar3D(VLP16, ROOM.scene, seed=0))
    state = builder.AddSystem(ConstantVectorSource(STATE))
    builder.Connect(state.get_output_port(), lidar.GetInputPort("state"))
    log = tmp_path / "log.mcap"
    with MissionLogWriter(log) as writer:
        ports = [RecordedPort("lidar_points", "/lidar_points", "cloud")]
        recorder = builder.AddSystem(MissionRecorder(writer, ports))
        builder.Connect(lidar.GetOutputPort("lidar_points"), recorder.GetInputPort("lidar_points"))
        Simulator(builder.Build()).AdvanceTo(0.35)
    topic = log_summary(log)["topics"]["/lidar_points"]
    assert (topic["schema"], topic["encoding"]) == (CLOUD_SCHEMA, CLOUD_ENCODING)
    clouds = [m for _, _, m in read_mission_log(log, ["/lidar_points"])]
    # sweeps end at 0.1, 0.2, 0.3 s; the empty one before the first is not written
    np.testing.assert_allclose([c.time for c in clouds], [0.1, 0.2, 0.3], atol=1e-9)
    assert all(isinstance(c, PointCloud) and len(c.points) > 10_000 for c in clouds)


# --- read_sensor_stream on mission logs -------------------------------------------------------
def _fix(t, valid=True):
    return GpsFix(t, valid, 63.4, 10.4, 40.0, np.diag([4.0, 4.0, 9.0]), 0.9, 9 if valid else 0)


def test_mission_log_stream_is_in_time_order(tmp_path):
    log = tmp_path / "log.mcap"
    clouds = [_synthetic_cloud(t=0.1 * k, seed=k) for k in (1, 2, 3)]
    with MissionLogWriter(log) as w:
        for k in range(31):  # IMU at 100 Hz, a little ahead of the lidar, GNSS late
            t = 0.01 * k
            w.write_imu("/imu", ImuSample(t, np.array([0.0, 0.0, k]), np.array([0, 0, 9.8])))
            if k in (10, 20, 30):
                w.write_cloud("/lidar_points", clouds[k // 10 - 1], publish_time=t + 0.001)
            if k == 25:
                w.write_gps("/gps", _fix(0.05))  # written 0.2 s after its time
                w.write_gps("/gps", _fix(0.15, valid=False))
        for k in range(4):
            w.write_state("/ground_truth", 0.1 * k, np.arange(6.0) + k)
    msgs = list(read_sensor_stream(log))
    assert all(isinstance(m, SensorMessage) for m in msgs)
    times = [m.time for m in msgs]
    assert times == sorted(times)
    assert [m.kind for m in msgs].count("lidar") == 3 and len(msgs) == 31 + 3 + 2
    gps = [m.msg for m in msgs if m.kind == "gps"]
    assert [g.valid for g in gps] == [True, False] and gps[0].time == pytest.approx(0.05)
    # the GNSS fix comes out between the IMU samples of its time, not where it was written
    i = next(i for i, m in enumerate(msgs) if m.kind == "gps")
    assert msgs[i - 1].time <= 0.05 <= msgs[i + 1].time
    lidar = [m.msg for m in msgs if m.kind == "lidar"]
    for got, want in zip(lidar, clouds, strict=True):
        ok = np.isfinite(got.range_image)
        assert got.time == want.time and ok.sum() > 10_000
        assert np.max(np.abs(got.range_image[ok] - want.range_image[ok])) <= 0.001 + 1e-9
    # a run folder works as well as its log.mcap; the ground truth comes from read_log_states
    assert len(list(read_sensor_stream(tmp_path))) == len(msgs)
    t, states = read_ground_truth(log)
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2, 0.3])
    assert states.shape == (4, 6) and states[3].tolist() == [3, 4, 5, 6, 7, 8]


def test_mission_log_errors_name_the_path_and_the_topics(tmp_path):
    log = tmp_path / "log.mcap"
    with MissionLogWriter(log) as w:
        w.write_state("/state_estimate", 0.0, np.zeros(6))
    with pytest.raises(ConfigError, match=r"log\.mcap.*/lidar_points.*state_estimate"):
        read_sensor_stream(log)
    assert read_ground_truth(log) is None  # a hardware run has no ground truth
    with MissionLogWriter(log) as w:
        w.write_imu("/imu", ImuSample(0.0, np.ones(3), np.ones(3)))
    with pytest.raises(ConfigError, match=r"lidar messages on /velodyne_points.*only /imu"):
        read_sensor_stream(log, lidar_topic="/velodyne_points")


def test_a_path_that_is_neither_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"missing\.mcap.*expected an MCAP mission log.*nothing"):
        read_sensor_stream(tmp_path / "missing.mcap")
    text = tmp_path / "notes.txt"
    text.write_text("not a log")
    with pytest.raises(ConfigError, match=r"notes\.txt.*ROS 2 bag folder.*got neither"):
        read_sensor_stream(text)
    with pytest.raises(ConfigError, match=r"notes\.txt"):
        read_ground_truth(text)
    with pytest.raises(ValueError, match="got neither"):  # a ConfigError is a ValueError
        read_sensor_stream(tmp_path)  # a folder without log.mcap or metadata.yaml


# --- ROS 2 bags -------------------------------------------------------------------------------
rosbags = pytest.importorskip("rosbags")

STAMP0 = 1_700_000_000


def _ros_types():
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_HUMBLE)


def _header(ts, t, frame="base_link"):
    sec = int(np.floor(t))
    stamp = ts.types["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9))
    return ts.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)


def _velodyne_points(seed=0):
    """A VLP-16-like sweep: (xyz float32, ring, time offset) with NaN no-returns."""
    rng = np.random.default_rng(seed)
    elev = vlp16_elevations()
    cols = 360
    az = -np.pi + (np.arange(cols) + 0.5) * 2 * np.pi / cols
    ring, col = np.meshgrid(np.arange(16), np.arange(cols), indexing="ij")
    ring, col = ring.ravel(), col.ravel()
    r = rng.uniform(2.0, 60.0, len(ring))
    e = elev[ring] + rng.normal(0, 1e-4, len(ring))
    a = az[col] + rng.uniform(-0.2, 0.2, len(ring)) * 2 * np.pi / cols
    xyz = np.column_stack([r * np.cos(e) * np.cos(a), r * np.cos(e) * np.sin(a), r * np.sin(e)])
    xyz = xyz.astype(np.float32)
    xyz[rng.random(len(ring)) < 0.2] = np.nan  # no returns (is_dense false)
    offset = (col / cols * 0.1).astype(np.float32)  # [s] from the header stamp
    return xyz, ring.astype(np.uint16), offset


def _cloud2_with_ring(ts, t, xyz, ring, offset):
    """velodyne_pointcloud's layout: x y z intensity (f32), ring (u16), time (f32), 22 bytes,
    here in 2 rows with 4 padding bytes at the end of each."""
    pf = ts.types["sensor_msgs/msg/PointField"]
    dt = np.dtype(
        {
            "names": ["x", "y", "z", "intensity", "ring", "time"],
            "formats": ["<f4", "<f4", "<f4", "<f4", "<u2", "<f4"],
            "offsets": [0, 4, 8, 12, 16, 18],
            "itemsize": 22,
        }
    )
    pts = np.zeros(len(xyz), dt)
    pts["x"], pts["y"], pts["z"] = xyz.T
    pts["intensity"], pts["ring"], pts["time"] = 7.0, ring, offset
    width = len(xyz) // 2
    rows = pts.view(np.uint8).reshape(2, width * 22)
    data = np.concatenate([rows, np.full((2, 4), 0xAB, np.uint8)], axis=1).ravel()
    fields = [
        pf(name="x", offset=0, datatype=7, count=1),
        pf(name="y", offset=4, datatype=7, count=1),
        pf(name="z", offset=8, datatype=7, count=1),
        pf(name="intensity", offset=12, datatype=7, count=1),
        pf(name="ring", offset=16, datatype=4, count=1),
        pf(name="time", offset=18, datatype=7, count=1),
    ]
    return ts.types["sensor_msgs/msg/PointCloud2"](
        header=_header(ts, t, "velodyne"),
        height=2,
        width=width,
        fields=fields,
        is_bigendian=False,
        point_step=22,
        row_step=width * 22 + 4,
        data=data,
        is_dense=False,
    )


def _cloud2_big_endian_f64(ts, t, xyz, offset_ns):
    """No ring field: float64 xyz, uint32 ``t`` [ns] (Ouster), big-endian."""
    pf = ts.types["sensor_msgs/msg/PointField"]
    dt = np.dtype({"names": ["t", "x", "y", "z"], "formats": [">u4", ">f8", ">f8", ">f8"]})
    pts = np.zeros(len(xyz), dt)
    pts["x"], pts["y"], pts["z"] = xyz.astype(float).T
    pts["t"] = offset_ns
    fields = [
        pf(name="t", offset=0, datatype=6, count=1),
        pf(name="x", offset=4, datatype=8, count=1),
        pf(name="y", offset=12, datatype=8, count=1),
        pf(name="z", offset=20, datatype=8, count=1),
    ]
    return ts.types["sensor_msgs/msg/PointCloud2"](
        header=_header(ts, t, "os_lidar"),
        height=1,
        width=len(xyz),
        fields=fields,
        is_bigendian=True,
        point_step=dt.itemsize,
        row_step=dt.itemsize * len(xyz),
        data=pts.view(np.uint8).copy(),
        is_dense=False,
    )


def _imu(ts, t, k):
    v3, q = ts.types["geometry_msgs/msg/Vector3"], ts.types["geometry_msgs/msg/Quaternion"]
    return ts.types["sensor_msgs/msg/Imu"](
        header=_header(ts, t, "imu"),
        orientation=q(x=0.0, y=0.0, z=np.sin(0.1 * k), w=np.cos(0.1 * k)),
        orientation_covariance=np.zeros(9),
        angular_velocity=v3(x=0.01, y=-0.02, z=0.1 * k),
        angular_velocity_covariance=np.zeros(9),
        linear_acceleration=v3(x=0.5, y=0.0, z=9.81),
        linear_acceleration_covariance=np.zeros(9),
    )


def _fix_msg(ts, t, status, cov_type, cov):
    st = ts.types["sensor_msgs/msg/NavSatStatus"](status=status, service=1)
    return ts.types["sensor_msgs/msg/NavSatFix"](
        header=_header(ts, t, "gps"),
        status=st,
        latitude=63.43,
        longitude=10.39,
        altitude=45.5,
        position_covariance=np.asarray(cov, float),
        position_covariance_type=cov_type,
    )


@pytest.fixture(scope="module")
def ros2_bag(tmp_path_factory):
    from rosbags.rosbag2 import Writer

    ts = _ros_types()
    path = tmp_path_factory.mktemp("bags") / "sweeps"
    xyz, ring, offset = _velodyne_points()
    ns = int(STAMP0 * 1e9)
    with Writer(path, version=9) as w:
        c_pts = w.add_connection("/velodyne_points", "sensor_msgs/msg/PointCloud2", typestore=ts)
        c_os = w.add_connection("/ouster/points", "sensor_msgs/msg/PointCloud2", typestore=ts)
        c_imu = w.add_connection("/imu/data", "sensor_msgs/msg/Imu", typestore=ts)
        c_fix = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)

        def put(conn, msg, t_bag):
            w.write(conn, ns + int(t_bag * 1e9), ts.serialize_cdr(msg, conn.msgtype))

        for k in range(30):  # IMU at 100 Hz
            put(c_imu, _imu(ts, STAMP0 + 0.01 * k, k), 0.01 * k + 0.002)
        # the sweep is stamped at its start (0.05) and ends at 0.05 + max offset
        put(c_pts, _cloud2_with_ring(ts, STAMP0 + 0.05, xyz, ring, offset), 0.16)
        ok = np.isfinite(xyz).all(axis=1)
        put(
            c_os,
            _cloud2_big_endian_f64(ts, STAMP0 + 0.05, xyz[ok], 1000 * np.arange(ok.sum())),
            0.16,
        )
        cov = [1.0, 0.1, 0.0, 0.1, 2.0, 0.0, 0.0, 0.0, 9.0]
        put(c_fix, _fix_msg(ts, STAMP0 + 0.12, 0, 3, cov), 0.121)
        put(c_fix, _fix_msg(ts, STAMP0 + 0.13, -1, 0, np.zeros(9)), 0.131)
        unknown = _fix_msg(ts, 0.0, 2, 0, np.zeros(9))  # stamp 0: the bag time (0.2) counts
        put(c_fix, unknown, 0.2)
    return path, xyz, ring, offset


def test_ros2_bag_stream(ros2_bag):
    path, xyz, ring, offset = ros2_bag
    with pytest.raises(ConfigError, match=r"one sensor_msgs/msg/PointCloud2 topic.*ouster"):
        read_sensor_stream(path)  # two PointCloud2 topics: which one?
    msgs = list(read_sensor_stream(path, lidar_topic="/velodyne_points"))
    times = [m.time for m in msgs]
    assert times == sorted(times)
    assert [m.kind for m in msgs].count("imu") == 30 and len(msgs) == 30 + 1 + 3
    # IMU: values and times from the header stamps
    imu = [m.msg for m in msgs if m.kind == "imu"]
    assert imu[7].time == pytest.approx(STAMP0 + 0.07, abs=1e-6)
    np.testing.assert_allclose(imu[7].angular_velocity, [0.01, -0.02, 0.7])
    np.testing.assert_allclose(imu[7].linear_acceleration, [0.5, 0.0, 9.81])
    np.testing.assert_allclose(imu[7].orientation, [0, 0, np.sin(0.7), np.cos(0.7)])
    # NavSatFix: validity from status, covariance as given or 100 m² when unknown
    gps = [m.msg for m in msgs if m.kind == "gps"]
    assert [g.valid for g in gps] == [True, False, True]
    np.testing.assert_array_equal(gps[0].covariance_enu, [[1, 0.1, 0], [0.1, 2, 0], [0, 0, 9]])
    assert (gps[0].latitude, gps[0].longitude, gps[0].altitude) == (63.43, 10.39, 45.5)
    np.testing.assert_array_equal(gps[2].covariance_enu, UNKNOWN_COVARIANCE)
    assert UNKNOWN_COVARIANCE[0, 0] == 100.0
    assert gps[2].time == pytest.approx(STAMP0 + 0.2, abs=1e-6)  # stamp 0 → bag time
    # PointCloud2 with ring and time: every finite point kept, on its own ring, with its time
    (cloud,) = [m.msg for m in msgs if m.kind == "lidar"]
    ok = np.isfinite(xyz).all(axis=1)
    assert cloud.time == pytest.approx(STAMP0 + 0.05 + offset.max(), abs=1e-6)
    assert cloud.sweep_time == pytest.approx(offset.max(), abs=1e-7)
    assert cloud.range_image.shape == (16, 1800) and cloud.motion_applied
    assert len(cloud.points) == ok.sum() == np.isfinite(cloud.range_image).sum()
    order = np.lexsort((cloud.column, cloud.ring))
    src = np.flatnonzero(ok)  # the input, ring-major in column order as generated
    np.testing.assert_array_equal(cloud.points[order], xyz[src].astype(float))
    np.testing.assert_array_equal(cloud.ring[order], ring[src])
    np.testing.assert_allclose(cloud.point_time[order], offset[src].astype(float), atol=1e-9)
    np.testing.assert_allclose(
        cloud.range_image[cloud.ring, cloud.column], np.linalg.norm(cloud.points, axis=1)
    )
    # ring elevations measured from the points (no elevations given): the VLP-16's
    np.testing.assert_allclose(cloud.elevations, vlp16_elevations(), atol=1e-3)


def test_ros2_bag_cloud_without_ring_is_binned_by_elevation(ros2_bag):
    path, xyz, ring, _ = ros2_bag
    msgs = list(read_sensor_stream(path, lidar_topic="/ouster/points", imu_topic="/imu/data"))
    (cloud,) = [m.msg for m in msgs if m.kind == "lidar"]
    ok = np.isfinite(xyz).all(axis=1)
    assert len(cloud.points) == ok.sum()  # one point per pixel: nothing merged
    order = np.lexsort((cloud.column, cloud.ring))
    np.testing.assert_array_equal(cloud.ring[order], ring[ok])  # elevation bins = true rings
    np.testing.assert_array_equal(cloud.points[order], xyz[ok].astype(float))
    # integer t [ns] → s, from the first point
    np.testing.assert_allclose(cloud.point_time[order], 1e-6 * np.arange(ok.sum()), atol=1e-12)
    assert cloud.time == pytest.approx(STAMP0 + 0.05 + 1e-6 * (ok.sum() - 1), abs=1e-6)
    assert [m.kind for m in msgs].count("gps") == 3


def test_ros2_bag_errors_list_what_is_there(ros2_bag):
    path = ros2_bag[0]
    with pytest.raises(
        ConfigError,
        match=r"sweeps.*PointCloud2 messages on /points.*"
        r"/fix \(sensor_msgs/msg/NavSatFix\).*/imu/data \(sensor_msgs/msg/Imu\)",
    ):
        read_sensor_stream(path, lidar_topic="/points")
    assert read_ground_truth(path) is None
