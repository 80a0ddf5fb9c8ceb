"""Slamtec RPLIDAR A1 serial protocol (Ueland 2017's lidar, 115200 baud 8N1): pure codec, no I/O.

Requests (host → device)::

    0xA5  cmd                                   commands without payload (SCAN, STOP, ...)
    0xA5  cmd  size  payload[size]  checksum     commands with bit 7 set (0x80) carry a payload;
                                                 checksum = XOR of every byte before it

    SCAN 0x20, STOP 0x25, RESET 0x40, GET_INFO 0x50, GET_HEALTH 0x52 (no payload);
    e.g. SET_MOTOR_PWM 0xF0 carries a payload.

Response descriptor (device → host, 7 bytes, once before the response data)::

    0xA5 0x5A  | uint32 LE: bits 0-29 response length, bits 30-31 send mode | data type
    SCAN: A5 5A 05 00 00 40 81  (5-byte nodes, mode 1 = multiple responses, type 0x81)

Standard scan measurement node (5 bytes, repeated until STOP)::

    byte 0     quality << 2 | (not S) << 1 | S      S = first node of a new revolution
    byte 1-2   uint16 LE: angle_q6 << 1 | C         C = check bit, always 1
                                                    angle [deg] = angle_q6 / 64, clockwise
    byte 3-4   uint16 LE: distance_q2               distance [mm] = distance_q2 / 4, 0 = no return

The nodes carry only two check bits (S ≠ not-S, C = 1): :class:`ScanNodeParser` resynchronises
byte by byte on them (like the vendor SDK), so a byte that fails the checks is skipped, but
arbitrary line noise can still yield plausible-looking spurious nodes -- there is no checksum.

Angles: RPLIDAR measures clockwise (seen from above) from the sensor's 0° mark (x forward).
:class:`usvdrake.sensors.messages.LaserScan` is counter-clockwise (x forward, y left), so a
node at ``angle_deg`` points at ``-radians(angle_deg)`` (wrapped to [-π, π)) in the scan.

Every decoding error is a :class:`RplidarError` (a ``ValueError``); nothing else is raised and
no node whose check bits do not match is ever returned.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from usvdrake.sensors.messages import LaserScan

__all__ = [
    "ANS_TYPE_DEVHEALTH",
    "ANS_TYPE_DEVINFO",
    "ANS_TYPE_MEASUREMENT",
    "CMD_GET_HEALTH",
    "CMD_GET_INFO",
    "CMD_RESET",
    "CMD_SCAN",
    "CMD_STOP",
    "NODE_SIZE",
    "SCAN_DESCRIPTOR",
    "Request",
    "ResponseDescriptor",
    "RplidarError",
    "RplidarRevolution",
    "RplidarScanAssembler",
    "ScanNode",
    "ScanNodeParser",
    "decode_descriptor",
    "decode_node",
    "decode_nodes",
    "decode_request",
    "encode_descriptor",
    "encode_node",
    "encode_request",
    "laser_scan_to_nodes",
    "node_checks_ok",
]

SYNC_BYTE = 0xA5
SYNC_BYTE2 = 0x5A
CMD_FLAG_HAS_PAYLOAD = 0x80

CMD_SCAN = 0x20
CMD_STOP = 0x25
CMD_RESET = 0x40
CMD_GET_INFO = 0x50
CMD_GET_HEALTH = 0x52

ANS_TYPE_DEVINFO = 0x04
ANS_TYPE_DEVHEALTH = 0x06
ANS_TYPE_MEASUREMENT = 0x81

SEND_MODE_SINGLE = 0
SEND_MODE_MULTI = 1

NODE_SIZE = 5
DESCRIPTOR_SIZE = 7
MAX_PAYLOAD = 255

ANGLE_Q6_MAX = 0x7FFF  # 15 bits on the wire (the device sends [0, 360) deg = [0, 23040))
DISTANCE_Q2_MAX = 0xFFFF
QUALITY_MAX = 0x3F


class RplidarError(ValueError):
    """Bytes that are not a valid request, response descriptor or measurement node."""


def _check_int(name: str, v, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
        raise ValueError(f"{name}: not an integer: {v!r}")
    v = int(v)
    if not lo <= v <= hi:
        raise ValueError(f"{name} = {v} outside [{lo}, {hi}]")
    return v


def _as_bytes(data, err=RplidarError) -> bytes:
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise err(f"not a byte string: {type(data).__name__}")
    return bytes(data)


# ------------------------------------------------------------------------------------------
# Requests


@dataclass(frozen=True)
class Request:
    cmd: int
    payload: bytes | None = None  # None: a command without payload (bit 7 clear)


def encode_request(cmd: int, payload: bytes | None = None) -> bytes:
    """``0xA5 cmd`` or, for commands with bit 7 set, ``0xA5 cmd size payload checksum``."""
    cmd = _check_int("cmd", cmd, 0, 0xFF)
    if not cmd & CMD_FLAG_HAS_PAYLOAD:
        if payload:
            raise ValueError(f"command 0x{cmd:02x} carries no payload (bit 7 clear)")
        return bytes([SYNC_BYTE, cmd])
    payload = bytes(payload or b"")
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes (max {MAX_PAYLOAD})")
    body = bytes([SYNC_BYTE, cmd, len(payload)]) + payload
    c = 0
    for b in body:
        c ^= b
    return body + bytes([c])


def decode_request(data: bytes) -> Request:
    """Decode exactly one request packet."""
    data = _as_bytes(data)
    if len(data) < 2 or data[0] != SYNC_BYTE:
        raise RplidarError("request must start with 0xA5 cmd")
    cmd = data[1]
    if not cmd & CMD_FLAG_HAS_PAYLOAD:
        if len(data) != 2:
            raise RplidarError(f"command 0x{cmd:02x} without payload must be 2 bytes")
        return Request(cmd, None)
    if len(data) < 4 or len(data) != 4 + data[2]:
        raise RplidarError("payload request length does not match its size byte")
    c = 0
    for b in data[:-1]:
        c ^= b
    if c != data[-1]:
        raise RplidarError("request checksum mismatch")
    return Request(cmd, data[3:-1])


# ------------------------------------------------------------------------------------------
# Response descriptor


@dataclass(frozen=True)
class ResponseDescriptor:
    length: int  # 30 bits: bytes per response (5 for a scan node)
    send_mode: int  # 2 bits: 0 single response, 1 multiple responses
    data_type: int  # 0x81 scan node, 0x04 device info, 0x06 device health


def encode_descriptor(d: ResponseDescriptor) -> bytes:
    length = _check_int("length", d.length, 0, (1 << 30) - 1)
    mode = _check_int("send_mode", d.send_mode, 0, 3)
    dtype = _check_int("data_type", d.data_type, 0, 0xFF)
    return bytes([SYNC_BYTE, SYNC_BYTE2]) + struct.pack("<IB", length | (mode << 30), dtype)


def decode_descriptor(data: bytes) -> ResponseDescriptor:
    data = _as_bytes(data)
    if len(data) != DESCRIPTOR_SIZE:
        raise RplidarError(f"response descriptor must be 7 bytes, got {len(data)}")
    if data[0] != SYNC_BYTE or data[1] != SYNC_BYTE2:
        raise RplidarError("response descriptor must start with 0xA5 0x5A")
    word, dtype = struct.unpack("<IB", data[2:])
    return ResponseDescriptor(word & ((1 << 30) - 1), word >> 30, dtype)


SCAN_DESCRIPTOR = encode_descriptor(ResponseDescriptor(NODE_SIZE, SEND_MODE_MULTI, 0x81))


# ------------------------------------------------------------------------------------------
# Measurement nodes


@dataclass(frozen=True)
class ScanNode:
    """One standard scan measurement, raw wire integers (exact round trips)."""

    quality: int  # 0..63 (A1: 0 or ~15 in practice)
    angle_q6: int  # 0..32767, angle [deg] = angle_q6 / 64, clockwise
    distance_q2: int  # 0..65535, distance [mm] = distance_q2 / 4; 0 = no return
    start: bool = False  # first node of a new revolution

    @property
    def angle_deg(self) -> float:
        return self.angle_q6 / 64.0

    @property
    def distance_mm(self) -> float:
        return self.distance_q2 / 4.0

    @property
    def distance_m(self) -> float:
        return self.distance_q2 / 4000.0

    @classmethod
    def from_values(
        cls, angle_deg: float, distance_mm: float, quality: int = 15, start: bool = False
    ) -> ScanNode:
        """Quantise an angle [deg, clockwise, wrapped to [0, 360)] and a distance [mm]."""
        if not (math.isfinite(angle_deg) and math.isfinite(distance_mm)):
            raise ValueError("angle and distance must be finite")
        q6 = round((angle_deg % 360.0) * 64.0) % (360 * 64)
        q2 = round(distance_mm * 4.0)
        return cls(quality, q6, q2, bool(start))


def node_checks_ok(b0: int, b1: int) -> bool:
    """The two check bits of a node: S ≠ not-S in byte 0 and C = 1 in byte 1."""
    return ((b0 ^ (b0 >> 1)) & 1) == 1 and (b1 & 1) == 1


def encode_node(node: ScanNode) -> bytes:
    q = _check_int("quality", node.quality, 0, QUALITY_MAX)
    a = _check_int("angle_q6", node.angle_q6, 0, ANGLE_Q6_MAX)
    d = _check_int("distance_q2", node.distance_q2, 0, DISTANCE_Q2_MAX)
    s = 1 if node.start else 0
    return struct.pack("<BHH", (q << 2) | ((s ^ 1) << 1) | s, (a << 1) | 1, d)


def decode_node(data: bytes) -> ScanNode:
    """Decode exactly one 5-byte node; checks the S/not-S pair and the check bit C."""
    data = _as_bytes(data)
    if len(data) != NODE_SIZE:
        raise RplidarError(f"scan node must be 5 bytes, got {len(data)}")
    b0, aw, d = struct.unpack("<BHH", data)
    if not ((b0 ^ (b0 >> 1)) & 1):
        raise RplidarError("start flag and its inverse disagree")
    if not aw & 1:
        raise RplidarError("check bit C is not set")
    return ScanNode(b0 >> 2, aw >> 1, d, bool(b0 & 1))


def decode_nodes(data: bytes) -> list[ScanNode]:
    """Decode a whole number of back-to-back nodes (all must be valid)."""
    data = _as_bytes(data)
    if len(data) % NODE_SIZE:
        raise RplidarError(f"{len(data)} bytes is not a whole number of 5-byte nodes")
    return [decode_node(data[i : i + NODE_SIZE]) for i in range(0, len(data), NODE_SIZE)]


class ScanNodeParser:
    """Byte stream (after a SCAN request) → nodes.

    Skips a leading scan response descriptor (``A5 5A 05 00 00 40 81``, counted in
    ``descriptors``), reassembles nodes split across reads, and on a node whose check bits
    fail drops one byte and retries (``check_errors``, ``discarded_bytes``). Keeps at most
    ``max_buffer`` bytes.
    """

    def __init__(self, max_buffer: int = 4096):
        if max_buffer < DESCRIPTOR_SIZE:
            raise ValueError(f"max_buffer must be at least {DESCRIPTOR_SIZE}")
        self.max_buffer = max_buffer
        self._buf = bytearray()
        self.nodes = 0
        self.descriptors = 0
        self.check_errors = 0
        self.discarded_bytes = 0

    def reset(self) -> None:
        self._buf.clear()

    def feed(self, data: bytes) -> list[ScanNode]:
        self._buf += bytes(data)
        buf = self._buf
        out: list[ScanNode] = []
        i, n = 0, len(buf)
        while n - i >= NODE_SIZE:
            if buf[i] == SYNC_BYTE and buf[i + 1] == SYNC_BYTE2:
                if n - i < DESCRIPTOR_SIZE:
                    break  # wait: may be a descriptor
                if buf[i : i + DESCRIPTOR_SIZE] == SCAN_DESCRIPTOR:
                    self.descriptors += 1
                    i += DESCRIPTOR_SIZE
                    continue
            b0, b1 = buf[i], buf[i + 1]
            if node_checks_ok(b0, b1):
                out.append(
                    ScanNode(
                        b0 >> 2, (b1 | (buf[i + 2] << 8)) >> 1, buf[i + 3] | (buf[i + 4] << 8),
                        bool(b0 & 1),
                    )
                )  # fmt: skip
                i += NODE_SIZE
            else:
                self.check_errors += 1
                self.discarded_bytes += 1
                i += 1
        del buf[:i]
        if len(buf) > self.max_buffer:
            self.discarded_bytes += len(buf) - self.max_buffer
            del buf[: len(buf) - self.max_buffer]
        self.nodes += len(out)
        return out


# ------------------------------------------------------------------------------------------
# Revolutions


@dataclass(frozen=True)
class RplidarRevolution:
    """One revolution as measured: the nodes from one start flag to before the next.

    ``time`` is the host time of the last node, ``scan_time`` the time from this revolution's
    start node to the next one's (0 when flushed without a following start node).
    """

    nodes: tuple[ScanNode, ...]
    time: float = 0.0
    scan_time: float = 0.0

    @property
    def angles_deg(self) -> np.ndarray:
        """Clockwise angles [deg] as measured (not sorted, may exceed 360 on the wire)."""
        return np.array([n.angle_q6 for n in self.nodes], float) / 64.0

    @property
    def distances_m(self) -> np.ndarray:
        """[m]; 0 = no return."""
        return np.array([n.distance_q2 for n in self.nodes], float) / 4000.0

    @property
    def qualities(self) -> np.ndarray:
        return np.array([n.quality for n in self.nodes], int)

    def to_laser_scan(
        self,
        num_beams: int = 360,
        range_min: float = 0.15,
        range_max: float = 12.0,
        min_quality: int = 0,
    ) -> LaserScan:
        """Bin onto the fixed grid ``angle_min = -π``, ``angle_increment = 2π / num_beams``
        (counter-clockwise, beam i at ``-π + i·inc``).

        Each node's clockwise angle θ becomes ``-radians(θ)`` and goes to the nearest beam
        (wrapping around). When several returns fall into one beam the nearest valid one is
        kept. Nodes with distance 0, quality below ``min_quality`` or a distance outside
        [range_min, range_max] are no returns; beams without a valid return get
        ``ranges = inf``, ``valid = False``. Defaults: A1 range 0.15 – 12 m.
        """
        if num_beams < 1:
            raise ValueError("num_beams must be positive")
        inc = 2.0 * math.pi / num_beams
        ranges = np.full(num_beams, np.inf)
        if self.nodes:
            a = -np.radians(self.angles_deg)
            idx = np.rint((a + math.pi) / inc).astype(int) % num_beams
            r = self.distances_m
            ok = (r > 0) & (r >= range_min) & (r <= range_max) & (self.qualities >= min_quality)
            np.minimum.at(ranges, idx[ok], r[ok])
        return LaserScan(
            time=self.time,
            angle_min=-math.pi,
            angle_increment=inc,
            range_min=range_min,
            range_max=range_max,
            scan_time=self.scan_time,
            ranges=ranges,
            valid=np.isfinite(ranges),
        )


class RplidarScanAssembler:
    """Nodes → revolutions, cut at the start flag (S = 1).

    Nodes before the first start flag are an incomplete revolution and are dropped
    (``dropped_nodes``). A revolution is returned when the next start node arrives, or by
    :meth:`flush`. ``time`` passed to :meth:`add`/:meth:`feed` is the host receive time.

    Bounded memory: a revolution that reaches ``max_nodes`` nodes without the next start flag
    (default 16384, a few times the most a revolution holds -- 32 k samples/s at 5 Hz on the
    fastest models, ~1.5 k in the legacy scan mode) is dropped (``overlong_revolutions``, its
    nodes in ``dropped_nodes``), and nodes are dropped until the next start flag.
    """

    def __init__(self, max_nodes: int = 16384):
        if max_nodes < 1:
            raise ValueError("max_nodes must be positive")
        self.max_nodes = int(max_nodes)
        self._nodes: list[ScanNode] = []
        self._t_start: float | None = None
        self._t_last = 0.0
        self.revolutions = 0
        self.dropped_nodes = 0
        self.overlong_revolutions = 0

    def add(self, node: ScanNode, time: float = 0.0) -> RplidarRevolution | None:
        out = None
        if node.start:
            if self._t_start is not None and self._nodes:
                out = RplidarRevolution(
                    tuple(self._nodes), self._t_last, float(time) - self._t_start
                )
                self.revolutions += 1
            self._nodes = []
            self._t_start = float(time)
        elif self._t_start is None:
            self.dropped_nodes += 1
            return None
        elif len(self._nodes) >= self.max_nodes:  # start flag lost: not a revolution
            self.overlong_revolutions += 1
            self.dropped_nodes += len(self._nodes) + 1
            self._nodes, self._t_start = [], None
            return None
        self._nodes.append(node)
        self._t_last = float(time)
        return out

    def feed(self, nodes, time: float = 0.0) -> list[RplidarRevolution]:
        out = []
        for n in nodes:
            rev = self.add(n, time)
            if rev is not None:
                out.append(rev)
        return out

    def flush(self) -> RplidarRevolution | None:
        """Return the revolution in progress (``scan_time`` 0) and start over."""
        if self._t_start is None or not self._nodes:
            return None
        rev = RplidarRevolution(tuple(self._nodes), self._t_last, 0.0)
        self._nodes, self._t_start = [], None
        self.revolutions += 1
        return rev


def laser_scan_to_nodes(scan: LaserScan, quality: int = 15) -> list[ScanNode]:
    """A simulated scan as the device would send it (e.g. to emulate an RPLIDAR): one node per
    beam in clockwise order starting at the beam nearest 0°, the first with the start flag;
    invalid beams are sent with distance 0. Angles and distances are quantised (1/64°, ¼ mm).
    """
    ranges = np.asarray(scan.ranges, float)
    valid = np.asarray(scan.valid, bool) & np.isfinite(ranges)
    cw = np.mod(-np.degrees(scan.angles), 360.0)
    order = np.argsort(np.mod(np.rint(cw * 64.0), 360 * 64), kind="stable")
    nodes = []
    for k, i in enumerate(order):
        d = ranges[i] * 1000.0 if valid[i] else 0.0
        nodes.append(
            ScanNode.from_values(float(cw[i]), float(d), quality if valid[i] else 0, k == 0)
        )
    return nodes
