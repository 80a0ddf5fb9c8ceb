"""Thruster microcontroller protocol (hardware_io/codecs/thrust.py) and the T200 thrust curve."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hardware_io import thrust_curve as tc
from hardware_io.codecs import thrust as th
from usvdrake.vessel import load_vessel

# ------------------------------------------------------------------------------------------
# CRC


def _crc_oracle(body: bytes) -> int:
    """Independent CRC-16/CCITT-FALSE, bit by bit from its definition (poly 0x1021, init
    0xFFFF, MSB first, no final XOR); the codec uses the standard library's table version."""
    crc = 0xFFFF
    for byte in body:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else crc << 1
            crc &= 0xFFFF
    return crc


def _crc_ok(frame: bytes) -> bool:
    return len(frame) >= 9 and _crc_oracle(frame[2:-2]) == int.from_bytes(frame[-2:], "little")


def test_crc_check_value():
    assert th.crc16_ccitt_false(b"123456789") == 0x29B1
    assert _crc_oracle(b"123456789") == 0x29B1
    rng = np.random.default_rng(0)
    for _ in range(200):
        data = rng.integers(0, 256, rng.integers(0, 100)).astype(np.uint8).tobytes()
        assert th.crc16_ccitt_false(data) == _crc_oracle(data)


def test_worked_example_of_protocol_md():
    frame = th.encode_command(0x1234, [1500, 1600, 1400, 1700])
    assert frame.hex(" ") == "aa 55 01 01 0a 34 12 04 00 dc 05 40 06 78 05 a4 06 07 72"
    frame = th.encode_command(7, [1500, 1620, 1380], [0, 9000, -4500])
    assert frame.hex(" ") == (
        "aa 55 01 01 0e 07 00 03 01 dc 05 00 00 54 06 28 23 64 05 6c ee fb 96"
    )
    frame = th.encode_telemetry(
        0x1234, th.Status.UNDERVOLTAGE, 14800, [0, 1200, -900, 2000], [1500, 1600, 1400, 1700]
    )
    assert frame.hex(" ") == (
        "aa 55 01 81 15 34 12 04 03 04 d0 39 00 00 dc 05 b0 04 40 06 7c fc 78 05 d0 07 a4 06 e5 79"
    )


# ------------------------------------------------------------------------------------------
# Round trips (hypothesis)

u16 = st.integers(0, 0xFFFF)
i16 = st.integers(-0x8000, 0x7FFF)


@st.composite
def commands(draw):
    n = draw(st.integers(1, th.MAX_CHANNELS))
    pwm = tuple(draw(st.lists(u16, min_size=n, max_size=n)))
    ang = draw(st.none() | st.lists(i16, min_size=n, max_size=n).map(tuple))
    return th.ThrustCommand(draw(u16), pwm, ang)


@st.composite
def telemetries(draw):
    n = draw(st.integers(1, th.MAX_CHANNELS))
    which = draw(st.sampled_from(["rpm", "pwm", "both"]))
    rpm = tuple(draw(st.lists(i16, min_size=n, max_size=n))) if which != "pwm" else None
    pwm = tuple(draw(st.lists(u16, min_size=n, max_size=n))) if which != "rpm" else None
    status = th.Status(draw(st.integers(0, 255)))
    return th.Telemetry(draw(u16), status, draw(u16), rpm, pwm)


def _encode(msg) -> bytes:
    if isinstance(msg, th.ThrustCommand):
        return th.encode_command(msg.seq, msg.pwm_us, msg.angles_cdeg)
    return th.encode_telemetry(msg.seq, msg.status, msg.battery_mv, msg.rpm, msg.pwm_us)


@settings(max_examples=400, deadline=None)
@given(commands() | telemetries())
def test_frame_round_trip(msg):
    """Each frame decodes to itself with its own decoder and is refused by the other's."""
    frame = _encode(msg)
    assert _crc_ok(frame) and len(frame) <= th.MAX_FRAME
    own, other = (th.decode_command, th.decode_telemetry)
    if not isinstance(msg, th.ThrustCommand):
        own, other = other, own
    assert own(frame) == msg
    with pytest.raises(th.FrameError):
        other(frame)


@settings(max_examples=100, deadline=None)
@given(
    st.lists(st.tuples(commands() | telemetries(), st.binary(max_size=40)), max_size=8),
    st.lists(st.integers(1, 50), min_size=1, max_size=20),
    st.integers(1, 4),
)
def test_parser_chunking_and_garbage(items, chunk_sizes, buffer_frames):
    stream = b"".join(garbage + _encode(msg) for msg, garbage in items)
    # Flush: a false sync inside garbage may claim up to MAX_FRAME bytes before its CRC fails.
    stream += bytes(th.MAX_FRAME)
    parser = th.FrameParser(max_buffer=buffer_frames * th.MAX_FRAME)
    out, pos, k = [], 0, 0
    while pos < len(stream):
        n = chunk_sizes[k % len(chunk_sizes)]
        out += parser.feed(stream[pos : pos + n])
        assert len(parser._buf) <= parser.max_buffer
        pos, k = pos + n, k + 1
    assert out == [msg for msg, _ in items]
    assert parser.frames == len(items)


def test_parser_sequence_wraps_and_back_to_back():
    frames = [th.encode_command(s % 65536, [1500]) for s in range(65530, 65545)]
    out = th.FrameParser().feed(b"".join(frames))
    assert [m.seq for m in out] == [s % 65536 for s in range(65530, 65545)]


def test_parser_counts_crc_errors_and_resyncs():
    good = th.encode_command(1, [1600, 1400])
    bad = bytearray(th.encode_command(2, [1600, 1400]))
    bad[8] ^= 0x10
    p = th.FrameParser()
    out = p.feed(b"\x00\xaa" + bytes(bad) + b"junk\xaa" + good)
    assert out == [th.decode_command(good)]
    assert p.crc_errors == 1


def test_parser_bounds_its_buffer():
    p = th.FrameParser(max_buffer=th.MAX_FRAME)
    for _ in range(1000):
        assert p.feed(b"\xaa\x55\x01\x01\x45" + bytes(30)) == []
        assert len(p._buf) <= th.MAX_FRAME
    assert p.feed(bytes(th.MAX_FRAME) + th.encode_command(3, [1500])) != []


# ------------------------------------------------------------------------------------------
# Fuzzing: 100 000 random and mutated frames


def _random_valid(rng) -> bytes:
    n = int(rng.integers(1, th.MAX_CHANNELS + 1))
    seq = int(rng.integers(0, 65536))
    if rng.random() < 0.5:
        pwm = rng.integers(0, 65536, n).tolist()
        ang = rng.integers(-32768, 32768, n).tolist() if rng.random() < 0.5 else None
        return th.encode_command(seq, pwm, ang)
    which = int(rng.integers(1, 4))
    rpm = rng.integers(-32768, 32768, n).tolist() if which & 1 else None
    pwm = rng.integers(0, 65536, n).tolist() if which & 2 else None
    return th.encode_telemetry(
        seq, int(rng.integers(0, 256)), int(rng.integers(0, 65536)), rpm, pwm
    )


def _recrc(frame: bytearray) -> bytes:
    """Recompute the CRC so that mutations of the header/payload reach the content checks."""
    if len(frame) >= 4:
        frame[-2:] = _crc_oracle(bytes(frame[2:-2])).to_bytes(2, "little")
    return bytes(frame)


def _mutate(rng, kind: int) -> bytes:
    if kind == 0:  # random bytes, half of them behind a plausible header
        data = rng.integers(0, 256, int(rng.integers(0, 90))).astype(np.uint8).tobytes()
        if rng.random() < 0.5:
            data = bytes([0xAA, 0x55, 1, int(rng.choice([0x01, 0x81]))]) + data
        return data
    f = bytearray(_random_valid(rng))
    if kind == 1:  # flipped bits
        for _ in range(int(rng.integers(1, 4))):
            i = int(rng.integers(0, len(f)))
            f[i] ^= 1 << int(rng.integers(0, 8))
        return bytes(f)
    if kind == 2:  # truncation or trailing bytes
        if rng.random() < 0.7:
            return bytes(f[: int(rng.integers(0, len(f)))])
        return bytes(f) + rng.integers(0, 256, int(rng.integers(1, 5))).astype(np.uint8).tobytes()
    if kind == 3:  # splice of two valid frames
        g = _random_valid(rng)
        return bytes(f[: int(rng.integers(0, len(f) + 1))]) + g[int(rng.integers(0, len(g))) :]
    # kind 4: corrupt a header/payload byte but give the frame a valid CRC
    i = int(rng.integers(2, max(3, len(f) - 2)))
    f[i] = int(rng.integers(0, 256))
    if rng.random() < 0.3:  # or resize the payload and patch the length byte
        f = f[:7] + f[7:-2][: int(rng.integers(0, len(f) - 8))] + f[-2:]
        f[4] = (len(f) - 9) & 0xFF
    return _recrc(f)


def test_fuzz_100k_only_frame_errors_and_never_a_bad_crc():
    rng = np.random.default_rng(20240607)
    parser = th.FrameParser()
    stream = bytearray()
    counts = {"ok": 0, "err": 0}
    for k in range(100_000):
        data = _mutate(rng, k % 5)
        try:
            msg = th.decode_frame(data)
        except th.FrameError:
            counts["err"] += 1
        else:  # anything else propagates and fails the test
            counts["ok"] += 1
            assert _crc_ok(data), data.hex()
            assert _encode(msg) == data  # canonical: the bytes really were this frame
        if k % 7 == 0:  # every kind ends up in the stream (7 and 5 are coprime)
            stream += data
    assert counts["err"] > 50_000 and counts["ok"] > 5_000  # both paths really exercised
    # the same bytes through the stream parser in random chunks
    pos, out = 0, []
    while pos < len(stream):
        n = int(rng.integers(1, 200))
        out += parser.feed(bytes(stream[pos : pos + n]))
        pos += n
    assert out and parser.crc_errors > 0
    for msg in out:
        frame = _encode(msg)
        assert _crc_ok(frame) and frame in stream


@pytest.mark.parametrize("junk", [None, 5, "aa55", [0xAA, 0x55], b"", b"\xaa\x55"])
def test_decode_rejects_non_frames(junk):
    with pytest.raises(th.FrameError):
        th.decode_frame(junk)


def test_encoder_validates():
    with pytest.raises(ValueError):
        th.encode_command(0, [])
    with pytest.raises(ValueError):
        th.encode_command(0, [1500] * (th.MAX_CHANNELS + 1))
    with pytest.raises(ValueError):
        th.encode_command(65536, [1500])
    with pytest.raises(ValueError):
        th.encode_command(0, [1500, 1500], [0])
    with pytest.raises(ValueError):
        th.encode_command(0, [1500.5])
    with pytest.raises(ValueError):
        th.encode_telemetry(0, 0, 16000)
    with pytest.raises(ValueError):
        th.encode_telemetry(0, 256, 16000, rpm=[0])
    assert th.decode_command(th.encode_command(np.int64(3), np.array([1500, 1510]))).seq == 3


# ------------------------------------------------------------------------------------------
# Thrust curve


def test_curve_monotone():
    p = np.linspace(1000, 2000, 4001)
    assert np.all(np.diff(tc.pwm_to_force(p)) >= 0)
    f = np.linspace(-80, 80, 4001)
    assert np.all(np.diff(tc.force_to_pwm(f)) >= 0)
    assert np.all(np.diff(tc._FORCE) >= 0) and np.all(np.diff(tc._PWM) > 0)


def test_curve_zero_deadband_and_saturation():
    assert tc.force_to_pwm(0.0) == 1500.0 and tc.force_to_pwm_us(0.0) == 1500
    for p in range(1500 - tc.ESC_DEADBAND_US, 1500 + tc.ESC_DEADBAND_US + 1):
        assert tc.pwm_to_force(p) == 0.0
    assert tc.force_to_pwm(1e-9) >= 1528 and tc.force_to_pwm(-1e-9) <= 1472
    assert tc.force_to_pwm(1e3) == 1900 and tc.force_to_pwm(-1e3) == 1100
    assert tc.pwm_to_force(2500) == tc.FORCE_MAX == tc.pwm_to_force(1900)
    assert tc.pwm_to_force(0) == tc.FORCE_MIN == tc.pwm_to_force(1100)


def test_curve_inverse_of_itself():
    f = np.linspace(tc.FORCE_MIN, tc.FORCE_MAX, 2001)
    np.testing.assert_allclose(tc.pwm_to_force(tc.force_to_pwm(f)), f, atol=1e-9)
    # through whole microseconds: within half a µs of the steepest table segment
    slope = np.max(np.diff(tc._FORCE) / np.diff(tc._PWM))  # [N/µs]
    err = np.abs(tc.pwm_to_force(tc.force_to_pwm_us(f)) - f)
    assert err.max() <= 0.5 * slope + 1e-9
    p = np.r_[np.arange(1100, 1472), np.arange(1529, 1901)]
    np.testing.assert_allclose(tc.force_to_pwm(tc.pwm_to_force(p)), p, atol=1e-9)
    assert np.all(tc.force_to_pwm(tc.pwm_to_force(np.arange(1472, 1529))) == 1500)


def test_curve_values_from_published_table():
    kgf = tc.G0
    assert tc.pwm_to_force(1900) == pytest.approx(5.25 * kgf)
    assert tc.pwm_to_force(1100) == pytest.approx(-4.07 * kgf)
    assert tc.pwm_to_force(1728) == pytest.approx(2.22 * kgf)
    assert tc.pwm_to_force(1308) == pytest.approx(-1.35 * kgf)
    assert tc.force_to_pwm(4.25 * kgf) == pytest.approx(1840)
    # an independent summary of the same 16 V sheet: +51.4 N / -39.9 N peak
    assert tc.FORCE_MAX == pytest.approx(51.4, abs=0.1)
    assert tc.FORCE_MIN == pytest.approx(-39.9, abs=0.1)
    assert tc.VOLTAGE == 16.0 and tc.SOURCE_URL.endswith(".xlsx")


def test_command_to_channels_for_the_vessels():
    roboat = load_vessel("roboat2").thrusters
    pwm, ang = tc.command_to_channels(roboat, [0.0, 20.0, -20.0, 100.0])
    assert ang is None and pwm[0] == 1500 and pwm[1] > 1528 and pwm[2] < 1472 and pwm[3] == 1900
    frame = th.encode_command(1, pwm, ang)
    assert th.decode_command(frame).pwm_us == tuple(pwm)
    ntnu = load_vessel("ntnu_round").thrusters
    cmd = [1.0, np.pi / 2, 0.0, -np.pi / 4, 2.0, np.pi]
    pwm, ang = tc.command_to_channels(ntnu, cmd)
    assert ang == [9000, -4500, -18000] and pwm[1] == 1500
    assert th.decode_command(th.encode_command(2, pwm, ang)).angles_cdeg == tuple(ang)
