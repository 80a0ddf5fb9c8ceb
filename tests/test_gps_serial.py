"""GpsSerialSource on a pseudo-terminal fed with recorded NMEA captures."""

import dataclasses
import math
import os
import random
import threading
import time
from pathlib import Path

import pytest
from pydrake.systems.analysis import Simulator

from hardware_io.codecs.nmea import KNOT_TO_MPS, NmeaError, decode
from hardware_io.systems import GpsSerialSource
from hardware_io.transport import PortNotFoundError, SerialTransport

DATA = Path(__file__).parent / "data" / "nmea"
# plaka.log has VTG but no GGA, so the u-blox capture (GGA/RMC/VTG) is replayed first and
# plaka's VTG sentences (with a course) come last.
CAPTURES = ("ublox-zed-f9p-nmea.log", "plaka.log")
# Last GGA of the u-blox capture: 4552.65403,S,17030.00677,E,1,12,0.66,14.2,M,1.8,M
LAST_LAT = -(45 + 52.65403 / 60)
LAST_LON = 170 + 30.00677 / 60
# Last VTG of plaka.log: 217.40,T,...,5.83,N
LAST_SPEED = 5.83 * KNOT_TO_MPS
LAST_COG_DEG = 217.40


def _sentences() -> list[bytes]:
    out = []
    for name in CAPTURES:
        for line in (DATA / name).read_bytes().splitlines():
            line = line.strip()
            if line and not line.startswith(b"#"):
                out.append(line + b"\r\n")
    return out


def _corrupt(data: bytes, rate: float = 0.01, seed: int = 7) -> bytes:
    rng = random.Random(seed)
    buf = bytearray(data)
    for i in range(len(buf)):
        if rng.random() < rate:
            buf[i] ^= rng.randrange(1, 256)
    return bytes(buf)


def _writer(fd: int, data: bytes, chunk: int = 256) -> None:
    pos = 0
    while pos < len(data):
        try:
            pos += os.write(fd, data[pos : pos + chunk])
        except BlockingIOError:
            pass
        time.sleep(0.002)


def _run(data: bytes):
    """Replays ``data`` through a pty into a simulated GpsSerialSource; returns (fix, status)."""
    master, slave = os.openpty()
    os.set_blocking(master, False)
    system = GpsSerialSource(os.ttyname(slave), 115200, "amsterdam", period=0.02)
    try:
        sim = Simulator(system)
        sim.Initialize()
        ctx = sim.get_context()
        thread = threading.Thread(target=_writer, args=(master, data), daemon=True)
        thread.start()
        deadline = time.monotonic() + 15.0
        t = 0.0
        while system.status(ctx).bytes_read < len(data):
            assert time.monotonic() < deadline, f"only {system.status(ctx)} of {len(data)} B"
            t += 0.1
            sim.AdvanceTo(t)
            time.sleep(0.01)
        thread.join(timeout=5.0)
        sim.AdvanceTo(t + 0.1)  # everything read; one more update changes nothing
        fix = system.GetOutputPort("gps").Eval(ctx)
        # the counters on the diagnostics port, for runners (a flat dict of the status), and
        # the port's link (never lost here)
        assert system.GetOutputPort("diagnostics").Eval(ctx) == dataclasses.asdict(
            system.status(ctx)
        ) | {"connected": True, "disconnects": 0, "reconnects": 0}
        return fix, system.status(ctx)
    finally:
        system.close()
        os.close(master)
        os.close(slave)


def test_replay_decodes_last_fix_and_speed():
    lines = _sentences()
    expected_bad = 0
    for s in lines:
        try:
            decode(s)
        except NmeaError:
            expected_bad += 1
    fix, st = _run(b"".join(lines))
    assert st.sentences == len(lines)
    assert st.bad_sentences == expected_bad
    assert st.fixes == 6
    assert fix.valid and fix.satellites == 12
    assert fix.latitude == pytest.approx(LAST_LAT, abs=1e-7)  # 1e-5' ~ 1.7e-7 deg
    assert fix.longitude == pytest.approx(LAST_LON, abs=1e-7)
    assert fix.altitude == pytest.approx(14.2 + 1.8)
    assert fix.hdop == pytest.approx(0.66)
    assert fix.covariance_enu[0, 0] == pytest.approx((0.66 * 3.0) ** 2 / 2)
    assert fix.speed == pytest.approx(LAST_SPEED, abs=1e-9)
    assert fix.course == pytest.approx(math.pi / 2 - math.radians(LAST_COG_DEG))
    assert fix.time > 0.0


def test_corrupted_stream_counts_bad_sentences_and_keeps_going():
    data = _corrupt(b"".join(_sentences()))
    fix, st = _run(data)
    assert st.bad_sentences > 0
    assert st.fixes > 0
    assert fix.valid
    assert fix.latitude == pytest.approx(LAST_LAT, abs=1e-4)
    assert fix.longitude == pytest.approx(LAST_LON, abs=1e-4)


def test_missing_port_raises_one_line_error():
    port = "/dev/ttyUSB9-does-not-exist"
    with pytest.raises(PortNotFoundError) as e:
        SerialTransport(port, 9600)
    msg = str(e.value)
    assert port in msg and "\n" not in msg
    assert isinstance(e.value, OSError)
    with pytest.raises(PortNotFoundError, match="ttyUSB9"):
        GpsSerialSource(port, 9600, "amsterdam")


def test_unplug_closes_port_and_read_keeps_returning_empty():
    master, slave = os.openpty()
    transport = SerialTransport(os.ttyname(slave), 9600, reconnect_period=0.05)
    os.write(master, b"$abc")
    deadline = time.monotonic() + 5.0
    got = b""
    while got != b"$abc":
        assert time.monotonic() < deadline
        got += transport.read()[0]
    os.close(master)  # unplug: the pty disappears
    os.close(slave)
    for _ in range(5):
        data, host_time = transport.read()
        assert data == b"" and host_time > 0
        time.sleep(0.06)
    assert transport.errors == 1 and not transport.connected and transport.reconnects == 0
    transport.close()
