"""Worst-case inputs for the byte-stream codecs: linear time and bounded memory on any stream
(garbage, lost start flags, a stalled azimuth), counters of what was dropped, the valid data
around the garbage still decodes, and receiver quirks in RMC do not lose the fix.

Peak memory is measured on each worst case (``tracemalloc``): ≤ 100 MB (before the fixes:
hundreds of MB to GB for the assemblers). Time is not judged here (a busy machine would decide
it): ``usvdrake bench codec_worst_cases`` times the full-size cases against the issue's 1 s.
"""

from __future__ import annotations

import datetime as dt
import tracemalloc

import numpy as np
import pytest

from hardware_io.codecs import velodyne
from hardware_io.codecs.nmea import GGA, RMC, NmeaError, checksum, decode, encode
from hardware_io.codecs.nmea_stream import MAX_SENTENCE_LEN, NmeaStream, split_sentences
from hardware_io.codecs.rplidar import RplidarScanAssembler, ScanNode
from hardware_io.codecs.velodyne import SweepAssembler, Vlp16Packet

MAX_BYTES = 100 * 2**20


def measured(run):
    """Runs ``run()`` under tracemalloc: returns (its result, peak bytes allocated)."""
    tracemalloc.start()
    try:
        result = run()
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    print(f"peak {peak / 2**20:.1f} MB")
    return result, peak


def with_checksum(body: str) -> bytes:
    return b"$%s*%02X" % (body.encode(), checksum(body))


GOOD_GGA = encode(GGA(45319.0, 48.1173, 11.516667, 1, 8, 0.9, 545.4, 46.9))


# ---------------------------------------------------------------------------------------------
# NMEA
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "garbage",
    [
        b"$" * 160_000,  # a start character per byte, no line end (was quadratic: 84 s)
        b"!" * 80_000 + b"$" * 80_000,
        b"$" + b"A" * 160_000,  # one endless sentence
        b"$GPGGA," * 25_000,  # endless truncated sentences
        (b"$" + b"B" * 200 + b"\r\n") * 800,  # over-long lines
    ],
)
def test_nmea_stream_garbage_in_one_read(garbage):
    data = GOOD_GGA + garbage + b"\r\n" + GOOD_GGA

    def run():
        stream = NmeaStream()
        return stream, stream.feed(data)

    (stream, sentences), peak = measured(run)
    assert peak <= MAX_BYTES
    # the valid sentences around the garbage decode; the garbage is counted, not kept
    assert [decode(s) for s in sentences if s.startswith(b"$GPGGA,") and b"*" in s][::2] == [
        decode(GOOD_GGA)
    ]
    assert decode(sentences[0]) == decode(GOOD_GGA) == decode(sentences[-1])
    assert len(stream.pending) <= MAX_SENTENCE_LEN
    garbage_bytes = len(garbage) - garbage.count(b"\r") - garbage.count(b"\n")
    assert stream.dropped_bytes == garbage_bytes - sum(len(s) for s in sentences[1:-1])
    if b"B" * 200 in garbage:
        assert stream.overlong == 800


def test_nmea_stream_garbage_in_many_reads_keeps_bounded_state():
    stream = NmeaStream()
    out = stream.feed(GOOD_GGA)
    for chunk in (b"$" * 1000, b"A" * 1000, b"!AIVDM" * 200):
        for _ in range(50):
            out += stream.feed(chunk)
            assert len(stream.pending) <= MAX_SENTENCE_LEN
    out += stream.feed(b"\r\n" + GOOD_GGA + b"\r\n")
    assert decode(out[0]) == decode(out[-1]) == decode(GOOD_GGA)
    assert out[1:-1] == [b"!AIVDM"]  # the tail of the last read, ended by the line end
    assert stream.overlong >= 1 and stream.dropped_bytes > 100_000


def test_split_sentences_matches_simple_reference():
    """The linear splitter cuts exactly as the straightforward (quadratic) definition."""

    def reference(buffer: bytes, max_len: int):
        out, pos = [], 0
        while True:
            starts = [i for i in range(pos, len(buffer)) if buffer[i] in b"$!"]
            if not starts:
                return out, b""
            start = starts[0]
            ends = [i for i in range(start + 1, len(buffer)) if buffer[i] in b"\r\n"]
            e = ends[0] if ends else len(buffer)
            nxt = [i for i in range(start + 1, e) if buffer[i] in b"$!"]
            if nxt:
                pos = nxt[0]
                continue
            if not ends:
                tail = buffer[start:]
                return out, (tail if len(tail) <= max_len else b"")
            if e - start <= max_len:
                out.append(buffer[start:e])
            pos = e + 1

    rng = np.random.default_rng(7)
    alphabet = np.frombuffer(b"$!\r\nAB,*0", np.uint8)
    for _ in range(2000):
        buf = alphabet[rng.integers(0, len(alphabet), int(rng.integers(0, 60)))].tobytes()
        max_len = int(rng.integers(1, 12))
        assert split_sentences(buf, max_len) == reference(buf, max_len), buf


# ---------------------------------------------------------------------------------------------
# RMC receiver quirks: strict checksum and fix fields, lenient about the rest
# ---------------------------------------------------------------------------------------------

RMC_FIX = "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4"


@pytest.mark.parametrize(
    ("rest", "date", "variation"),
    [
        (",2208-1,003.1,W", None, -3.1),  # GPS week-rollover garbage in the date
        (",310223,003.1,W", None, -3.1),  # 31 February
        (",230394,003.1,", dt.date(1994, 3, 23), None),  # variation without hemisphere
        (",230394,,W", dt.date(1994, 3, 23), None),  # hemisphere without variation
        (",230394,x.1,E", dt.date(1994, 3, 23), None),
        (",2208-1,003.1,,A", None, None),
        (",230394,003.1,W,?,V", dt.date(1994, 3, 23), -3.1),  # bad mode letter
    ],
)
def test_rmc_quirks_keep_the_fix(rest, date, variation):
    m = decode(with_checksum(RMC_FIX + rest))
    assert isinstance(m, RMC) and m.valid
    assert m.time_of_day_s == 12 * 3600 + 35 * 60 + 19
    assert m.latitude_deg == pytest.approx(48 + 7.038 / 60)
    assert m.longitude_deg == pytest.approx(11 + 31.0 / 60)
    assert m.speed_over_ground_mps == pytest.approx(22.4 * 1852 / 3600)
    assert m.course_over_ground_deg == 84.4
    assert m.date == date
    assert m.magnetic_variation_deg == (None if variation is None else pytest.approx(variation))
    # what decodes re-encodes to itself
    assert decode(encode(m)) == m


@pytest.mark.parametrize(
    "body",
    [
        "GPRMC,123519,A,4807.038,X,01131.000,E,022.4,084.4,2208-1,003.1,W",  # hemisphere
        "GPRMC,123519,A,4807.038,,01131.000,E,022.4,084.4,230394,003.1,W",
        "GPRMC,123519,A,4807.038,N,01131.000,,022.4,084.4,230394,003.1,W",
        "GPRMC,126019,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",  # time
        "GPRMC,123519,Q,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W",  # status
        "GPRMC,123519,A,48x7.038,N,01131.000,E,022.4,084.4,230394,003.1,W",  # latitude
        "GPRMC,123519,A,4807.038,N,01131.000,E,nan,084.4,230394,003.1,W",  # speed
        "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,08-4,230394,003.1,W",  # course
        "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394",  # field count
    ],
)
def test_rmc_fix_fields_stay_strict(body):
    with pytest.raises(NmeaError):
        decode(with_checksum(body))


def test_rmc_checksum_stays_strict():
    good = with_checksum(RMC_FIX + ",2208-1,003.1,")
    assert isinstance(decode(good), RMC)
    bad = good[:-2] + b"%02X" % (int(good[-2:], 16) ^ 1)
    with pytest.raises(NmeaError, match="checksum"):
        decode(bad)


# ---------------------------------------------------------------------------------------------
# VLP-16 sweep assembler
# ---------------------------------------------------------------------------------------------


def _packet(az_cdeg, ts: int = 0, dist: int = 2500) -> Vlp16Packet:
    az = np.broadcast_to(np.asarray(az_cdeg), (12,)).copy()
    return Vlp16Packet(az, np.full((12, 32), dist), np.zeros((12, 32), int), ts)


def _rotation(n_packets: int, start_cdeg: int = 35000, az_step: int = 20) -> list[Vlp16Packet]:
    """A constant-rate rotation, 0.2° per firing: 75 packets per 360°."""
    out, az = [], start_cdeg
    for k in range(n_packets):
        out.append(_packet((az + 2 * az_step * np.arange(12)) % 36000, ts=int(k * 1327.104)))
        az = (az + 24 * az_step) % 36000
    return out


def test_vlp16_constant_azimuth_is_bounded():
    stalled = _packet(18000)  # no azimuth wrap, ever
    good = _rotation(200)

    def run():
        asm = SweepAssembler(resolution_deg=0.2)
        clouds = []
        for _ in range(3000):
            clouds += asm.feed(stalled)
        for p in good:
            clouds += asm.feed(p)
        return asm, clouds

    (asm, clouds), peak = measured(run)
    assert peak <= MAX_BYTES
    assert asm.overlong_sweeps == 3 and asm.dropped_packets == 3000
    assert asm.max_sweep_packets == 1000
    # the rotation after the stall still gives full sweeps (the first part is partial)
    assert len(clouds) == 2 and asm.partial_sweeps == 1
    for c in clouds:
        assert np.all(c.range_image == 5.0) and len(c.points) == 16 * 1800


def test_vlp16_flush_after_a_stall_is_bounded():
    stalled = _packet(18000)

    def run():
        asm = SweepAssembler(resolution_deg=0.2)
        for _ in range(2500):
            assert asm.feed(stalled) == []
        return asm, asm.flush()

    (asm, cloud), peak = measured(run)
    assert peak <= MAX_BYTES
    assert asm.overlong_sweeps == 2 and asm.dropped_packets == 2000
    assert cloud is not None and np.isfinite(cloud.range_image).sum() == 16  # one column


def test_vlp16_max_sweep_packets_validated():
    with pytest.raises(ValueError):
        SweepAssembler(max_sweep_packets=0)
    assert velodyne.SweepAssembler().max_sweep_packets >= 3 * 302  # dual return at 300 rpm


# ---------------------------------------------------------------------------------------------
# RPLidar scan assembler
# ---------------------------------------------------------------------------------------------


def _revolution(n: int = 360) -> list[ScanNode]:
    return [ScanNode.from_values(i * 360.0 / n, 1000.0, start=i == 0) for i in range(n)]


def test_rplidar_lost_start_flag_is_bounded():
    n_garbage = 100_000
    good = _revolution()

    def run():
        asm = RplidarScanAssembler()
        revs = []
        revs += asm.feed(good[:1])  # a start flag, then never another one for a long time
        revs += asm.feed(ScanNode(15, (i * 64) % 23040, 4000 + i % 1000) for i in range(n_garbage))
        revs += asm.feed(good)
        revs += asm.feed(good[:1])
        return asm, revs

    (asm, revs), peak = measured(run)
    assert peak <= MAX_BYTES
    assert asm.overlong_revolutions == 1 and asm.dropped_nodes == 1 + n_garbage
    # the valid revolution after the garbage still decodes
    assert len(revs) == 1 and revs[0].nodes == tuple(good)
    assert asm.revolutions == 1


def test_rplidar_max_nodes():
    with pytest.raises(ValueError):
        RplidarScanAssembler(max_nodes=0)
    asm = RplidarScanAssembler(max_nodes=360)
    good = _revolution(360)
    assert asm.feed(good + good[:1]) and asm.overlong_revolutions == 0  # exactly max: kept
    assert asm.feed(good[1:] + good[1:2]) == [] and asm.overlong_revolutions == 1
    assert asm.dropped_nodes == 361
