"""NMEA 0183 codec: bytes <-> messages, pure (no I/O).

Decoded sentences: ``GGA`` (fix data), ``RMC`` (recommended minimum) and ``VTG`` (course and
speed over ground), for any talker id (``GP``, ``GN``, ``GL``, ``GA``, ``II``, ``IN`` ...).

* :func:`decode` takes one sentence (``$`` ... ``*hh``, an optional ``\\r\\n`` is ignored) and
  returns a :class:`GGA`, :class:`RMC` or :class:`VTG`; any other sentence type (including
  proprietary ``$P...`` and encapsulated ``!...`` sentences) with a valid checksum returns
  ``None``. A missing or wrong checksum, non-ASCII bytes, a wrong field count for a known type
  or a malformed field raise :class:`NmeaError` (a ``ValueError``) -- never another exception.
  Exception (receiver quirks must not lose fixes): in RMC only the fix fields (time, status,
  position with hemispheres, speed, course) are strict; a malformed date (e.g. after a GPS
  week rollover), a magnetic variation without its hemisphere, or a malformed mode or
  navigational status decode to ``None`` (unknown).
* :func:`encode_gga`, :func:`encode_rmc`, :func:`encode_vtg` (or :func:`encode`) produce a
  complete sentence with checksum and ``\\r\\n``.
* :func:`split_sentences` / :class:`NmeaStream` cut sentences out of an arbitrary byte stream.

Units are SI-ish and explicit in the field names: time of day in seconds since UTC midnight,
latitude/longitude in signed degrees (north/east positive), speeds in m/s (converted from knots
or km/h), courses in degrees, altitudes in metres. Empty fields decode to ``None``.

Encoding precision (the grid on which round trips are exact): time 3 decimals of a second,
latitude/longitude minutes 6 decimals (~2 mm), speeds 3 decimals of a knot / km/h, courses and
magnetic variation 2 decimals of a degree, HDOP 2 decimals, altitude and geoid separation
3 decimals of a metre, age of differential 2 decimals of a second. ``decode(encode(m)) == m``
holds for every message on that grid; :func:`quantise` maps any message onto it
(``quantise(m) == decode(encode(m))``, and it is idempotent).
"""

from __future__ import annotations

import datetime as _dt
import math
import re
from dataclasses import dataclass

__all__ = [
    "GGA",
    "KMH_TO_MPS",
    "KNOT_TO_MPS",
    "RMC",
    "VTG",
    "NmeaError",
    "checksum",
    "decode",
    "encode",
    "encode_gga",
    "encode_rmc",
    "encode_vtg",
    "quantise",
]

KNOT_TO_MPS = 1852.0 / 3600.0
KMH_TO_MPS = 1.0 / 3.6


class NmeaError(ValueError):
    """A sentence that cannot be decoded (checksum, framing, field count or field syntax), or a
    message that cannot be encoded (non-finite or out-of-range values)."""


# --------------------------------------------------------------------------------------------
# Messages
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GGA:
    """Global positioning system fix data."""

    time_of_day_s: float | None = None  #: UTC seconds since midnight
    latitude_deg: float | None = None  #: north positive
    longitude_deg: float | None = None  #: east positive
    fix_quality: int | None = None  #: 0 invalid, 1 GPS, 2 DGPS, 4 RTK fixed, 5 RTK float, ...
    satellites: int | None = None  #: satellites in use
    hdop: float | None = None
    altitude_msl_m: float | None = None  #: antenna altitude above mean sea level (geoid)
    geoid_separation_m: float | None = None  #: geoid height above the WGS-84 ellipsoid
    age_of_differential_s: float | None = None
    station_id: int | None = None  #: differential reference station id (0000-1023)
    talker: str = "GP"


@dataclass(frozen=True)
class RMC:
    """Recommended minimum specific GNSS data."""

    time_of_day_s: float | None = None  #: UTC seconds since midnight
    status: str | None = None  #: "A" valid, "V" navigation receiver warning
    latitude_deg: float | None = None
    longitude_deg: float | None = None
    speed_over_ground_mps: float | None = None  #: from knots
    course_over_ground_deg: float | None = None  #: degrees true
    #: UTC date (two-digit years: 80-99 -> 19xx, 00-79 -> 20xx); None if empty or malformed
    date: _dt.date | None = None
    #: east positive (subtract from true course); None if empty, malformed or without E/W
    magnetic_variation_deg: float | None = None
    mode: str | None = None  #: NMEA 2.3+ mode indicator (A, D, E, F, M, N, P, R, S)
    nav_status: str | None = None  #: NMEA 4.1 navigational status (A, S, C, U, V)
    talker: str = "GP"

    @property
    def valid(self) -> bool:
        return self.status == "A"


@dataclass(frozen=True)
class VTG:
    """Course over ground and ground speed."""

    course_true_deg: float | None = None
    course_magnetic_deg: float | None = None
    speed_mps_from_knots: float | None = None
    speed_mps_from_kmh: float | None = None
    mode: str | None = None  #: NMEA 2.3+ mode indicator
    talker: str = "GP"


Message = GGA | RMC | VTG

# --------------------------------------------------------------------------------------------
# Checksum and framing
# --------------------------------------------------------------------------------------------


def checksum(body: bytes | str) -> int:
    """XOR of the characters between ``$`` (or ``!``) and ``*``."""
    if isinstance(body, str):
        body = body.encode("ascii")
    c = 0
    for b in body:
        c ^= b
    return c


_HEX = b"0123456789ABCDEFabcdef"
_ADDRESS = re.compile(r"(?:[A-Z0-9]{2}(GGA|RMC|VTG)|[A-Z0-9]{2,})\Z")


def _body_fields(sentence: bytes | str) -> tuple[str, list[str]]:
    """Checks framing and checksum; returns (address, data fields)."""
    if isinstance(sentence, str):
        try:
            sentence = sentence.encode("ascii")
        except UnicodeEncodeError:
            raise NmeaError("non-ASCII character in sentence") from None
    if not isinstance(sentence, bytes | bytearray | memoryview):
        raise NmeaError(f"expected bytes or str, got {type(sentence).__name__}")
    s = bytes(sentence)
    while s[-1:] in (b"\n", b"\r"):
        s = s[:-1]
    if len(s) < 1 or s[0] not in b"$!":
        raise NmeaError("sentence does not start with '$' or '!'")
    star = s.rfind(b"*")
    if star < 0:
        raise NmeaError("missing checksum")
    cs = s[star + 1 :]
    if len(cs) != 2 or cs[0] not in _HEX or cs[1] not in _HEX:
        raise NmeaError(f"malformed checksum field {cs!r}")
    body = s[1:star]
    for b in body:
        if b < 0x20 or b > 0x7E or b in b"$!*":
            raise NmeaError(f"invalid character {b:#04x} in sentence")
    if checksum(body) != int(cs, 16):
        raise NmeaError(f"checksum mismatch: computed {checksum(body):02X}, sentence says {cs!r}")
    fields = body.decode("ascii").split(",")
    return fields[0], fields[1:]


# --------------------------------------------------------------------------------------------
# Field parsers (strict: regex first, so float() never sees 'nan', 'inf', '1_0', ' 1' ...)
# --------------------------------------------------------------------------------------------

_NUM = re.compile(r"[+-]?(?:\d+(?:\.\d*)?|\.\d+)\Z")
_UINT = re.compile(r"\d+\Z")
_TIME = re.compile(r"(\d\d)(\d\d)(\d\d(?:\.\d*)?)\Z")
_LAT = re.compile(r"(\d\d)(\d\d(?:\.\d*)?)\Z")
_LON = re.compile(r"(\d\d\d)(\d\d(?:\.\d*)?)\Z")
_DATE = re.compile(r"(\d\d)(\d\d)(\d\d)\Z")
_LETTER = re.compile(r"[A-Z]\Z")


def _parsed(f: str, name: str, pattern: re.Pattern, convert, what: str):
    """None for an empty field, else ``convert(f)`` once ``pattern`` matches (NmeaError if not)."""
    if f == "":
        return None
    if not pattern.match(f):
        raise NmeaError(f"{name}: not {what}: {f!r}")
    return convert(f)


def _num(f: str, name: str) -> float | None:
    return _parsed(f, name, _NUM, float, "a number")


def _uint(f: str, name: str) -> int | None:
    return _parsed(f, name, _UINT, int, "an unsigned integer")


def _scaled(f: str, name: str, scale: float) -> float | None:
    v = _num(f, name)
    return None if v is None else v * scale


def _time(f: str) -> float | None:
    if f == "":
        return None
    m = _TIME.match(f)
    if not m:
        raise NmeaError(f"time: malformed {f!r}")
    hh, mm, ss = int(m[1]), int(m[2]), float(m[3])
    if hh > 23 or mm > 59 or ss >= 61.0 or (ss >= 60.0 and (hh, mm) != (23, 59)):
        raise NmeaError(f"time: out of range {f!r}")
    return hh * 3600 + mm * 60 + ss


def _angle(f: str, hemi: str, lat: bool) -> float | None:
    name = "latitude" if lat else "longitude"
    if f == "" and hemi == "":
        return None
    m = (_LAT if lat else _LON).match(f)
    if not m:
        raise NmeaError(f"{name}: malformed {f!r}")
    deg, minutes = int(m[1]), float(m[2])
    if minutes >= 60.0:
        raise NmeaError(f"{name}: minutes out of range {f!r}")
    v = deg + minutes / 60.0
    if v > (90.0 if lat else 180.0):
        raise NmeaError(f"{name}: out of range {f!r}")
    if hemi == ("N" if lat else "E"):
        return v
    if hemi == ("S" if lat else "W"):
        return -v
    raise NmeaError(f"{name}: bad hemisphere {hemi!r}")


def _letter(f: str, name: str, allowed: str | None = None) -> str | None:
    if f == "":
        return None
    if not _LETTER.match(f) or (allowed is not None and f not in allowed):
        raise NmeaError(f"{name}: unexpected {f!r}")
    return f


def _unit(f: str, expected: str, name: str) -> None:
    if f not in ("", expected):
        raise NmeaError(f"{name}: unit {f!r}, expected {expected!r}")


def _date(f: str) -> _dt.date | None:
    if f == "":
        return None
    m = _DATE.match(f)
    if not m:
        raise NmeaError(f"date: malformed {f!r}")
    day, month, yy = int(m[1]), int(m[2]), int(m[3])
    try:
        return _dt.date(2000 + yy if yy < 80 else 1900 + yy, month, day)
    except ValueError:
        raise NmeaError(f"date: invalid {f!r}") from None


# --------------------------------------------------------------------------------------------
# Decoding
# --------------------------------------------------------------------------------------------


def _decode_gga(talker: str, f: list[str]) -> GGA:
    if len(f) != 14:
        raise NmeaError(f"GGA: expected 14 fields, got {len(f)}")
    _unit(f[9], "M", "GGA altitude")
    _unit(f[11], "M", "GGA geoid separation")
    return GGA(
        time_of_day_s=_time(f[0]),
        latitude_deg=_angle(f[1], f[2], lat=True),
        longitude_deg=_angle(f[3], f[4], lat=False),
        fix_quality=_uint(f[5], "GGA fix quality"),
        satellites=_uint(f[6], "GGA satellites"),
        hdop=_num(f[7], "GGA hdop"),
        altitude_msl_m=_num(f[8], "GGA altitude"),
        geoid_separation_m=_num(f[10], "GGA geoid separation"),
        age_of_differential_s=_num(f[12], "GGA age of differential"),
        station_id=_uint(f[13], "GGA station id"),
        talker=talker,
    )


def _decode_rmc(talker: str, f: list[str]) -> RMC:
    if len(f) not in (11, 12, 13):
        raise NmeaError(f"RMC: expected 11 to 13 fields, got {len(f)}")
    # Strict about the fields a fix needs; lenient about the rest (real receivers send a GPS
    # week-rollover date such as "2208-1", a variation without its hemisphere, ...): a malformed
    # date, magnetic variation, mode or navigational status decodes to None (unknown).
    time_of_day_s = _time(f[0])
    status = _letter(f[1], "RMC status", "AV")
    latitude_deg = _angle(f[2], f[3], lat=True)
    longitude_deg = _angle(f[4], f[5], lat=False)
    speed = _scaled(f[6], "RMC speed", KNOT_TO_MPS)
    course = _num(f[7], "RMC course")
    var = _lenient(_num, f[9], "RMC magnetic variation")
    if var is not None and f[10] in ("E", "W"):
        var = var if f[10] == "E" else -var
    else:
        var = None
    return RMC(
        time_of_day_s=time_of_day_s,
        status=status,
        latitude_deg=latitude_deg,
        longitude_deg=longitude_deg,
        speed_over_ground_mps=speed,
        course_over_ground_deg=course,
        date=_lenient(_date, f[8]),
        magnetic_variation_deg=var,
        mode=_lenient(_letter, f[11], "RMC mode") if len(f) > 11 else None,
        nav_status=_lenient(_letter, f[12], "RMC nav status") if len(f) > 12 else None,
        talker=talker,
    )


def _lenient(parse, *args):
    """``parse(*args)``, or None where the field is malformed."""
    try:
        return parse(*args)
    except NmeaError:
        return None


def _decode_vtg(talker: str, f: list[str]) -> VTG:
    if len(f) not in (8, 9):
        raise NmeaError(f"VTG: expected 8 or 9 fields, got {len(f)}")
    for i, u in zip((1, 3, 5, 7), "TMNK", strict=True):
        _unit(f[i], u, "VTG")
    return VTG(
        course_true_deg=_num(f[0], "VTG course true"),
        course_magnetic_deg=_num(f[2], "VTG course magnetic"),
        speed_mps_from_knots=_scaled(f[4], "VTG speed knots", KNOT_TO_MPS),
        speed_mps_from_kmh=_scaled(f[6], "VTG speed km/h", KMH_TO_MPS),
        mode=_letter(f[8], "VTG mode") if len(f) > 8 else None,
        talker=talker,
    )


_DECODERS = {"GGA": _decode_gga, "RMC": _decode_rmc, "VTG": _decode_vtg}


def decode(sentence: bytes | str) -> GGA | RMC | VTG | None:
    """Decodes one sentence; ``None`` for valid sentences of other types; else NmeaError."""
    address, fields = _body_fields(sentence)
    m = _ADDRESS.match(address)
    if not m:
        raise NmeaError(f"malformed address field {address!r}")
    if m[1] is None:
        return None
    return _DECODERS[m[1]](address[:2], fields)


# --------------------------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------------------------


def _finite(v: float, name: str) -> float:
    if not isinstance(v, int | float) or isinstance(v, bool) or not math.isfinite(v):
        raise NmeaError(f"{name}: not a finite number: {v!r}")
    return float(v)


def _fmt(v: float | None, decimals: int, name: str, scale: float = 1.0) -> str:
    if v is None:
        return ""
    s = f"{_finite(v, name) / scale:.{decimals}f}"
    if s.startswith("-") and s.strip("-0.") == "":
        s = s[1:]  # no "-0.000"
    return s


def _fmt_uint(v: int | None, width: int, name: str) -> str:
    if v is None:
        return ""
    if not isinstance(v, int) or isinstance(v, bool) or v < 0:
        raise NmeaError(f"{name}: not a non-negative integer: {v!r}")
    return f"{v:0{width}d}"


def _fmt_time(t: float | None) -> str:
    if t is None:
        return ""
    ms = round(_finite(t, "time") * 1000)
    if not 0 <= ms < 86_401_000:
        raise NmeaError(f"time of day out of range: {t!r}")
    if ms >= 86_400_000:  # leap second 23:59:60.xxx
        hh, mm, sms = 23, 59, ms - 86_340_000
    else:
        hh, rem = divmod(ms, 3_600_000)
        mm, sms = divmod(rem, 60_000)
    return f"{hh:02d}{mm:02d}{sms // 1000:02d}.{sms % 1000:03d}"


def _fmt_angle(v: float | None, lat: bool) -> tuple[str, str]:
    if v is None:
        return "", ""
    name = "latitude" if lat else "longitude"
    v = _finite(v, name)
    micro_min = round(abs(v) * 60_000_000)  # minutes with 6 decimals, as an integer
    if micro_min > (90 if lat else 180) * 60_000_000:
        raise NmeaError(f"{name} out of range: {v!r}")
    deg, rem = divmod(micro_min, 60_000_000)
    hemi = ("N" if lat else "E") if v >= 0 or micro_min == 0 else ("S" if lat else "W")
    width = 2 if lat else 3
    return f"{deg:0{width}d}{rem // 1_000_000:02d}.{rem % 1_000_000:06d}", hemi


def _fmt_letter(v: str | None, name: str, allowed: str | None = None) -> str:
    if v is None:
        return ""
    if not isinstance(v, str) or not _LETTER.match(v) or (allowed and v not in allowed):
        raise NmeaError(f"{name}: not a single capital letter: {v!r}")
    return v


def _fmt_date(d: _dt.date | None) -> str:
    if d is None:
        return ""
    if not isinstance(d, _dt.date) or not 1980 <= d.year <= 2079:
        raise NmeaError(f"date not representable with a two-digit year: {d!r}")
    return f"{d.day:02d}{d.month:02d}{d.year % 100:02d}"


def _sentence(talker: str, kind: str, fields: list[str]) -> bytes:
    if not isinstance(talker, str) or not re.fullmatch(r"[A-Z0-9]{2}", talker):
        raise NmeaError(f"talker id must be two capitals/digits: {talker!r}")
    body = ",".join([talker + kind, *fields]).encode("ascii")
    return b"$%s*%02X\r\n" % (body, checksum(body))


def encode_gga(msg: GGA) -> bytes:
    lat, ns = _fmt_angle(msg.latitude_deg, lat=True)
    lon, ew = _fmt_angle(msg.longitude_deg, lat=False)
    return _sentence(
        msg.talker,
        "GGA",
        [
            _fmt_time(msg.time_of_day_s),
            lat,
            ns,
            lon,
            ew,
            _fmt_uint(msg.fix_quality, 1, "fix quality"),
            _fmt_uint(msg.satellites, 2, "satellites"),
            _fmt(msg.hdop, 2, "hdop"),
            _fmt(msg.altitude_msl_m, 3, "altitude"),
            "M",
            _fmt(msg.geoid_separation_m, 3, "geoid separation"),
            "M",
            _fmt(msg.age_of_differential_s, 2, "age of differential"),
            _fmt_uint(msg.station_id, 4, "station id"),
        ],
    )


def encode_rmc(msg: RMC) -> bytes:
    lat, ns = _fmt_angle(msg.latitude_deg, lat=True)
    lon, ew = _fmt_angle(msg.longitude_deg, lat=False)
    var = _fmt(msg.magnetic_variation_deg, 2, "magnetic variation")
    var_dir = ""
    if var:
        var_dir = "W" if var.startswith("-") else "E"
        var = var.lstrip("-")
    fields = [
        _fmt_time(msg.time_of_day_s),
        _fmt_letter(msg.status, "status", "AV"),
        lat,
        ns,
        lon,
        ew,
        _fmt(msg.speed_over_ground_mps, 3, "speed", KNOT_TO_MPS),
        _fmt(msg.course_over_ground_deg, 2, "course"),
        _fmt_date(msg.date),
        var,
        var_dir,
    ]
    if msg.mode is not None or msg.nav_status is not None:
        fields.append(_fmt_letter(msg.mode, "mode"))
    if msg.nav_status is not None:
        fields.append(_fmt_letter(msg.nav_status, "navigational status"))
    return _sentence(msg.talker, "RMC", fields)


def encode_vtg(msg: VTG) -> bytes:
    fields = [
        _fmt(msg.course_true_deg, 2, "course true"),
        "T",
        _fmt(msg.course_magnetic_deg, 2, "course magnetic"),
        "M",
        _fmt(msg.speed_mps_from_knots, 3, "speed knots", KNOT_TO_MPS),
        "N",
        _fmt(msg.speed_mps_from_kmh, 3, "speed km/h", KMH_TO_MPS),
        "K",
    ]
    if msg.mode is not None:
        fields.append(_fmt_letter(msg.mode, "mode"))
    return _sentence(msg.talker, "VTG", fields)


def encode(msg: GGA | RMC | VTG) -> bytes:
    if isinstance(msg, GGA):
        return encode_gga(msg)
    if isinstance(msg, RMC):
        return encode_rmc(msg)
    if isinstance(msg, VTG):
        return encode_vtg(msg)
    raise NmeaError(f"cannot encode {type(msg).__name__}")


def quantise(msg: GGA | RMC | VTG) -> GGA | RMC | VTG:
    """The message rounded to the encoding precision: ``decode(encode(msg))``."""
    out = decode(encode(msg))
    assert out is not None
    return out
