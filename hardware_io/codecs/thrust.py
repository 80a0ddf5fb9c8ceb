"""Host ⇄ thruster microcontroller protocol (STM32 in Roboat II, Arduino in Ueland 2017): pure
codec, no I/O.

Frame (all multi-byte fields little-endian; full byte tables in ``hardware_io/PROTOCOL.md``)::

    off  size  field
    0    2     sync 0xAA 0x55
    2    1     version (1)
    3    1     type: 0x01 command (host → MCU), 0x81 telemetry (MCU → host)
    4    1     payload length L [bytes]
    5    2     sequence number uint16 (wraps 65535 → 0)
    7    L     payload
    7+L  2     CRC-16/CCITT-FALSE over bytes 2 .. 6+L (everything after the sync)

Command payload:   n uint8 | flags uint8 (bit0: angles present) |
                   n × (pwm uint16 [µs] [, angle int16 [centi-degrees]])
Telemetry payload: n uint8 | flags uint8 (bit0: rpm present, bit1: pwm present) |
                   status uint8 | battery uint16 [mV] | n × ([rpm int16] [, pwm uint16 [µs]])

Every decoding error is a :class:`FrameError` (a ``ValueError``); nothing else is raised and no
frame whose CRC does not match is ever returned.
"""

from __future__ import annotations

import binascii
import enum
import struct
from dataclasses import dataclass

SYNC = b"\xaa\x55"
VERSION = 1
TYPE_COMMAND = 0x01
TYPE_TELEMETRY = 0x81
HEADER_SIZE = 7  # sync, version, type, length, seq
CRC_SIZE = 2
MAX_CHANNELS = 16
MAX_PAYLOAD = 5 + 4 * MAX_CHANNELS  # 69: the largest telemetry payload
MAX_FRAME = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE  # 78

CMD_FLAG_ANGLES = 0x01
TLM_FLAG_RPM = 0x01
TLM_FLAG_PWM = 0x02

# MCU commands 1500 µs on every channel after 150 ms without a valid command frame: 6 lost
# frames at the host's 50 Hz keep-alive; neutral within 150 ms + one firmware tick (≤ 10 ms)
# of the last frame, i.e. within 200 ms of a cut link (PROTOCOL.md, "Sequence numbers and the
# watchdog").
WATCHDOG_TIMEOUT_S = 0.150


class FrameError(ValueError):
    """A byte string is not a valid frame of this protocol (bad framing, length, CRC, field)."""


class Status(enum.IntFlag):
    """Telemetry status byte (bits 3-7 reserved, sent as 0, kept if set)."""

    WATCHDOG_TRIPPED = 0x01  # no valid command for 150 ms: all channels at 1500 µs
    ESC_FAULT = 0x02  # an ESC reported a fault / an RPM sensor reads 0 while commanded
    UNDERVOLTAGE = 0x04  # battery below the firmware's threshold


@dataclass(frozen=True)
class ThrustCommand:
    seq: int  # uint16
    pwm_us: tuple[int, ...]  # per channel, uint16 [µs]
    angles_cdeg: tuple[int, ...] | None = None  # per channel, int16 [0.01 deg], or absent


@dataclass(frozen=True)
class Telemetry:
    seq: int  # uint16: sequence number of the last valid command frame received
    status: Status
    battery_mv: int  # uint16 [mV]
    rpm: tuple[int, ...] | None = None  # per channel, int16 [rev/min], signed by direction
    pwm_us: tuple[int, ...] | None = None  # per channel, uint16 [µs] as output by the MCU


# ------------------------------------------------------------------------------------------
# CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, xorout 0; check("123456789")
# = 0x29B1.


def crc16_ccitt_false(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no final XOR): the
    standard library's CRC-CCITT (``binascii.crc_hqx``) started from 0xFFFF."""
    return binascii.crc_hqx(data, crc)


# ------------------------------------------------------------------------------------------
# Encoding


def _check_int(name: str, v, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        try:
            iv = int(v)
        except (TypeError, ValueError, OverflowError) as e:
            raise ValueError(f"{name}: not an integer: {v!r}") from e
        if iv != v:
            raise ValueError(f"{name}: not an integer: {v!r}")
        v = iv
    if not lo <= v <= hi:
        raise ValueError(f"{name} = {v} outside [{lo}, {hi}]")
    return v


def _frame(msg_type: int, seq: int, payload: bytes) -> bytes:
    seq = _check_int("seq", seq, 0, 0xFFFF)
    body = struct.pack("<BBBH", VERSION, msg_type, len(payload), seq) + payload
    return SYNC + body + struct.pack("<H", crc16_ccitt_false(body))


def _check_n(n: int) -> None:
    if not 1 <= n <= MAX_CHANNELS:
        raise ValueError(f"number of channels {n} outside [1, {MAX_CHANNELS}]")


def encode_command(seq: int, pwm_us, angles_cdeg=None) -> bytes:
    """Command frame: PWM [µs] per channel, optionally an angle [centi-degrees] per channel."""
    pwm = [_check_int("pwm_us", p, 0, 0xFFFF) for p in pwm_us]
    _check_n(len(pwm))
    flags, fields = 0, []
    if angles_cdeg is None:
        fields = [struct.pack("<H", p) for p in pwm]
    else:
        ang = [_check_int("angles_cdeg", a, -0x8000, 0x7FFF) for a in angles_cdeg]
        if len(ang) != len(pwm):
            raise ValueError(f"{len(ang)} angles for {len(pwm)} channels")
        flags = CMD_FLAG_ANGLES
        fields = [struct.pack("<Hh", p, a) for p, a in zip(pwm, ang, strict=True)]
    return _frame(TYPE_COMMAND, seq, bytes([len(pwm), flags]) + b"".join(fields))


def encode_telemetry(seq: int, status, battery_mv: int, rpm=None, pwm_us=None) -> bytes:
    """Telemetry frame: status bits, battery [mV], per channel RPM and/or measured PWM [µs]."""
    status = _check_int("status", int(status), 0, 0xFF)
    battery_mv = _check_int("battery_mv", battery_mv, 0, 0xFFFF)
    if rpm is None and pwm_us is None:
        raise ValueError("telemetry needs rpm and/or pwm_us")
    r = None if rpm is None else [_check_int("rpm", v, -0x8000, 0x7FFF) for v in rpm]
    p = None if pwm_us is None else [_check_int("pwm_us", v, 0, 0xFFFF) for v in pwm_us]
    if r is not None and p is not None and len(r) != len(p):
        raise ValueError(f"{len(r)} rpm values for {len(p)} pwm values")
    n = len(r if r is not None else p)
    _check_n(n)
    flags = (TLM_FLAG_RPM if r is not None else 0) | (TLM_FLAG_PWM if p is not None else 0)
    out = bytearray(struct.pack("<BBBH", n, flags, status, battery_mv))
    for i in range(n):
        if r is not None:
            out += struct.pack("<h", r[i])
        if p is not None:
            out += struct.pack("<H", p[i])
    return _frame(TYPE_TELEMETRY, seq, bytes(out))


# ------------------------------------------------------------------------------------------
# Decoding


def _split(frame: bytes) -> tuple[int, int, bytes]:
    """Check framing and CRC of exactly one frame; return (type, seq, payload)."""
    if not isinstance(frame, (bytes, bytearray, memoryview)):
        raise FrameError(f"not a byte string: {type(frame).__name__}")
    frame = bytes(frame)
    if len(frame) < HEADER_SIZE + CRC_SIZE:
        raise FrameError(f"frame too short ({len(frame)} bytes)")
    if frame[:2] != SYNC:
        raise FrameError("missing sync bytes 0xAA 0x55")
    version, msg_type, length = frame[2], frame[3], frame[4]
    if version != VERSION:
        raise FrameError(f"unsupported protocol version {version}")
    if len(frame) != HEADER_SIZE + length + CRC_SIZE:
        raise FrameError(f"length field {length} does not match a {len(frame)}-byte frame")
    body = frame[2:-CRC_SIZE]
    crc = frame[-2] | (frame[-1] << 8)
    if crc16_ccitt_false(body) != crc:
        raise FrameError("CRC mismatch")
    seq = frame[5] | (frame[6] << 8)
    return msg_type, seq, frame[HEADER_SIZE:-CRC_SIZE]


def _decode_command_payload(seq: int, payload: bytes) -> ThrustCommand:
    if len(payload) < 2:
        raise FrameError("command payload too short")
    n, flags = payload[0], payload[1]
    if not 1 <= n <= MAX_CHANNELS:
        raise FrameError(f"number of channels {n} outside [1, {MAX_CHANNELS}]")
    if flags & ~CMD_FLAG_ANGLES:
        raise FrameError(f"unknown command flags 0x{flags:02x}")
    angles = bool(flags & CMD_FLAG_ANGLES)
    size = 4 if angles else 2
    if len(payload) != 2 + n * size:
        raise FrameError(f"command payload of {len(payload)} bytes for {n} channels")
    if angles:
        vals = struct.unpack(f"<{'Hh' * n}", payload[2:])
        return ThrustCommand(seq, tuple(vals[0::2]), tuple(vals[1::2]))
    return ThrustCommand(seq, struct.unpack(f"<{n}H", payload[2:]), None)


def _decode_telemetry_payload(seq: int, payload: bytes) -> Telemetry:
    if len(payload) < 5:
        raise FrameError("telemetry payload too short")
    n, flags, status, battery_mv = struct.unpack("<BBBH", payload[:5])
    if not 1 <= n <= MAX_CHANNELS:
        raise FrameError(f"number of channels {n} outside [1, {MAX_CHANNELS}]")
    if flags & ~(TLM_FLAG_RPM | TLM_FLAG_PWM) or not flags:
        raise FrameError(f"invalid telemetry flags 0x{flags:02x}")
    has_rpm, has_pwm = bool(flags & TLM_FLAG_RPM), bool(flags & TLM_FLAG_PWM)
    fmt = ("h" if has_rpm else "") + ("H" if has_pwm else "")
    if len(payload) != 5 + n * 2 * len(fmt):
        raise FrameError(f"telemetry payload of {len(payload)} bytes for {n} channels")
    vals = struct.unpack("<" + fmt * n, payload[5:])
    k = len(fmt)
    rpm = tuple(vals[0::k]) if has_rpm else None
    pwm = tuple(vals[k - 1 :: k]) if has_pwm else None
    return Telemetry(seq, Status(status), battery_mv, rpm, pwm)


def decode_frame(frame: bytes) -> ThrustCommand | Telemetry:
    """Decode exactly one frame of either type; raises :class:`FrameError` otherwise."""
    msg_type, seq, payload = _split(frame)
    if msg_type == TYPE_COMMAND:
        return _decode_command_payload(seq, payload)
    if msg_type == TYPE_TELEMETRY:
        return _decode_telemetry_payload(seq, payload)
    raise FrameError(f"unknown message type 0x{msg_type:02x}")


def decode_command(frame: bytes) -> ThrustCommand:
    msg = decode_frame(frame)
    if not isinstance(msg, ThrustCommand):
        raise FrameError("not a command frame")
    return msg


def decode_telemetry(frame: bytes) -> Telemetry:
    msg = decode_frame(frame)
    if not isinstance(msg, Telemetry):
        raise FrameError("not a telemetry frame")
    return msg


# ------------------------------------------------------------------------------------------
# Stream parser


class FrameParser:
    """Byte stream → frames. Resynchronises on 0xAA 0x55 after garbage, reassembles frames
    split across reads, drops frames with a bad CRC (``crc_errors``) or bad contents
    (``frame_errors``), and keeps at most ``max_buffer`` bytes (oldest dropped first).

    On a CRC mismatch only the first sync byte is discarded, so a real frame hidden behind a
    false sync (e.g. 0xAA 0x55 inside a payload of a lost frame) is still found.
    """

    def __init__(self, max_buffer: int = 4 * MAX_FRAME):
        if max_buffer < MAX_FRAME:
            raise ValueError(f"max_buffer must be at least {MAX_FRAME}")
        self.max_buffer = max_buffer
        self._buf = bytearray()
        self.frames = 0  # valid frames returned
        self.crc_errors = 0  # complete candidate frames whose CRC did not match
        self.frame_errors = 0  # bad header (version, length) or bad contents with a good CRC
        self.discarded_bytes = 0  # bytes skipped while hunting for sync or dropped on overflow

    def reset(self) -> None:
        self._buf.clear()

    def _drop(self, n: int) -> None:
        del self._buf[:n]
        self.discarded_bytes += n

    def feed(self, data: bytes) -> list[ThrustCommand | Telemetry]:
        self._buf += bytes(data)
        out: list[ThrustCommand | Telemetry] = []
        while True:
            buf = self._buf
            i = buf.find(SYNC)
            if i < 0:
                # keep a trailing 0xAA: it may be the first half of a split sync
                keep = 1 if buf[-1:] == SYNC[:1] else 0
                self._drop(len(buf) - keep)
                break
            if i:
                self._drop(i)
                buf = self._buf
            if len(buf) < HEADER_SIZE:
                break
            version, msg_type, length = buf[2], buf[3], buf[4]
            if (
                version != VERSION
                or msg_type not in (TYPE_COMMAND, TYPE_TELEMETRY)
                or length > MAX_PAYLOAD
            ):
                self.frame_errors += 1
                self._drop(1)
                continue
            total = HEADER_SIZE + length + CRC_SIZE
            if len(buf) < total:
                break
            candidate = bytes(buf[:total])
            crc = candidate[-2] | (candidate[-1] << 8)
            if crc16_ccitt_false(candidate[2:-2]) != crc:
                self.crc_errors += 1
                self._drop(1)
                continue
            try:
                msg = decode_frame(candidate)
            except FrameError:
                self.frame_errors += 1
                self._drop(1)
                continue
            del self._buf[:total]
            self.frames += 1
            out.append(msg)
        if len(self._buf) > self.max_buffer:
            self._drop(len(self._buf) - self.max_buffer)
        return out
