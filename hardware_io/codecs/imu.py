"""Xsens MTi "Xbus" MTData2 codec (IMU/AHRS output): pure, bytes <-> messages, no I/O.

Followed: Xsens, *MT Low Level Communication Protocol Documentation* (document MT0101P,
revisions Y 2017 / 2019.A, "MTi 1/10/100/600-series"): section "Message structure" (Xbus
framing, extended length, checksum) and the MTData2 (MID 0x36) chapter with the table of data
identifiers (XDI); cross-checked with the MTi User Manual (MT0605P, "all binary data is
big-endian").

Message (every multi-byte field big-endian)::

    PRE 0xFA | BID 0xFF | MID 0x36 | LEN (1 byte, 0..254)              | DATA | CS
    PRE 0xFA | BID 0xFF | MID 0x36 | 0xFF | EXT_LEN (2 bytes, 255..2048) | DATA | CS

    CS: the sum of every byte after the preamble (BID .. CS inclusive) is 0 mod 256.

MTData2 DATA is a sequence of packets ``XDI (uint16) | size (uint8) | payload (size bytes)``.
The two lowest XDI bits select the number format (0 float32, 3 float64; 1 and 2 are the fixed
point formats fp1220 / fp1632, not decoded here), bits 2-3 the output frame of orientation
(0x0 ENU, 0x4 NED, 0x8 NWU). Decoded packets:

======  ==================  ===========================================================
XDI     name                decoded field (SI)
======  ==================  ===========================================================
0x1020  PacketCounter       ``packet_counter`` uint16 (wraps)
0x1060  SampleTimeFine      ``sample_time_fine`` uint32, ticks of 100 µs (10 kHz, wraps)
0x2010  Quaternion          ``quaternion`` (q0, q1, q2, q3) = (w, x, y, z), sensor -> frame
0x2030  EulerAngles         ``euler_rad`` (roll, pitch, yaw) [rad]; on the wire [deg]
0x4020  Acceleration        ``acceleration`` (x, y, z) [m/s²] specific force (gravity incl.)
0x8020  RateOfTurn          ``rate_of_turn`` (x, y, z) [rad/s]
0xE020  StatusWord          ``status_word`` uint32
======  ==================  ===========================================================

(each of 0x2010/0x2030 optionally with a frame bit 0x4/0x8, each float XDI optionally with
format bits 0x3). Any other packet, and a known quantity in a fixed-point format, is kept
verbatim in ``other`` -- the protocol says unknown packets are skipped by their size -- and
re-encoded after the known ones.

Encoding is canonical: counter, time, quaternion, Euler, acceleration, rate of turn, status,
then ``other``; every float packet as float32 (or float64 with ``float64=True``). So
``encode_mtdata2(decode_mtdata2(frame)) == frame`` holds for canonical frames, and
``decode_mtdata2(encode_mtdata2(m)) == m`` for every message on the float32 grid
(:func:`quantise` maps any message onto it). The one exception: Euler angles sent as float64
(degrees on the wire, radians here) round-trip only to within an ulp.

Frames: the Xsens sensor frame is x forward, y left, z up (the default, with orientation in
ENU), the same as the project's body frame and ``ImuSample`` (quaternion body -> ENU, but stored
x, y, z, w there). :func:`to_imu_sample` only accepts ENU orientation; a non-default sensor
alignment (SetAlignmentRotation) is the installer's business, not the codec's.

Every decoding error is a :class:`MtError` (a ``ValueError``); nothing else is raised and no
message whose checksum does not match is ever returned.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from usvdrake.sensors.messages import ImuSample

__all__ = [
    "BID_MASTER",
    "MAX_PAYLOAD",
    "MID_MTDATA2",
    "PREAMBLE",
    "MTData2",
    "MtError",
    "MtStream",
    "checksum_ok",
    "decode_frame",
    "decode_mtdata2",
    "encode_frame",
    "encode_mtdata2",
    "from_imu_sample",
    "quantise",
    "to_imu_sample",
]

MID_GOTO_MEASUREMENT = 0x10  # host → MTi: enter measurement mode
MID_GOTO_MEASUREMENT_ACK = 0x11  # MTi → host: acknowledged
PREAMBLE = 0xFA
BID_MASTER = 0xFF
MID_MTDATA2 = 0x36
SYNC = bytes([PREAMBLE, BID_MASTER])
EXT_LEN = 0xFF  # LEN value announcing a 2-byte extended length
MAX_PAYLOAD = 2048  # largest DATA field the MT0101P allows with the extended length
TICKS_PER_S = 10_000  # SampleTimeFine

XDI_PACKET_COUNTER = 0x1020
XDI_SAMPLE_TIME_FINE = 0x1060
XDI_QUATERNION = 0x2010
XDI_EULER = 0x2030
XDI_ACCELERATION = 0x4020
XDI_RATE_OF_TURN = 0x8020
XDI_STATUS_WORD = 0xE020

FMT_FLOAT32 = 0x0
FMT_FLOAT64 = 0x3
FRAMES = {0x0: "ENU", 0x4: "NED", 0x8: "NWU"}
_FRAME_BITS = {v: k for k, v in FRAMES.items()}


class MtError(ValueError):
    """Bytes that are not a valid Xbus message / MTData2 payload (framing, length, checksum,
    packet sizes, duplicate packets), or a message that cannot be encoded."""


@dataclass(frozen=True)
class MTData2:
    """One MTData2 message; absent outputs are ``None``."""

    packet_counter: int | None = None  #: uint16
    sample_time_fine: int | None = None  #: uint32 ticks of 100 µs (see ``time_s``)
    quaternion: tuple[float, float, float, float] | None = None  #: (w, x, y, z)
    euler_rad: tuple[float, float, float] | None = None  #: roll, pitch, yaw [rad], ZYX
    acceleration: tuple[float, float, float] | None = None  #: [m/s²] specific force
    rate_of_turn: tuple[float, float, float] | None = None  #: [rad/s]
    status_word: int | None = None  #: uint32
    orientation_frame: str = "ENU"  #: frame of quaternion / Euler: ENU, NED or NWU
    float64: bool = False  #: encode floats as float64 (decoded: every float packet was)
    other: tuple[tuple[int, bytes], ...] = ()  #: undecoded packets (XDI, payload), in order

    @property
    def time_s(self) -> float | None:
        """SampleTimeFine in seconds (wraps every 2**32 ticks ≈ 4.97 days)."""
        return None if self.sample_time_fine is None else self.sample_time_fine / TICKS_PER_S


# ------------------------------------------------------------------------------------------
# Xbus framing


def checksum_ok(frame: bytes) -> bool:
    """Independent check: the bytes after the preamble sum to 0 mod 256."""
    return len(frame) >= 5 and sum(frame[1:]) % 256 == 0


def encode_frame(mid: int, data: bytes, bid: int = BID_MASTER) -> bytes:
    """One Xbus message (extended length for more than 254 data bytes)."""
    if not 0 <= mid <= 0xFF or not 0 <= bid <= 0xFF:
        raise MtError(f"MID/BID out of range: {mid}, {bid}")
    n = len(data)
    if n > MAX_PAYLOAD:
        raise MtError(f"{n} data bytes exceed the maximum of {MAX_PAYLOAD}")
    length = bytes([n]) if n < EXT_LEN else bytes([EXT_LEN, n >> 8, n & 0xFF])
    body = bytes([bid, mid]) + length + bytes(data)
    return bytes([PREAMBLE]) + body + bytes([(-sum(body)) & 0xFF])


def _header(buf) -> tuple[int, int] | None:
    """(header size, data length) of the message starting at buf[0], None if incomplete."""
    if len(buf) < 4:
        return None
    if buf[3] != EXT_LEN:
        return 4, buf[3]
    if len(buf) < 6:
        return None
    return 6, (buf[4] << 8) | buf[5]


def decode_frame(frame: bytes) -> tuple[int, int, bytes]:
    """Check framing and checksum of exactly one Xbus message; return (BID, MID, data)."""
    if not isinstance(frame, bytes | bytearray | memoryview):
        raise MtError(f"not a byte string: {type(frame).__name__}")
    frame = bytes(frame)
    if len(frame) < 5:
        raise MtError(f"message too short ({len(frame)} bytes)")
    if frame[0] != PREAMBLE:
        raise MtError("missing preamble 0xFA")
    hdr = _header(frame)
    if hdr is None:
        raise MtError("truncated extended length")
    size, n = hdr
    if size == 6 and (n < EXT_LEN or n > MAX_PAYLOAD):
        raise MtError(f"extended length {n} outside [{EXT_LEN}, {MAX_PAYLOAD}]")
    if len(frame) != size + n + 1:
        raise MtError(f"length field {n} does not match a {len(frame)}-byte message")
    if sum(frame[1:]) & 0xFF:
        raise MtError("checksum mismatch")
    return frame[1], frame[2], frame[size:-1]


# ------------------------------------------------------------------------------------------
# MTData2 payload

_VECTORS = {  # group id -> (field, number of values)
    XDI_QUATERNION: ("quaternion", 4),
    XDI_EULER: ("euler_rad", 3),
    XDI_ACCELERATION: ("acceleration", 3),
    XDI_RATE_OF_TURN: ("rate_of_turn", 3),
}
_ORIENTATION = (XDI_QUATERNION, XDI_EULER)


def _parse_packets(data: bytes) -> list[tuple[int, bytes]]:
    out, i, n = [], 0, len(data)
    while i < n:
        if n - i < 3:
            raise MtError(f"truncated packet header at offset {i}")
        xdi, size = (data[i] << 8) | data[i + 1], data[i + 2]
        if i + 3 + size > n:
            raise MtError(f"packet 0x{xdi:04X} of {size} bytes overruns the message")
        out.append((xdi, data[i + 3 : i + 3 + size]))
        i += 3 + size
    return out


def decode_mtdata2_payload(data: bytes) -> MTData2:
    """The DATA field of an MTData2 message -> :class:`MTData2`."""
    fields: dict = {}
    other: list[tuple[int, bytes]] = []
    seen: set[int] = set()
    frames: set[str] = set()
    precisions: set[int] = set()
    for xdi, payload in _parse_packets(data):
        if xdi in seen:
            raise MtError(f"duplicate packet 0x{xdi:04X}")
        seen.add(xdi)
        group, fmt, frame_bits = xdi & 0xFFF0, xdi & 0x3, xdi & 0xC
        if xdi == XDI_PACKET_COUNTER:
            if len(payload) != 2:
                raise MtError(f"PacketCounter of {len(payload)} bytes")
            key, value = "packet_counter", struct.unpack(">H", payload)[0]
        elif xdi == XDI_SAMPLE_TIME_FINE:
            if len(payload) != 4:
                raise MtError(f"SampleTimeFine of {len(payload)} bytes")
            key, value = "sample_time_fine", struct.unpack(">I", payload)[0]
        elif xdi == XDI_STATUS_WORD:
            if len(payload) != 4:
                raise MtError(f"StatusWord of {len(payload)} bytes")
            key, value = "status_word", struct.unpack(">I", payload)[0]
        elif (
            group in _VECTORS
            and fmt in (FMT_FLOAT32, FMT_FLOAT64)
            and (frame_bits in FRAMES if group in _ORIENTATION else frame_bits == 0)
        ):
            key, count = _VECTORS[group]
            width = 8 if fmt == FMT_FLOAT64 else 4
            if len(payload) != count * width:
                raise MtError(f"packet 0x{xdi:04X} of {len(payload)} bytes, expected {count}")
            value = struct.unpack(f">{count}{'d' if width == 8 else 'f'}", payload)
            if not all(math.isfinite(v) for v in value):
                raise MtError(f"packet 0x{xdi:04X}: non-finite value")
            if key == "euler_rad":
                value = tuple(math.radians(v) for v in value)
            if group in _ORIENTATION:
                frames.add(FRAMES[frame_bits])
            precisions.add(fmt)
        else:
            other.append((xdi, bytes(payload)))
            continue
        if key in fields:  # e.g. 0x4020 and 0x4023 in one message
            raise MtError(f"two packets for {key}")
        fields[key] = value
    if len(frames) > 1:
        raise MtError(f"orientation in several frames: {sorted(frames)}")
    return MTData2(
        **fields,
        orientation_frame=frames.pop() if frames else "ENU",
        float64=precisions == {FMT_FLOAT64},
        other=tuple(other),
    )


def decode_mtdata2(frame: bytes) -> MTData2:
    """Exactly one Xbus MTData2 message (any BID) -> :class:`MTData2`; else :class:`MtError`."""
    _bid, mid, data = decode_frame(frame)
    if mid != MID_MTDATA2:
        raise MtError(f"not an MTData2 message (MID 0x{mid:02X})")
    return decode_mtdata2_payload(data)


def _check_uint(name: str, v, bits: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int | np.integer) or not 0 <= v < 1 << bits:
        raise MtError(f"{name}: not a uint{bits}: {v!r}")
    return int(v)


def _floats(name: str, v, count: int) -> tuple[float, ...]:
    try:
        vals = tuple(float(x) for x in v)
    except (TypeError, ValueError) as e:
        raise MtError(f"{name}: not {count} numbers: {v!r}") from e
    if len(vals) != count or not all(math.isfinite(x) for x in vals):
        raise MtError(f"{name}: not {count} finite numbers: {v!r}")
    return vals


def encode_mtdata2_payload(msg: MTData2) -> bytes:
    if msg.orientation_frame not in _FRAME_BITS:
        raise MtError(f"unknown orientation frame {msg.orientation_frame!r}")
    fmt, code = (FMT_FLOAT64, "d") if msg.float64 else (FMT_FLOAT32, "f")
    out = bytearray()

    def packet(xdi: int, payload: bytes) -> None:
        if len(payload) > 0xFF:
            raise MtError(f"packet 0x{xdi:04X}: {len(payload)} bytes do not fit the size byte")
        out.extend(struct.pack(">HB", xdi, len(payload)) + payload)

    if msg.packet_counter is not None:
        packet(
            XDI_PACKET_COUNTER,
            struct.pack(">H", _check_uint("packet_counter", msg.packet_counter, 16)),
        )
    if msg.sample_time_fine is not None:
        t = _check_uint("sample_time_fine", msg.sample_time_fine, 32)
        packet(XDI_SAMPLE_TIME_FINE, struct.pack(">I", t))
    for group in (XDI_QUATERNION, XDI_EULER, XDI_ACCELERATION, XDI_RATE_OF_TURN):
        key, count = _VECTORS[group]
        v = getattr(msg, key)
        if v is None:
            continue
        vals = _floats(key, v, count)
        if key == "euler_rad":
            vals = tuple(math.degrees(x) for x in vals)
        if not all(math.isfinite(x) for x in vals):
            raise MtError(f"{key}: overflows: {v!r}")
        bits = _FRAME_BITS[msg.orientation_frame] if group in _ORIENTATION else 0
        try:
            payload = struct.pack(f">{count}{code}", *vals)
        except OverflowError as e:
            raise MtError(f"{key}: outside the float32 range: {v!r}") from e
        packet(group | bits | fmt, payload)
    if msg.status_word is not None:
        packet(XDI_STATUS_WORD, struct.pack(">I", _check_uint("status_word", msg.status_word, 32)))
    for xdi, payload in msg.other:
        packet(_check_uint("XDI", xdi, 16), bytes(payload))
    return bytes(out)


def encode_mtdata2(msg: MTData2, bid: int = BID_MASTER) -> bytes:
    """A complete Xbus MTData2 message (preamble to checksum)."""
    return encode_frame(MID_MTDATA2, encode_mtdata2_payload(msg), bid)


def quantise(msg: MTData2) -> MTData2:
    """The message on the encoding grid: ``decode_mtdata2(encode_mtdata2(msg))``."""
    return decode_mtdata2(encode_mtdata2(msg))


# ------------------------------------------------------------------------------------------
# ImuSample conversion


def _euler_to_quaternion(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """(w, x, y, z) of R = Rz(yaw) Ry(pitch) Rx(roll) (the Xsens Euler convention)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ]
    )


def to_imu_sample(msg: MTData2, time: float | None = None) -> ImuSample:
    """:class:`MTData2` -> ``ImuSample``. Needs acceleration, rate of turn and an ENU
    orientation (quaternion, else Euler angles); ``time`` defaults to ``msg.time_s`` (the
    device clock -- pass the host receive time to align with other sensors)."""
    if msg.acceleration is None or msg.rate_of_turn is None:
        raise MtError("ImuSample needs Acceleration and RateOfTurn")
    if msg.orientation_frame != "ENU":
        raise MtError(f"ImuSample orientation is ENU, message has {msg.orientation_frame}")
    if msg.quaternion is not None:
        wxyz = np.asarray(msg.quaternion, float)
    elif msg.euler_rad is not None:
        wxyz = _euler_to_quaternion(*msg.euler_rad)
    else:
        raise MtError("ImuSample needs Quaternion or EulerAngles")
    if time is None:
        if msg.sample_time_fine is None:
            raise MtError("no time: message lacks SampleTimeFine and none was given")
        time = msg.time_s
    return ImuSample(
        time=float(time),
        angular_velocity=np.asarray(msg.rate_of_turn, float),
        linear_acceleration=np.asarray(msg.acceleration, float),
        orientation=np.array([wxyz[1], wxyz[2], wxyz[3], wxyz[0]]),
    )


def from_imu_sample(sample: ImuSample, packet_counter: int = 0) -> MTData2:
    """``ImuSample`` -> :class:`MTData2` as an MTi would send it (counter, SampleTimeFine =
    time rounded to 100 µs modulo 2**32, quaternion, acceleration, rate of turn)."""
    q = np.asarray(sample.orientation, float)
    return MTData2(
        packet_counter=int(packet_counter) & 0xFFFF,
        sample_time_fine=round(float(sample.time) * TICKS_PER_S) % (1 << 32),
        quaternion=(float(q[3]), float(q[0]), float(q[1]), float(q[2])),
        acceleration=tuple(float(v) for v in sample.linear_acceleration),
        rate_of_turn=tuple(float(v) for v in sample.angular_velocity),
    )


# ------------------------------------------------------------------------------------------
# Stream parser


class MtStream:
    """Byte stream (serial/USB) -> MTData2 messages. Resynchronises on 0xFA 0xFF after garbage,
    reassembles messages split across reads, drops candidates with a bad checksum
    (``checksum_errors``) or bad MTData2 contents (``frame_errors``) by discarding only the
    preamble byte (so a real message hidden behind a false 0xFA 0xFF is still found), skips
    valid messages of other MIDs (``other_messages``), and keeps at most ``max_buffer`` bytes.

    Only BID 0xFF (a directly connected MTi) is recognised.
    """

    MAX_MESSAGE = 6 + MAX_PAYLOAD + 1

    def __init__(self, max_buffer: int = 2 * (6 + MAX_PAYLOAD + 1)):
        if max_buffer < self.MAX_MESSAGE:
            raise ValueError(f"max_buffer must be at least {self.MAX_MESSAGE}")
        self.max_buffer = max_buffer
        self._buf = bytearray()
        self.messages = 0
        self.checksum_errors = 0
        self.frame_errors = 0
        self.other_messages = 0
        self.discarded_bytes = 0

    def reset(self) -> None:
        self._buf.clear()

    def _drop(self, n: int) -> None:
        del self._buf[:n]
        self.discarded_bytes += n

    def feed_frames(self, data: bytes) -> list[bytes]:
        """The complete, checksum-valid MTData2 messages (raw bytes) completed by ``data``."""
        self._buf += bytes(data)
        out: list[bytes] = []
        while True:
            buf = self._buf
            i = buf.find(SYNC)
            if i < 0:
                keep = 1 if buf[-1:] == SYNC[:1] else 0  # maybe the first half of a sync
                self._drop(len(buf) - keep)
                break
            if i:
                self._drop(i)
                buf = self._buf
            hdr = _header(buf)
            if hdr is None:
                break
            size, n = hdr
            if size == 6 and not EXT_LEN <= n <= MAX_PAYLOAD:
                self.frame_errors += 1
                self._drop(1)
                continue
            total = size + n + 1
            if len(buf) < total:
                break
            candidate = bytes(buf[:total])
            if sum(candidate[1:]) & 0xFF:
                self.checksum_errors += 1
                self._drop(1)
                continue
            if candidate[2] != MID_MTDATA2:
                self.other_messages += 1
                del self._buf[:total]
                continue
            try:
                decode_mtdata2_payload(candidate[size:-1])
            except MtError:
                self.frame_errors += 1
                self._drop(1)
                continue
            del self._buf[:total]
            self.messages += 1
            out.append(candidate)
        if len(self._buf) > self.max_buffer:
            self._drop(len(self._buf) - self.max_buffer)
        return out

    def feed(self, data: bytes) -> list[MTData2]:
        """The MTData2 messages completed by ``data``, decoded."""
        return [decode_mtdata2(f) for f in self.feed_frames(data)]
