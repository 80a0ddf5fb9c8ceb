"""Hardware sources (IMU, 2D lidars, VLP-16) against the device models of hardware_io/devices.py
on pseudo-terminals / a UDP socket."""

from __future__ import annotations

import dataclasses
import math
import socket
import time

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder

from hardware_io.codecs import imu as mt
from hardware_io.codecs import rplidar as rp
from hardware_io.codecs import scip
from hardware_io.codecs import velodyne as vlp
from hardware_io.emulators.devices import (
    SCIP_NO_RETURN_MM,
    RplidarDevice,
    ScipDevice,
    Vlp16Device,
    XsensDevice,
)
from hardware_io.emulators.pty_link import PtyDevice, WireFaults
from hardware_io.systems.imu_serial_source import GOTO_MEASUREMENT, ImuSerialSource
from hardware_io.systems.lidar_serial_source import LidarSerialSource
from hardware_io.systems.velodyne_udp_source import VelodyneUdpSource
from hardware_io.transport import UdpTransport
from usvdrake.sensors.messages import ImuSample, LaserScan, PointCloud

# ------------------------------------------------------------------------------------------
# helpers


def _simulate(source, port_name: str):
    builder = DiagramBuilder()
    builder.AddSystem(source)
    builder.ExportOutput(source.GetOutputPort(port_name), port_name)
    diagram = builder.Build()
    sim = Simulator(diagram)
    sim.Initialize()
    root = sim.get_context()
    return sim, diagram, source.GetMyContextFromRoot(root)


def _write_all(pty: PtyDevice, data: bytes, chunk: int = 1024) -> None:
    pos, deadline = 0, time.monotonic() + 2.0
    while pos < len(data) and time.monotonic() < deadline:
        n = pty.write(data[pos : pos + chunk])
        pos += n
        if n == 0:
            time.sleep(0.001)


def _service(pty: PtyDevice, device) -> None:
    """Let the device model answer whatever the host wrote."""
    data = pty.read()
    if data:
        reply = device.feed(data)
        if reply:
            _write_all(pty, reply)


def _run_serial(source, port_name, pty, device, emit, steps, dt, check=None, drain=5):
    """Drive ``steps`` steps: device answers the host, emits ``emit(k)`` bytes, simulation
    advances ``dt``; ``check(source_context)`` after each step; then ``drain`` steps without
    emitting. Returns the source context."""
    sim, diagram, ctx = _simulate(source, port_name)
    t = 0.0
    for k in range(steps):
        _service(pty, device)
        data = emit(k)
        if data:
            _write_all(pty, data)
        time.sleep(0.002)
        t += dt
        sim.AdvanceTo(t)
        if check is not None:
            check(ctx)
    for _ in range(drain):  # let the last bytes through (the kernel may lag under load)
        _service(pty, device)
        time.sleep(0.005)
        t += dt
        sim.AdvanceTo(t)
        if check is not None:
            check(ctx)
    return ctx


def _emitter(encode, items, sent):
    """``emit(k)``: the device's bytes for ``items[k]``, remembering in ``sent`` what went out."""

    def emit(k):
        data = encode(items[k])
        if data:
            sent.append(items[k])
        return data

    return emit


def _rplidar_scan(rng, time_s: float = 0.0) -> LaserScan:
    n = 360
    r = rng.uniform(0.2, 11.5, n)
    valid = rng.random(n) > 0.1
    return LaserScan(
        time=time_s,
        angle_min=-math.pi,
        angle_increment=2 * math.pi / n,
        range_min=0.15,
        range_max=12.0,
        ranges=np.where(valid, r, np.inf),
        valid=valid,
    )


def _utm_scan(rng, time_s: float = 0.0) -> LaserScan:
    g = scip.UTM30LX
    r = rng.uniform(0.05, 29.9, g.steps)
    valid = rng.random(g.steps) > 0.1
    return LaserScan(
        time=time_s,
        angle_min=math.radians(g.step0_deg),
        angle_increment=math.radians(g.step_deg),
        range_min=g.range_min,
        range_max=g.range_max,
        ranges=np.where(valid, r, np.inf),
        valid=valid,
    )


def _imu_sample(rng, time_s: float) -> ImuSample:
    q = rng.normal(size=4)
    return ImuSample(
        time=time_s,
        angular_velocity=rng.normal(0, 0.5, 3),
        linear_acceleration=rng.normal(0, 1, 3) + [0, 0, 9.81],
        orientation=q / np.linalg.norm(q),
    )


def _f32(v) -> np.ndarray:
    return np.asarray(v, float).astype(np.float32).astype(float)


# ------------------------------------------------------------------------------------------
# device models: handshakes


def test_rplidar_device_handshake():
    dev = RplidarDevice()
    health = dev.feed(b"\x00\x13" + rp.encode_request(rp.CMD_GET_HEALTH))  # garbage first
    assert rp.decode_descriptor(health[:7]) == rp.ResponseDescriptor(3, 0, rp.ANS_TYPE_DEVHEALTH)
    assert health[7:] == b"\x00\x00\x00" and dev.ignored_bytes == 2
    info = dev.feed(rp.encode_request(rp.CMD_GET_INFO))
    assert rp.decode_descriptor(info[:7]).data_type == rp.ANS_TYPE_DEVINFO
    assert len(info) == 7 + 20 and info[7] == RplidarDevice.MODEL
    assert dev.feed(rp.encode_request(0xF0, (660).to_bytes(2, "little"))) == b""  # motor PWM
    assert dev.scan_bytes(_rplidar_scan(np.random.default_rng(0))) == b""  # not scanning
    assert dev.feed(b"\xa5\x25") == b""
    assert dev.feed(b"\xa5") == b"" and not dev.scanning  # SCAN split across reads
    assert dev.feed(b"\x20") == rp.SCAN_DESCRIPTOR == bytes.fromhex("a55a0500004081")
    assert dev.scanning
    assert dev.feed(rp.encode_request(rp.CMD_GET_HEALTH)) == b""  # ignored while scanning
    scan = _rplidar_scan(np.random.default_rng(1))
    nodes = rp.decode_nodes(dev.scan_bytes(scan))
    assert len(nodes) == 360 and nodes[0].start and not any(n.start for n in nodes[1:])
    assert sum(n.distance_q2 > 0 for n in nodes) == int(scan.valid.sum())
    assert dev.feed(rp.encode_request(rp.CMD_STOP)) == b"" and not dev.scanning
    assert dev.scan_bytes(scan) == b""


def test_scip_device_handshake():
    dev = ScipDevice()
    assert dev.feed(b"SCIP2.0\n") == b"SCIP2.0\n00P\n\n"
    r = scip.decode_response(dev.feed(b"BM\n"))
    assert (r.command.name, r.status) == ("BM", "00") and dev.laser_on
    assert scip.decode_response(dev.feed(b"BM\r\n")).status == "02"  # CR LF accepted
    pp = scip.decode_response(dev.feed(b"PP\n"))
    assert b"AMAX:1080" in pp.lines and b"AFRT:540" in pp.lines and b"DMAX:30000" in pp.lines
    assert scip.decode_response(dev.feed(b"VV;ab\n")).command.string == "ab"
    assert dev.feed(b"XX\n") == b"XX\n0Ee\n\n"  # undefined command
    assert dev.feed(b"MD12\n").endswith(b"0C" + bytes([scip.checksum(b"0C")]) + b"\n\n")
    assert scip.decode_response(dev.feed(b"MD0000200001000\n")).status == "04"  # beyond AMAX
    scan = _utm_scan(np.random.default_rng(2), time_s=12.345)
    assert dev.scan_bytes(scan) == b""  # nothing requested yet
    md = scip.encode_scan_command("MD", 0, 1080, 1, 0, 2)  # two scans
    ack = scip.decode_response(dev.feed(md))
    assert ack.status == "00" and dev.command is not None
    d1 = scip.decode_response(dev.scan_bytes(scan))
    assert d1.status == "99" and d1.command.num_scans == 1 and d1.timestamp_ms == 12345
    mm = np.where(scan.valid, np.rint(scan.ranges * 1000), SCIP_NO_RETURN_MM)
    assert np.array_equal(d1.distances_mm, mm.astype(int))
    assert scip.decode_response(dev.scan_bytes(scan)).command.num_scans == 0
    assert dev.command is None and dev.scan_bytes(scan) == b""  # done after two scans
    # GD: answered by the next revolution, with 3-step clusters (the nearest valid return)
    assert dev.feed(scip.encode_scan_command("GD", 3, 8, 3)) == b""
    gd = scip.decode_response(dev.scan_bytes(scan))
    assert gd.status == "00" and len(gd.distances_mm) == 2
    assert gd.distances_mm[0] == min(v for v in mm[3:6] if v >= 20)
    assert scip.decode_response(dev.feed(b"QT\n")).status == "00" and not dev.laser_on
    assert scip.decode_response(dev.feed(b"GD0000108001\n")).status == "10"  # laser off


def test_xsens_device_handshake():
    dev = XsensDevice()
    rng = np.random.default_rng(3)
    s0, s1 = _imu_sample(rng, 1.0), _imu_sample(rng, 1.01)
    m0 = mt.decode_mtdata2(dev.sample_bytes(s0))
    m1 = mt.decode_mtdata2(dev.sample_bytes(s1))
    assert (m0.packet_counter, m1.packet_counter) == (0, 1)
    assert m1.sample_time_fine == 10100
    assert np.array_equal(m0.rate_of_turn, _f32(s0.angular_velocity))
    assert dev.feed(b"\x00garbage" + mt.encode_frame(0x30, b"")) == bytes.fromhex("faff3100d0")
    assert not dev.measuring and dev.sample_bytes(s0) == b""
    bid, mid, data = mt.decode_frame(dev.feed(mt.encode_frame(0x00, b"")))
    assert mid == 0x01 and int.from_bytes(data, "big") == dev.device_id
    assert mt.decode_frame(dev.feed(mt.encode_frame(0x1C, b"")))[2] == b"MTi-30-2A8G4"
    cfg = bytes.fromhex("2030 0064 4020 0064")
    assert mt.decode_frame(dev.feed(mt.encode_frame(0xC0, cfg))) == (0xFF, 0xC1, cfg)
    bad = bytearray(GOTO_MEASUREMENT)
    bad[-1] ^= 1
    assert dev.feed(bytes(bad)) == b"" and not dev.measuring  # bad checksum: ignored
    assert GOTO_MEASUREMENT == bytes.fromhex("faff1000f1")
    assert dev.feed(GOTO_MEASUREMENT) == bytes.fromhex("faff1100f0") and dev.measuring
    assert mt.decode_mtdata2(dev.sample_bytes(s0)).packet_counter == 2


def test_vlp16_device_packets():
    asm = vlp.SweepAssembler(0.2)
    cloud = PointCloud(
        elevations=asm.elevations,
        azimuths=asm.azimuths,
        range_image=np.full((16, 1800), 12.3456),
    )
    dev = Vlp16Device()
    packets = dev.sweep_packets(cloud)
    assert len(packets) == 75 and all(len(p) == vlp.PACKET_SIZE for p in packets)
    p0 = vlp.decode_packet(packets[0])
    assert p0.azimuth_cdeg[:3].tolist() == [0, 40, 80] and p0.timestamp_us == 0
    assert np.all(p0.distance == 6173)  # 12.3456 m / 2 mm, rounded
    assert vlp.decode_packet(packets[1]).timestamp_us == round(24 * 55.296)


# ------------------------------------------------------------------------------------------
# IMU


def test_imu_source_decodes_samples():
    rng = np.random.default_rng(10)
    samples = [_imu_sample(rng, 0.01 * k) for k in range(40)]
    dev, sent = XsensDevice(), []
    with PtyDevice() as pty:
        source = ImuSerialSource(pty.path, 115200, period=0.01)

        emit = _emitter(dev.sample_bytes, samples, sent)

        def check(ctx):
            st = source.status(ctx)
            if st.samples:
                out = source.GetOutputPort("imu").Eval(ctx)
                ref = sent[st.samples - 1]
                assert np.array_equal(out.angular_velocity, _f32(ref.angular_velocity))
                assert np.array_equal(out.linear_acceleration, _f32(ref.linear_acceleration))
                assert np.array_equal(out.orientation, _f32(ref.orientation))
                assert out.time >= 0 and abs(out.time / 0.01 - round(out.time / 0.01)) < 1e-9

        try:
            ctx = _run_serial(source, "imu", pty, dev, emit, 40, 0.01, check)
            st = source.status(ctx)
            diagnostics = source.GetOutputPort("diagnostics").Eval(ctx)
        finally:
            source.close()
    assert st.requests_sent == 1 and dev.messages == 1  # GoToMeasurement reached the device
    assert st.samples >= 30 and st.samples == st.frames
    assert st.bad_frames == 0 and st.samples_lost == 0
    assert diagnostics == dataclasses.asdict(st) | {
        "connected": True,
        "disconnects": 0,
        "reconnects": 0,
    }
    assert diagnostics["samples"] == st.samples


def test_imu_source_survives_corruption():
    rng = np.random.default_rng(11)
    faults = WireFaults(0.01, seed=5)
    dev = XsensDevice()
    with PtyDevice(faults) as pty:
        source = ImuSerialSource(pty.path, period=0.01)
        try:
            ctx = _run_serial(
                source, "imu", pty, dev, lambda k: dev.sample_bytes(_imu_sample(rng, 0.01 * k)),
                150, 0.01,
            )  # fmt: skip
            st = source.status(ctx)
            out = source.GetOutputPort("imu").Eval(ctx)
        finally:
            source.close()
    assert faults.bytes_corrupted > 0
    assert st.bad_frames > 0 and st.samples > 30 and st.samples_lost > 0
    assert abs(np.linalg.norm(out.orientation) - 1.0) < 1e-6


# ------------------------------------------------------------------------------------------
# 2D lidars


def _check_rplidar(out: LaserScan, ref: LaserScan) -> None:
    assert out.angle_min == -math.pi and out.angle_increment == pytest.approx(2 * math.pi / 360)
    assert np.array_equal(out.valid, ref.valid)
    v = ref.valid
    assert np.max(np.abs(out.ranges[v] - ref.ranges[v])) <= 0.000125 + 1e-12  # ¼ mm grid


def _check_utm(out: LaserScan, ref: LaserScan) -> None:
    assert out.angle_min == pytest.approx(ref.angle_min, abs=1e-12)
    assert out.angle_increment == pytest.approx(ref.angle_increment, abs=1e-12)
    assert np.array_equal(out.valid, ref.valid)
    v = ref.valid
    assert np.max(np.abs(out.ranges[v] - np.rint(ref.ranges[v] * 1000) / 1000)) < 1e-12  # mm


@pytest.mark.parametrize("protocol", ["rplidar", "scip"])
def test_lidar_source_decodes_scans(protocol):
    rng = np.random.default_rng(20)
    make, check_scan = (
        (_rplidar_scan, _check_rplidar) if protocol == "rplidar" else (_utm_scan, _check_utm)
    )
    scans = [make(rng, 0.05 * k) for k in range(25)]
    dev = RplidarDevice() if protocol == "rplidar" else ScipDevice()
    sent = []
    with PtyDevice() as pty:
        source = LidarSerialSource(pty.path, 115200, protocol, period=0.01)

        emit = _emitter(dev.scan_bytes, scans, sent)

        def check(ctx):
            st = source.status(ctx)
            if st.scans:
                out = source.GetOutputPort("lidar_scan").Eval(ctx)
                check_scan(out, sent[st.scans - 1])
                assert out.time >= 0 and abs(out.time / 0.01 - round(out.time / 0.01)) < 1e-9

        try:
            ctx = _run_serial(source, "lidar_scan", pty, dev, emit, 25, 0.02, check)
            st = source.status(ctx)
        finally:
            source.close()
    assert st.starts == 1 and st.bad_frames == 0 and st.partial_scans == 0
    # rplidar: a revolution completes when the next one starts
    assert st.scans == len(sent) - (1 if protocol == "rplidar" else 0) >= 20
    if protocol == "rplidar":
        assert st.bytes_written == 4 and dev.requests == 2  # STOP, SCAN
        assert st.frames == 360 * len(sent)
    else:
        assert st.bytes_written == len(b"QT\nSCIP2.0\nBM\nMD0000108001000\n")
        assert dev.commands == 4 and dev.bad_commands == 0


@pytest.mark.parametrize("protocol", ["rplidar", "scip"])
def test_lidar_source_survives_corruption(protocol):
    rng = np.random.default_rng(21)
    scan = _rplidar_scan(rng) if protocol == "rplidar" else _utm_scan(rng)
    faults = WireFaults(0.01, seed=7)
    dev = RplidarDevice() if protocol == "rplidar" else ScipDevice()
    with PtyDevice(faults) as pty:
        source = LidarSerialSource(pty.path, 115200, protocol, period=0.01, restart_timeout=0.3)
        try:
            ctx = _run_serial(
                source, "lidar_scan", pty, dev, lambda k: dev.scan_bytes(scan), 60, 0.02
            )
            st = source.status(ctx)
            out = source.GetOutputPort("lidar_scan").Eval(ctx)
        finally:
            source.close()
    assert faults.bytes_corrupted > 0
    assert st.bad_frames > 0 and st.discarded_bytes > 0
    assert st.scans >= 5
    # most published beams are the device's (corruption that passes the checks is possible)
    q = 0.000125 if protocol == "rplidar" else 0.0005
    ref = scan.ranges if protocol == "rplidar" else np.rint(scan.ranges * 1000) / 1000
    both = out.valid & scan.valid
    close = np.abs(np.where(both, out.ranges, 0.0) - np.where(both, ref, 0.0)) <= q + 1e-12
    hit = both & close
    assert hit.sum() >= 0.8 * out.valid.sum() > 0
    if protocol == "scip":
        assert st.partial_scans > 0  # salvaged: lines with a bad checksum lose only their beams
    else:  # misaligned nodes after resynchronisation are filtered, revolutions stay whole
        assert st.implausible_nodes > 0 and st.scans <= dev.revolutions + 5
        assert out.valid.sum() >= 0.8 * scan.valid.sum()


def test_lidar_source_rejects_unknown_protocol():
    with pytest.raises(ValueError, match="unknown lidar protocol 'sick'") as e:
        LidarSerialSource("/dev/null", 115200, "sick")
    assert "\n" not in str(e.value)


# ------------------------------------------------------------------------------------------
# VLP-16 over UDP


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _vlp_clouds(rng, n: int) -> list[PointCloud]:
    asm = vlp.SweepAssembler(0.2)
    out = []
    for _ in range(n):
        image = rng.uniform(0.5, 120.0, (16, 1800))
        image[rng.random(image.shape) < 0.1] = np.inf
        out.append(PointCloud(elevations=asm.elevations, azimuths=asm.azimuths, range_image=image))
    return out


def _run_udp(source, clouds, port, faults=None):
    sim, diagram, ctx = _simulate(source, "lidar_points")
    dev = Vlp16Device()
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        t = 0.0
        for cloud in clouds:
            for p in dev.sweep_packets(cloud):
                sender.sendto(faults.apply(p) if faults else p, ("127.0.0.1", port))
            time.sleep(0.005)
            for _ in range(3):
                t += 0.01
                sim.AdvanceTo(t)
    finally:
        sender.close()
    return ctx


def test_velodyne_source_decodes_sweeps():
    rng = np.random.default_rng(30)
    clouds = _vlp_clouds(rng, 5)
    port = _free_udp_port()
    source = VelodyneUdpSource("127.0.0.1", port, period=0.01)
    try:
        with pytest.raises(OSError, match=f"127.0.0.1:{port}") as e:  # the port is taken
            UdpTransport("127.0.0.1", port)
        assert "\n" not in str(e.value)
        ctx = _run_udp(source, clouds, port)
        st = source.status(ctx)
        out = source.GetOutputPort("lidar_points").Eval(ctx)
        diagnostics = source.GetOutputPort("diagnostics").Eval(ctx)
    finally:
        source.close()
    assert st.datagrams == 5 * 75 and st.bad_packets == 0
    assert diagnostics == dataclasses.asdict(st) | {
        "connected": True,
        "disconnects": 0,
        "reconnects": 0,
    }  # UDP: never lost
    assert st.partial_sweeps == 1 and st.sweeps == 3  # the first is dropped, the last pending
    ref = clouds[st.sweeps].range_image  # sweep k completes when sweep k + 1 starts
    expected = np.where(np.isfinite(ref), np.rint(ref / 0.002) * 0.002, np.inf)
    assert np.array_equal(np.isfinite(out.range_image), np.isfinite(expected))
    m = np.isfinite(expected)
    assert np.max(np.abs(out.range_image[m] - expected[m])) < 1e-9  # 2 mm grid
    assert len(out.points) == m.sum()
    assert np.allclose(out.azimuths, clouds[0].azimuths)
    assert out.time > 0 and out.sweep_time == pytest.approx(1800 * 55.296e-6, rel=1e-3)


def test_velodyne_source_survives_corruption():
    rng = np.random.default_rng(31)
    clouds = _vlp_clouds(rng, 6)
    faults = WireFaults(0.01, seed=9)
    with UdpTransport("127.0.0.1", 0) as transport:
        source = VelodyneUdpSource(period=0.01, transport=transport)
        ctx = _run_udp(source, clouds, transport.port, faults)
        st = source.status(ctx)
        out = source.GetOutputPort("lidar_points").Eval(ctx)
    assert st.datagrams == 6 * 75 and st.bad_packets > 0 and st.sweeps >= 1
    assert out.range_image.shape == (16, 1800) and np.all(np.isfinite(out.points))
