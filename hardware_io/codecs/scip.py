"""Hokuyo SCIP 2.0 (UTM-30LX, Pham et al.'s lidar): pure codec, no I/O.

Commands (host → sensor), ASCII terminated by LF, optional ``;string`` (≤ 16 characters) that
the sensor echoes back::

    VV  PP  II  BM  QT  RS                          version, parameters, state, laser on/off, reset
    GD ssss eeee cc [;str]                          one scan: start step, end step, cluster count
    MD ssss eeee cc i nn [;str]                     continuous: + scan interval, number of scans
                                                    (00 = until QT); GS/MS: 2-character values

Responses (sensor → host)::

    echo LF                     the command as received (MD data: remaining number of scans)
    ss sum LF                   status "00" ok ("99" = MD/MS scan data), sum over the 2 chars
    [tttt sum LF]               timestamp [ms], 4-character encoding (24 bits, wraps)
    [data sum LF] ...           data cut into lines of 64 characters (the last one shorter)
    LF                          a blank line ends every response

Character encoding: each character carries 6 bits as ``value + 0x30``, most significant first
(3 characters: 0 .. 262143 mm). Line checksum: ``(sum of the line's data bytes & 0x3F) + 0x30``.
Info lines of VV/PP/II (``DMIN:23;X``) have the sum over the text before the ``;``.

Decoded scan data: :class:`ScanData` (raw distances [mm] per cluster; the UTM-30LX reports
values below ~20 mm as error codes). UTM-30LX geometry: 1081 steps, step 0 at −135°, 0.25° per
step, front step 540, counter-clockwise (seen from above) like ``LaserScan``; see
:func:`to_laser_scan`.

Every decoding error is a :class:`ScipError` (a ``ValueError``); nothing else is raised and no
response with a wrong line checksum is ever returned.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from usvdrake.sensors.messages import LaserScan

__all__ = [
    "LINE_DATA_MAX",
    "UTM30LX",
    "ScanData",
    "ScipCommand",
    "ScipError",
    "ScipResponse",
    "ScipStream",
    "SensorGeometry",
    "checksum",
    "decode_command",
    "decode_response",
    "decode_values",
    "encode_command",
    "encode_response",
    "encode_scan_command",
    "encode_scan_data",
    "encode_values",
    "to_laser_scan",
]

LF = b"\n"
LINE_DATA_MAX = 64
MAX_STRING = 16
SCAN_COMMANDS = {"GD": 3, "GS": 2, "MD": 3, "MS": 2}  # name → characters per value
INFO_COMMANDS = {"VV", "PP", "II"}
SIMPLE_COMMANDS = {"VV", "PP", "II", "BM", "QT", "RS"}
KNOWN_COMMANDS = SIMPLE_COMMANDS | set(SCAN_COMMANDS)
MAX_STEP = 9999


class ScipError(ValueError):
    """Bytes that are not a valid SCIP 2.0 command or response (framing, checksum, field)."""


@dataclass(frozen=True)
class SensorGeometry:
    steps: int  # number of measurement steps (AMIN .. AMAX)
    step0_deg: float  # angle of step 0, counter-clockwise from the front
    step_deg: float  # angular resolution per step
    front_step: int
    range_min: float  # [m]
    range_max: float  # [m]
    scan_time: float  # [s] one revolution


UTM30LX = SensorGeometry(1081, -135.0, 0.25, 540, 0.023, 30.0, 0.025)


# ------------------------------------------------------------------------------------------
# Character encoding and checksum


def checksum(data: bytes) -> int:
    """SCIP line checksum: low 6 bits of the byte sum, plus 0x30."""
    return (sum(data) & 0x3F) + 0x30


def encode_values(values, nchars: int = 3) -> bytes:
    """Each value as ``nchars`` characters of 6 bits (value + 0x30), most significant first."""
    if nchars not in (2, 3, 4):
        raise ValueError("nchars must be 2, 3 or 4")
    hi = (1 << (6 * nchars)) - 1
    out = bytearray()
    for v in values:
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise ValueError(f"not an integer: {v!r}")
        v = int(v)
        if not 0 <= v <= hi:
            raise ValueError(f"value {v} outside [0, {hi}] for {nchars}-character encoding")
        for k in range(nchars - 1, -1, -1):
            out.append(((v >> (6 * k)) & 0x3F) + 0x30)
    return bytes(out)


def decode_values(data: bytes, nchars: int = 3) -> list[int]:
    data = bytes(data)
    if len(data) % nchars:
        raise ScipError(f"{len(data)} characters is not a multiple of {nchars}")
    out = []
    for i in range(0, len(data), nchars):
        v = 0
        for c in data[i : i + nchars]:
            if not 0x30 <= c <= 0x6F:
                raise ScipError(f"character 0x{c:02x} outside the 6-bit range 0x30..0x6F")
            v = (v << 6) | (c - 0x30)
        out.append(v)
    return out


# ------------------------------------------------------------------------------------------
# Commands


@dataclass(frozen=True)
class ScipCommand:
    name: str  # "MD", "GD", "VV", ...
    start_step: int | None = None
    end_step: int | None = None
    cluster_count: int | None = None
    scan_interval: int | None = None  # MD/MS only
    num_scans: int | None = None  # MD/MS only (00 = unlimited)
    string: str = ""


_STRING_RE = re.compile(r"[\x20-\x3a\x3c-\x7e]{0,16}\Z")  # printable ASCII except ';'


def _check_string(s: str) -> str:
    if not isinstance(s, str) or not _STRING_RE.match(s):
        raise ValueError(f"string must be ≤ {MAX_STRING} printable characters without ';'")
    return s


def _tail(string: str) -> bytes:
    return (";" + string).encode("ascii") if string else b""


def encode_command(name: str, string: str = "") -> bytes:
    """A command without parameters (VV, PP, II, BM, QT, RS), with optional ``;string``."""
    if name not in SIMPLE_COMMANDS:
        raise ValueError(f"unknown parameterless command {name!r}")
    return name.encode("ascii") + _tail(_check_string(string)) + LF


def encode_scan_command(
    name: str = "MD",
    start_step: int = 0,
    end_step: int = 1080,
    cluster_count: int = 1,
    scan_interval: int = 0,
    num_scans: int = 0,
    string: str = "",
) -> bytes:
    """``GD``/``GS``: ssss eeee cc; ``MD``/``MS``: ssss eeee cc i nn; then ``;string`` LF."""
    return (
        _command_text(
            ScipCommand(name, start_step, end_step, cluster_count, scan_interval, num_scans, string)
        )
        + LF
    )


def _command_text(c: ScipCommand) -> bytes:
    if c.name in SIMPLE_COMMANDS:
        return c.name.encode("ascii") + _tail(_check_string(c.string))
    if c.name not in SCAN_COMMANDS:
        raise ValueError(f"unknown command {c.name!r}")
    for f, hi in (("start_step", MAX_STEP), ("end_step", MAX_STEP), ("cluster_count", 99)):
        v = getattr(c, f)
        if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= hi:
            raise ValueError(f"{f} = {v!r} outside [0, {hi}]")
    if c.start_step > c.end_step:
        raise ValueError("start_step > end_step")
    text = f"{c.name}{c.start_step:04d}{c.end_step:04d}{c.cluster_count:02d}"
    if c.name[0] == "M":
        for f, hi in (("scan_interval", 9), ("num_scans", 99)):
            v = getattr(c, f)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= hi:
                raise ValueError(f"{f} = {v!r} outside [0, {hi}]")
        text += f"{c.scan_interval:01d}{c.num_scans:02d}"
    return text.encode("ascii") + _tail(_check_string(c.string))


_SCAN_CMD_RE = re.compile(
    rb"(?P<name>[GM][DS])(?P<s>\d{4})(?P<e>\d{4})(?P<c>\d{2})(?:(?P<i>\d)(?P<n>\d{2}))?"
    rb"(?:;(?P<str>[\x20-\x3a\x3c-\x7e]{1,16}))?\Z"
)
_SIMPLE_CMD_RE = re.compile(
    rb"(?P<name>VV|PP|II|BM|QT|RS)(?:;(?P<str>[\x20-\x3a\x3c-\x7e]{1,16}))?\Z"
)


def decode_command(line: bytes) -> ScipCommand:
    """Decode a command (or an echo line), with or without the terminating LF."""
    line = bytes(line)
    if line.endswith(LF):
        line = line[:-1]
    m = _SIMPLE_CMD_RE.match(line)
    if m:
        return ScipCommand(m["name"].decode(), string=(m["str"] or b"").decode())
    m = _SCAN_CMD_RE.match(line)
    if not m:
        raise ScipError(f"not a SCIP 2.0 command: {line[:40]!r}")
    name = m["name"].decode()
    if (m["i"] is not None) != (name[0] == "M"):
        raise ScipError(f"wrong parameter count for {name}")
    s, e = int(m["s"]), int(m["e"])
    if s > e:
        raise ScipError("start step > end step")
    return ScipCommand(
        name,
        s,
        e,
        int(m["c"]),
        None if m["i"] is None else int(m["i"]),
        None if m["n"] is None else int(m["n"]),
        (m["str"] or b"").decode(),
    )


# ------------------------------------------------------------------------------------------
# Responses


@dataclass(frozen=True)
class ScipResponse:
    """Any response without scan data: echo, status and the data lines (checksums removed;
    for VV/PP/II the trailing ``;`` too)."""

    command: ScipCommand
    status: str  # two characters, "00" = ok
    lines: tuple[bytes, ...] = ()


@dataclass(frozen=True)
class ScanData:
    """A GD/GS (status "00") or MD/MS (status "99") scan."""

    command: ScipCommand
    status: str
    timestamp_ms: int  # 24-bit sensor clock [ms]
    distances_mm: tuple[int, ...]  # one per cluster, raw (values < ~20 are error codes)

    @property
    def num_values(self) -> int:
        return len(self.distances_mm)


def num_clusters(c: ScipCommand) -> int:
    n = c.end_step - c.start_step + 1
    k = max(c.cluster_count, 1)  # cluster count 00 means 1
    return -(-n // k)


def _has_data(c: ScipCommand, status: str) -> bool:
    if c.name in ("GD", "GS"):
        return status == "00"
    if c.name in ("MD", "MS"):
        return status == "99"
    return False


def _status_line(status: str) -> bytes:
    if not isinstance(status, str) or not re.fullmatch(r"[\x21-\x7e]{2}", status):
        raise ValueError(f"status must be 2 printable characters, got {status!r}")
    s = status.encode("ascii")
    return s + bytes([checksum(s)]) + LF


def _data_line(data: bytes) -> bytes:
    return data + bytes([checksum(data)]) + LF


def encode_response(command: ScipCommand, status: str = "00", lines=()) -> bytes:
    """A response without scan data (e.g. the ``00`` acknowledgement of MD, BM, QT, or VV/PP
    info lines, sent as ``text;sum``)."""
    if _has_data(command, status):
        raise ValueError("use encode_scan_data for a response with scan data")
    if lines and command.name not in INFO_COMMANDS:
        raise ValueError(f"{command.name} responses carry no data lines")
    out = bytearray(_command_text(command) + LF + _status_line(status))
    for line in lines:
        line = bytes(line)
        if not line or len(line) > LINE_DATA_MAX or LF in line:
            raise ValueError("a line must have 1..64 characters without LF")
        out += line + b";" + bytes([checksum(line)]) + LF
    return bytes(out + LF)


def encode_scan_data(scan: ScanData) -> bytes:
    """Echo, status, timestamp, data lines of 64 characters, blank line."""
    c = scan.command
    if c.name not in SCAN_COMMANDS or not _has_data(c, scan.status):
        raise ValueError(f"{c.name} with status {scan.status!r} carries no scan data")
    if len(scan.distances_mm) != num_clusters(c):
        raise ValueError(
            f"{len(scan.distances_mm)} distances for {num_clusters(c)} clusters of {c}"
        )
    ts = encode_values([scan.timestamp_ms], 4)  # checks 0 .. 2**24 - 1
    data = encode_values(scan.distances_mm, SCAN_COMMANDS[c.name])
    out = bytearray(_command_text(c) + LF + _status_line(scan.status) + _data_line(ts))
    for i in range(0, len(data), LINE_DATA_MAX):
        out += _data_line(data[i : i + LINE_DATA_MAX])
    return bytes(out + LF)


def _checked(line: bytes, what: str) -> bytes:
    if len(line) < 2:
        raise ScipError(f"{what} line too short")
    if checksum(line[:-1]) != line[-1]:
        raise ScipError(f"{what} line checksum mismatch")
    return line[:-1]


def decode_response(frame: bytes) -> ScipResponse | ScanData:
    """Decode exactly one response, ending with the blank line (LF LF)."""
    if not isinstance(frame, (bytes, bytearray, memoryview)):
        raise ScipError(f"not a byte string: {type(frame).__name__}")
    frame = bytes(frame)
    if not frame.endswith(b"\n\n"):
        raise ScipError("response must end with a blank line (LF LF)")
    lines = frame[:-2].split(LF)
    if len(lines) < 2:
        raise ScipError("response needs an echo and a status line")
    cmd = decode_command(lines[0])
    status_line = lines[1]
    if len(status_line) != 3:
        raise ScipError("status line must be 2 characters + sum")
    status = _checked(status_line, "status").decode("latin-1")
    rest = lines[2:]
    if not _has_data(cmd, status):
        if cmd.name in INFO_COMMANDS:
            out = []
            for line in rest:
                if len(line) < 3 or line[-2:-1] != b";":
                    raise ScipError("info line must be text ; sum")
                if checksum(line[:-2]) != line[-1]:
                    raise ScipError("info line checksum mismatch")
                out.append(line[:-2])
            return ScipResponse(cmd, status, tuple(out))
        if rest:
            raise ScipError(f"{cmd.name} with status {status!r} carries no further lines")
        return ScipResponse(cmd, status)
    if not rest or len(rest[0]) != 5:
        raise ScipError("timestamp line must be 4 characters + sum")
    (ts,) = decode_values(_checked(rest[0], "timestamp"), 4)
    nchars = SCAN_COMMANDS[cmd.name]
    expected = num_clusters(cmd) * nchars
    data = bytearray()
    body = rest[1:]
    for k, line in enumerate(body):
        n = len(line) - 1
        if n < 1 or n > LINE_DATA_MAX or (k < len(body) - 1 and n != LINE_DATA_MAX):
            raise ScipError("data lines must carry 64 characters (the last one 1..64)")
        data += _checked(line, "data")
    if len(data) != expected:
        raise ScipError(f"{len(data)} data characters, expected {expected}")
    return ScanData(cmd, status, ts, tuple(decode_values(data, nchars)))


# ------------------------------------------------------------------------------------------
# Stream parser


class ScipStream:
    """Byte stream → responses, split on the blank line (LF LF).

    A block that does not decode is retried from each later line start or command name inside
    it (garbage before an echo is skipped, ``discarded_bytes``); a block with no valid response
    counts in ``errors`` (bad checksums included). Keeps at most ``max_buffer`` bytes
    without a blank line (oldest dropped first).
    """

    _NAME_RE = re.compile(rb"(?=VV|PP|II|BM|QT|RS|GD|GS|MD|MS)")  # overlapping matches

    def __init__(self, max_buffer: int = 16384):
        self.max_buffer = max_buffer
        self._buf = bytearray()
        self.responses = 0
        self.errors = 0
        self.discarded_bytes = 0

    def reset(self) -> None:
        self._buf.clear()

    def _decode_block(self, block: bytes):
        starts = {0} | {m.start() for m in self._NAME_RE.finditer(block)}
        starts |= {i + 1 for i, b in enumerate(block) if b == 0x0A and i + 1 < len(block)}
        for p in sorted(starts):
            if len(block) - p < 5:
                break
            try:
                msg = decode_response(block[p:])
            except ScipError:
                continue
            self.discarded_bytes += p
            return msg
        self.discarded_bytes += len(block)
        if block.strip(b"\n"):
            self.errors += 1
        return None

    def feed(self, data: bytes) -> list[ScipResponse | ScanData]:
        self._buf += bytes(data)
        out: list[ScipResponse | ScanData] = []
        while True:
            i = self._buf.find(b"\n\n")
            if i < 0:
                break
            block = bytes(self._buf[: i + 2])
            del self._buf[: i + 2]
            msg = self._decode_block(block)
            if msg is not None:
                self.responses += 1
                out.append(msg)
        if len(self._buf) > self.max_buffer:
            self.discarded_bytes += len(self._buf) - self.max_buffer
            del self._buf[: len(self._buf) - self.max_buffer]
        return out


# ------------------------------------------------------------------------------------------
# LaserScan


def to_laser_scan(
    scan: ScanData, time: float = 0.0, geometry: SensorGeometry = UTM30LX
) -> LaserScan:
    """One beam per cluster, at the centre of its steps: angle = step0 + step·res [rad, ccw],
    ``angle_increment`` = cluster count × res. Distances outside [range_min, range_max]
    (including the sensor's error codes below ~20 mm) become ``inf`` / ``valid = False``."""
    c = scan.command
    k = max(c.cluster_count, 1)
    res = math.radians(geometry.step_deg)
    a0 = math.radians(geometry.step0_deg) + (c.start_step + (k - 1) / 2.0) * res
    r = np.asarray(scan.distances_mm, float) / 1000.0
    ok = (r >= geometry.range_min) & (r <= geometry.range_max)
    return LaserScan(
        time=float(time),
        angle_min=a0,
        angle_increment=k * res,
        range_min=geometry.range_min,
        range_max=geometry.range_max,
        scan_time=geometry.scan_time,
        ranges=np.where(ok, r, np.inf),
        valid=ok,
    )
