"""Xsens MTData2 and Velodyne VLP-16 codecs (hardware_io/codecs/imu.py, velodyne.py)."""

import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hardware_io.codecs import imu, velodyne
from hardware_io.codecs.imu import MTData2, MtError, MtStream
from hardware_io.codecs.velodyne import Firing, VelodyneError, Vlp16Packet
from usvdrake.sensors.messages import ImuSample

# ------------------------------------------------------------------------------------------
# Xsens MTData2

f32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
vec3 = st.tuples(f32, f32, f32)
angles = st.floats(-math.pi, math.pi, allow_nan=False)

mtdata2 = st.builds(
    MTData2,
    packet_counter=st.none() | st.integers(0, 0xFFFF),
    sample_time_fine=st.none() | st.integers(0, 0xFFFFFFFF),
    quaternion=st.none() | st.tuples(f32, f32, f32, f32),
    euler_rad=st.none() | st.tuples(angles, angles, angles),
    acceleration=st.none() | vec3,
    rate_of_turn=st.none() | vec3,
    status_word=st.none() | st.integers(0, 0xFFFFFFFF),
    orientation_frame=st.sampled_from(["ENU", "NED", "NWU"]),
    other=st.lists(
        st.tuples(st.sampled_from([0x0810, 0xC020, 0x5020]), st.binary(max_size=40)),
        max_size=3,
        unique_by=lambda p: p[0],
    ).map(tuple),
)


def test_known_frame_bytes():
    """Hand-assembled per MT0101P: counter 0x0102, acceleration (0, 0, 9.81) float32 BE."""
    data = bytes.fromhex("1020 02 0102") + bytes.fromhex("4020 0c") + struct.pack(">3f", 0, 0, 9.81)
    body = bytes([0xFF, 0x36, len(data)]) + data
    frame = b"\xfa" + body + bytes([(-sum(body)) & 0xFF])
    msg = imu.decode_mtdata2(frame)
    assert msg.packet_counter == 0x0102
    assert msg.acceleration == (0.0, 0.0, float(np.float32(9.81)))
    assert imu.encode_mtdata2(msg) == frame
    assert frame[20:24] == bytes.fromhex("411CF5C3")  # 9.81 as in the MTi user manual


@settings(max_examples=150, deadline=None)
@given(mtdata2, st.booleans())
def test_mtdata2_round_trip(msg, float64):
    msg = MTData2(**{**msg.__dict__, "float64": float64})
    frame = imu.encode_mtdata2(msg)
    assert imu.checksum_ok(frame)
    q = imu.decode_mtdata2(frame)
    if not (float64 and msg.euler_rad is not None):  # float64 degrees <-> rad: within 1 ulp
        assert imu.encode_mtdata2(q) == frame  # canonical frames round-trip byte for byte
        assert imu.quantise(q) == q
    for key in ("packet_counter", "sample_time_fine", "quaternion", "acceleration"):
        assert getattr(q, key) == getattr(msg, key)  # float32 values are exact
    assert (q.rate_of_turn, q.status_word, q.other) == (
        msg.rate_of_turn,
        msg.status_word,
        msg.other,
    )
    if msg.euler_rad is not None:  # degrees on the wire
        assert np.allclose(q.euler_rad, msg.euler_rad, atol=1e-6 if not float64 else 1e-14)


def test_extended_length():
    msg = MTData2(packet_counter=7, other=((0x5020, bytes(200)), (0x5030, bytes(100))))
    frame = imu.encode_mtdata2(msg)
    assert frame[3] == 0xFF and (frame[4] << 8 | frame[5]) == len(frame) - 7
    assert imu.decode_mtdata2(frame) == msg
    assert MtStream().feed(b"\x00" + frame) == [msg]


def test_imu_sample_conversion():
    yaw = 0.7
    s = ImuSample(
        time=12.3456,
        angular_velocity=np.array([0.01, -0.02, 0.3]),
        linear_acceleration=np.array([0.1, 0.2, 9.81]),
        orientation=np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]),
    )
    m = imu.from_imu_sample(s, packet_counter=70000)
    assert m.packet_counter == 70000 & 0xFFFF and m.sample_time_fine == 123456
    back = imu.to_imu_sample(imu.decode_mtdata2(imu.encode_mtdata2(m)))
    assert back.time == pytest.approx(12.3456, abs=1e-12)
    for a, b in [
        (back.angular_velocity, s.angular_velocity),
        (back.linear_acceleration, s.linear_acceleration),
        (back.orientation, s.orientation),
    ]:
        assert np.allclose(a, b, atol=1e-6)
    e = MTData2(
        euler_rad=(0.0, 0.0, yaw), acceleration=(0, 0, 9.81), rate_of_turn=(0, 0, 0)
    )  # Euler only: same orientation
    assert np.allclose(imu.to_imu_sample(e, time=1.0).orientation, s.orientation)
    with pytest.raises(MtError):
        imu.to_imu_sample(MTData2(acceleration=(0, 0, 0), rate_of_turn=(0, 0, 0)), time=0.0)
    with pytest.raises(MtError):
        imu.to_imu_sample(MTData2(**{**m.__dict__, "orientation_frame": "NED"}))


def test_stream_random_chunks_and_garbage():
    rng = np.random.default_rng(1)
    msgs = [
        MTData2(
            packet_counter=i,
            sample_time_fine=100 * i,
            quaternion=(1.0, 0.0, 0.0, 0.0),
            acceleration=tuple(rng.normal(size=3).astype(np.float32).tolist()),
            rate_of_turn=tuple(rng.normal(size=3).astype(np.float32).tolist()),
        )
        for i in range(200)
    ]
    stream = bytearray()
    for m in msgs:
        g = rng.integers(0, 256, rng.integers(0, 12), dtype=np.uint8).tobytes()
        if rng.random() < 0.2:
            g += b"\xfa\xff"  # a false sync right before the real one
        stream += g + imu.encode_mtdata2(m)
        if rng.random() < 0.1:
            stream += imu.encode_frame(0x3E, b"")  # WakeUp: another message, skipped
    p, out, i = MtStream(), [], 0
    while i < len(stream):
        n = int(rng.integers(1, 40))
        out += p.feed(stream[i : i + n])
        i += n
    assert out == msgs
    assert p.other_messages > 0


def test_stream_rejects_bad_checksum():
    good = imu.encode_mtdata2(MTData2(packet_counter=1))
    bad = bytearray(good)
    bad[-1] ^= 0x01
    p = MtStream()
    assert p.feed(bytes(bad) + good) == [MTData2(packet_counter=1)]
    assert p.checksum_errors == 1
    with pytest.raises(MtError):
        imu.decode_mtdata2(bytes(bad))


def _mutate(rng, frame: bytes) -> bytes:
    b = bytearray(frame)
    kind = rng.integers(0, 5)
    if kind == 0:  # flip bytes
        for _ in range(rng.integers(1, 4)):
            b[rng.integers(0, len(b))] = rng.integers(0, 256)
    elif kind == 1:  # truncate
        b = b[: rng.integers(0, len(b))]
    elif kind == 2:  # insert
        i = rng.integers(0, len(b) + 1)
        b[i:i] = rng.integers(0, 256, rng.integers(1, 4), dtype=np.uint8).tobytes()
    elif kind == 3:  # mutate and fix the checksum (exercises the payload parser)
        b[rng.integers(3, len(b))] = rng.integers(0, 256)
        b[-1] = (b[-1] - sum(b[1:])) & 0xFF
    else:  # random bytes behind a header
        b = bytearray(
            b"\xfa\xff\x36" + rng.integers(0, 256, rng.integers(0, 60), np.uint8).tobytes()
        )
    return bytes(b)


def test_mtdata2_fuzz_100k():
    rng = np.random.default_rng(20240601)
    base = [
        imu.encode_mtdata2(
            MTData2(
                packet_counter=1,
                sample_time_fine=2,
                quaternion=(1, 0, 0, 0),
                acceleration=(0, 0, 9.81),
                rate_of_turn=(0.1, 0.2, 0.3),
                status_word=5,
            )
        ),
        imu.encode_mtdata2(MTData2(euler_rad=(0.1, 0.2, 0.3), float64=True)),
        imu.encode_mtdata2(
            MTData2(packet_counter=3, other=((0x5020, bytes(200)), (0x5030, bytes(100))))
        ),
    ]
    decoded = errors = 0
    stream = MtStream()
    for _ in range(100_000):
        if rng.random() < 0.1:
            frame = rng.integers(0, 256, rng.integers(0, 80), np.uint8).tobytes()
        else:
            frame = _mutate(rng, base[rng.integers(0, len(base))])
        try:
            imu.decode_mtdata2(frame)
        except MtError:
            errors += 1
        else:
            decoded += 1
            assert imu.checksum_ok(frame) and frame[2] == 0x36
        for raw in stream.feed_frames(frame):
            assert imu.checksum_ok(raw) and raw[:2] == b"\xfa\xff"
            imu.decode_mtdata2(raw)  # the parser only yields decodable frames
    assert decoded > 1000 and errors > 50_000


# ------------------------------------------------------------------------------------------
# Velodyne VLP-16

cdeg = st.integers(0, 35999)
raw_packets = st.builds(
    lambda az, d, r, ts, mode: Vlp16Packet(
        np.array(az) if mode != velodyne.RETURN_DUAL else np.repeat(az[:6], 2),
        np.array(d).reshape(12, 32),
        np.array(r).reshape(12, 32),
        ts,
        mode,
    ),
    st.lists(cdeg, min_size=12, max_size=12),
    st.lists(st.integers(0, 0xFFFF), min_size=384, max_size=384),
    st.lists(st.integers(0, 255), min_size=384, max_size=384),
    st.integers(0, 3_599_999_999),
    st.sampled_from(velodyne.RETURN_MODES),
)


@settings(max_examples=100, deadline=None)
@given(raw_packets)
def test_vlp16_packet_round_trip(p):
    data = velodyne.encode_packet(p)
    assert len(data) == 1206 and data[1204] == p.return_mode and data[1205] == 0x22
    assert velodyne.decode_packet(data) == p
    assert velodyne.encode_packet(velodyne.decode_packet(data)) == data


@settings(max_examples=100, deadline=None)
@given(
    st.integers(0, 35999),
    st.integers(15, 45),  # rotation per block [0.01°] (300..1200 rpm-ish)
    st.lists(st.integers(0, 0xFFFF), min_size=384, max_size=384),
    st.lists(st.integers(0, 255), min_size=384, max_size=384),
    st.integers(0, 3_599_999_999),
)
def test_vlp16_firings_round_trip(az0, step, d, r, ts):
    firings = [
        Firing(
            azimuth_deg=((az0 + (i // 2) * step) % 36000) / 100.0,
            distances_m=tuple(k * 0.002 for k in d[16 * i : 16 * i + 16]),
            reflectivities=tuple(r[16 * i : 16 * i + 16]),
        )
        for i in range(24)
    ]
    back = velodyne.decode_firings(velodyne.encode_firings(firings, ts))
    assert len(back) == 24
    for i, (a, b) in enumerate(zip(firings, back, strict=True)):
        assert b.distances_m == a.distances_m and b.reflectivities == a.reflectivities
        expect = a.azimuth_deg if i % 2 == 0 else ((az0 + (i // 2) * step + step / 2) % 36000) / 100
        assert b.azimuth_deg == pytest.approx(expect, abs=1e-9)
        assert b.time_offset_us == pytest.approx(55.296 * i)


def _packet(az_cdeg, dist=None, ts=0, mode=velodyne.RETURN_STRONGEST):
    d = np.zeros((12, 32), int) if dist is None else dist
    return Vlp16Packet(np.asarray(az_cdeg), d, np.zeros((12, 32), int), ts, mode)


def test_vlp16_hand_built_point():
    """Laser id 3 (+3°), first firing of block 0 at α = 30.00°, 10.000 m."""
    d = np.zeros((12, 32), int)
    d[0, 3] = 5000  # 5000 × 2 mm
    data = velodyne.encode_packet(_packet(3000 + 20 * np.arange(12), d, ts=123))
    assert data[0:4] == bytes([0xFF, 0xEE, 0xB8, 0x0B])  # flag, 3000 little-endian
    assert data[4 + 9 : 4 + 12] == bytes([0x88, 0x13, 0])  # channel 3: 5000 little-endian
    pts = velodyne.packet_points(data)
    w, a = math.radians(3.0), math.radians(30.0)
    expected = [10 * math.cos(w) * math.cos(a), -10 * math.cos(w) * math.sin(a), 10 * math.sin(w)]
    assert pts.xyz.shape == (1, 3)
    assert np.allclose(pts.xyz[0], expected, atol=1e-9, rtol=0)
    assert pts.ring[0] == 9 and pts.laser_id[0] == 3  # rings sorted -15..15: +3° is ring 9
    assert pts.time_offset_us[0] == pytest.approx(3 * 2.304)
    # manual frame: X = R cos ω sin α (right), Y = R cos ω cos α (forward) -> x = Y, y = -X
    assert pts.xyz[0, 0] > 0 and pts.xyz[0, 1] < 0  # 30° clockwise: ahead and to the right


def test_vlp16_second_firing_and_dual():
    d = np.zeros((12, 32), int)
    d[11, 16] = 1000  # last block, second firing, laser 0 (-15°)
    az = (35900 + 20 * np.arange(12)) % 36000  # wraps inside the packet
    pts = velodyne.packet_points(_packet(az, d))
    assert pts.azimuth_deg[0] == pytest.approx(((35900 + 220 + 10) % 36000) / 100)
    dd = np.zeros((12, 32), int)
    dd[0, 0], dd[1, 0] = 100, 200
    dual = velodyne.packet_points(_packet(np.repeat(1000 + 40 * np.arange(6), 2), dd, mode=0x39))
    assert list(dual.return_index) == [0, 1] and list(dual.time_offset_us) == [0, 0]
    with pytest.raises(VelodyneError):  # dual mode: block pairs must share their azimuth
        velodyne.decode_packet(
            velodyne.encode_packet(_packet(1000 + 20 * np.arange(12))).replace(
                b"\x37\x22", b"\x39\x22"
            )
        )


def test_vlp16_errors():
    good = velodyne.encode_packet(_packet(20 * np.arange(12)))
    for bad in [
        good[:-1],
        good + b"\x00",
        b"",
        good[:100] + b"\xff\xef" + good[102:],  # block 1 flag
        good[:2] + b"\xa0\x8c" + good[4:],  # azimuth 36000
        good[:1200] + struct.pack("<I", 3_600_000_000) + good[1204:],
        good[:1204] + b"\x40\x22",
        good[:1204] + b"\x37\x24",  # Puck Hi-Res: other elevations
    ]:
        with pytest.raises(VelodyneError):
            velodyne.decode_packet(bad)
    with pytest.raises(VelodyneError):
        velodyne.encode_firings([Firing(0.0, (200.0,) + (0.0,) * 15)] * 24, 0)


def test_vlp16_fuzz_100k():
    rng = np.random.default_rng(7)
    base = []
    for mode in (0x37, 0x38, 0x39):
        az = rng.integers(0, 36000, 12)
        if mode == 0x39:
            az = np.repeat(az[:6], 2)
        d = rng.integers(0, 0x10000, (12, 32))
        base.append(
            velodyne.encode_packet(_packet(az, d, ts=int(rng.integers(0, 3.6e9)), mode=mode))
        )
    ok = errors = 0
    for k in range(100_000):
        u = rng.random()
        if u < 0.05:
            data = rng.integers(0, 256, 1206, np.uint8).tobytes()
        elif u < 0.1:
            data = rng.integers(0, 256, rng.integers(0, 1300), np.uint8).tobytes()
        else:
            b = np.frombuffer(base[k % 3], np.uint8).copy()
            idx = rng.integers(0, 1206, rng.integers(1, 4))
            b[idx] = rng.integers(0, 256, len(idx))
            b = b.tobytes()
            if rng.random() < 0.02:
                b = b[: rng.integers(0, 1206)]
            data = bytes(b)
        try:
            p = velodyne.decode_packet(data)
        except VelodyneError:
            errors += 1
            continue
        ok += 1
        if k % 10 == 0:  # no checksum: only assert that the output is physically bounded
            pts = velodyne.packet_points(p)
            assert np.all(np.isfinite(pts.xyz))
            assert np.all(np.linalg.norm(pts.xyz, axis=1) <= 131.07 + 1e-9)
            assert np.all((pts.ring >= 0) & (pts.ring < 16))
            assert np.all((pts.azimuth_deg >= 0) & (pts.azimuth_deg < 360))
            assert np.all((pts.time_offset_us >= 0) & (pts.time_offset_us < 1331))
    assert ok > 30_000 and errors > 10_000


def _sweep_packets(n_packets, az_step=20, start_cdeg=35000, ts0=0, dist=2500):
    """Packets of a constant-rate rotation (az_step 0.01° per firing)."""
    out, az = [], start_cdeg
    for k in range(n_packets):
        azs = (az + 2 * az_step * np.arange(12)) % 36000
        d = np.full((12, 32), dist)
        out.append(
            velodyne.encode_packet(_packet(azs, d, ts=(ts0 + int(k * 1327.104)) % 3_600_000_000))
        )
        az = (az + 24 * az_step) % 36000
    return out


def test_sweep_assembler():
    asm = velodyne.SweepAssembler(resolution_deg=0.2)
    clouds = []
    for p in _sweep_packets(200, ts0=3_599_990_000):  # crosses the top of the hour
        clouds += asm.feed(p)
    assert asm.partial_sweeps == 1 and len(clouds) == 2  # 360° = 75 packets at 0.2°/firing
    c = clouds[0]
    assert c.range_image.shape == (16, 1800) and c.azimuths.shape == (1800,)
    assert np.all(c.range_image == 5.0)  # every cell filled, 2500 × 2 mm
    assert len(c.points) == 16 * 1800
    assert np.allclose(np.linalg.norm(c.points, axis=1), 5.0)
    assert c.sweep_time == pytest.approx(1800 * 55.296e-6, rel=1e-3)
    # the organised image agrees with the points: column azimuth ≈ point azimuth
    a = np.arctan2(c.points[:, 1], c.points[:, 0])
    da = np.angle(np.exp(1j * (a - c.azimuths[c.column])))
    assert np.max(np.abs(da)) <= math.radians(0.1) + 1e-9
    e = np.arcsin(c.points[:, 2] / 5.0)
    assert np.allclose(e, c.elevations[c.ring])
    assert c.time > 3600.0  # unwrapped across the hour
    assert asm.flush() is not None
