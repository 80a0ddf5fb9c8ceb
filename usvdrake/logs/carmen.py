"""Reader of CARMEN laser logs (old-style text), the classic 2D SLAM benchmarks.

The Freiburg / Radish logs (intel, aces, fr079, mit-csail; Kümmerle et al. 2009, "On measuring
the accuracy of SLAM algorithms") are one message per line::

    ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp
    FLASER n r1 … rn x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp

in metres, radians and seconds. FLASER carries no angles: its n beams span 180° from −90°
(n = 180 → 1° steps; n = 360 or 361 → 0.5°). x y θ is the laser's pose, odom_* the robot's
odometry (equal in intel; fr079's laser sits 0.04 m ahead). Readings at or above ``max_range``
(50 m by default: aces reports no-return as 50.00, the others as ~81.9) are no-returns:
``ranges = inf`` and ``valid = False``, the :class:`LaserScan` convention. The "corrected" logs
have the same FLASER lines with SLAM-corrected poses, used as approximate ground truth.

Files may be plain, bzip2 or gzip; the compression is recognised by its magic bytes.

Damage (:class:`~usvdrake.logs.damage.ReadDamage`): a FLASER line that does not parse (cut
short, a digit flipped into a letter, non-finite poses) and a line that is no CARMEN message at
all (binary bytes, no message name) are skipped and counted; a compressed stream that breaks off
(a truncated or corrupt ``.bz2`` / ``.gz``) keeps every line decoded before the break and
counts the rest as one skip of the compressed bytes left unread. A file whose first bytes are
not text is refused (:class:`ConfigError`).
"""

import bisect
import bz2
import gzip
import io
import re
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np

from usvdrake.errors import ConfigError
from usvdrake.logs.damage import ReadDamage, count_into
from usvdrake.sensors.messages import LaserScan

FOV = np.pi  # [rad] FLASER field of view, first beam at −FOV/2
# a CARMEN line: a comment, or a message name (ODOM, FLASER, PARAM, ROBOTLASER1, …) and fields
_MESSAGE_LINE = re.compile(r"(#|[A-Z][A-Z0-9_]*(\s|$))")
# bytes a text log never holds (control characters but tab, newline and carriage return, and
# what ASCII decoding replaced)
_NOT_TEXT = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\x7f\ufffd]")
# what a broken bzip2 / gzip stream raises while it is read: corrupt data (OSError, zlib.error),
# a stream that ends too soon (EOFError)
STREAM_ERRORS = (OSError, EOFError, zlib.error)


class CarmenScan(NamedTuple):
    timestamp: float  # [s] ipc timestamp (Unix epoch for intel and mit-csail, relative for others)
    scan: LaserScan  # the front laser's scan
    odometry_pose: np.ndarray  # (x [m], y [m], θ [rad]) of the pose chosen by ``pose=``


def open_log(path: str | Path) -> io.TextIOBase:
    """Open a log as text, decompressing bzip2 (``BZh``) or gzip (``1f 8b``) by magic bytes."""
    with open(path, "rb") as f:
        magic = f.read(3)
    if magic == b"BZh":
        return bz2.open(path, "rt", encoding="ascii", errors="replace")
    if magic[:2] == b"\x1f\x8b":
        return gzip.open(path, "rt", encoding="ascii", errors="replace")
    return open(path, encoding="ascii", errors="replace")


def _decompressed(raw) -> io.BufferedIOBase:
    """``raw`` (a binary file), decompressed as its magic bytes say (it stays open after)."""
    magic = raw.read(3)
    raw.seek(0)
    if magic == b"BZh":
        return bz2.BZ2File(raw)
    if magic[:2] == b"\x1f\x8b":
        return gzip.GzipFile(fileobj=raw)
    return raw


def beam_increment(n: int) -> float:
    """Angle between FLASER beams [rad]: 180° over n beams, or over n − 1 when n is odd (361)."""
    return FOV / (n - n % 2)


def parse_flaser(tokens: list[str], pose: str = "odometry", max_range: float = 50.0) -> CarmenScan:
    """One FLASER line, split on whitespace, as a :class:`CarmenScan`.

    pose: ``"odometry"`` (odom_x odom_y odom_theta) or ``"laser"`` (x y theta — in corrected
    logs, the corrected pose); max_range [m]: readings ≥ it are no-returns.
    """
    n = int(tokens[1])
    if n < 2 or len(tokens) < 9 + n:  # a scan needs beams and its pose and time fields
        raise ValueError(f"FLASER line with {n} beams and {len(tokens)} fields")
    r = np.array(tokens[2 : 2 + n], dtype=float)
    p = np.array(tokens[2 + n : 8 + n], dtype=float)
    timestamp = float(tokens[8 + n])
    if not (np.isfinite(p).all() and np.isfinite(timestamp)):  # a corrupt line, not a scan
        raise ValueError("FLASER line with a non-finite pose or time")
    valid = (r > 0.0) & (r < max_range)
    scan = LaserScan(
        time=timestamp,
        angle_min=-FOV / 2,
        angle_increment=beam_increment(n),
        range_min=0.0,
        range_max=max_range,
        ranges=np.where(valid, r, np.inf),
        valid=valid,
    )
    if pose == "odometry":
        chosen = p[3:6]
    elif pose == "laser":
        chosen = p[0:3]
    else:
        raise ValueError(f"pose must be 'odometry' or 'laser', got {pose!r}")
    return CarmenScan(timestamp=timestamp, scan=scan, odometry_pose=chosen)


def read_carmen(
    path: str | Path,
    pose: str = "odometry",
    max_range: float = 50.0,
    damage: ReadDamage | None = None,
    messages: set[str] | None = None,
) -> Iterator[CarmenScan]:
    """Yield ``(timestamp [s], LaserScan, pose (x, y, θ))`` for every FLASER line of a log.

    Scans come in file order: the ipc timestamps of the real logs are not strictly monotone
    (intel: 631 of 13 631 scans step back, by up to 0.9 s). Other messages (ODOM, PARAM, RLASER,
    NEFF, comments) are passed over; malformed lines (a log truncated while recording, a
    corrupt file) and the unreadable rest of a broken compressed stream are skipped and
    counted in ``damage`` (the module's notes). ConfigError if the file is not text.
    ``messages``: a set the names of the messages read are added to (:func:`is_corrected`).
    """
    if pose not in ("odometry", "laser"):
        raise ValueError(f"pose must be 'odometry' or 'laser', got {pose!r}")
    damage = count_into(damage)
    for number, line in _lines(path, damage):
        if not line.startswith("FLASER"):
            if _NOT_TEXT.search(line) or (line.strip() and not _MESSAGE_LINE.match(line)):
                damage.skip(path, number, "not a CARMEN line")
            elif messages is not None and line[:1].isupper():
                messages.add(line.split(maxsplit=1)[0])
            continue
        try:
            yield parse_flaser(line.split(), pose, max_range)
        except (IndexError, ValueError):
            damage.skip(path, number, "malformed FLASER line")


def _lines(path: str | Path, damage: ReadDamage) -> Iterator[tuple[int, str]]:
    """(line number, line) of a log up to where its compressed stream breaks, if it does (the
    rest counted in ``damage``). ConfigError when not even the first line is text."""
    try:
        raw = open(path, "rb")  # closed by the with below
    except OSError as e:
        raise ConfigError(path, "", "a readable CARMEN log", e.strerror or str(e)) from None
    number = 0
    # the raw file's position says how much of a compressed log was read when it broke
    with raw, io.TextIOWrapper(_decompressed(raw), encoding="ascii", errors="replace") as f:
        try:
            for number, line in enumerate(f, 1):
                if number == 1 and _NOT_TEXT.search(line[:256]) and not _MESSAGE_LINE.match(line):
                    raise ConfigError(path, "", "a CARMEN log (text, bzip2 or gzip)", "binary data")
                yield number, line
        except STREAM_ERRORS as e:
            if number == 0:
                raise ConfigError(
                    path, "", "a CARMEN log (text, bzip2 or gzip)", f"a broken stream ({e})"
                ) from None
            unread = max(Path(path).stat().st_size - raw.tell(), 0)
            damage.skip(
                path, "stream", "broken compressed stream (the rest of the file unread)", unread
            )


def is_corrected(messages: set[str]) -> bool:
    """Whether a log whose messages are ``messages`` (:func:`read_carmen`'s) is a "corrected"
    log: its FLASER poses are a SLAM's estimate, not odometry. The corrected logs of Kümmerle
    et al. 2009 carry the scan matcher's NEFF lines (its particles' effective number, one per
    scan); no raw log does."""
    return "NEFF" in messages


def has_odometry(scans) -> bool:
    """Whether a CARMEN log's scans carry odometry: their pose fields move (a log without an
    odometer writes one pose, usually 0 0 0, on every FLASER line)."""
    poses = np.array([rec.odometry_pose for rec in scans], float).reshape(-1, 3)
    return len(poses) > 1 and bool(np.any(np.ptp(poses, axis=0) > 0.0))


def read_poses(path: str | Path, pose: str = "laser") -> tuple[np.ndarray, np.ndarray]:
    """Timestamps (n,) [s] and poses (n × 3) [m, m, rad] of every scan of a log — with the
    default ``pose="laser"`` on a corrected log, the ground-truth trajectory."""
    stamps, poses = [], []
    for t, _, p in read_carmen(path, pose=pose):
        stamps.append(t)
        poses.append(p)
    return np.array(stamps, dtype=float), np.array(poses, dtype=float).reshape(-1, 3)


def read_odometry(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Timestamps (n,) [s] and odometry poses (n × 3) of the ODOM lines (none in mit-csail)."""
    stamps, poses = [], []
    for _, line in _lines(path, ReadDamage()):
        if line.startswith("ODOM"):
            try:
                tokens = line.split()
                pose, stamp = [float(v) for v in tokens[1:4]], float(tokens[7])
            except (IndexError, ValueError):
                continue  # cut short or corrupt
            poses.append(pose)
            stamps.append(stamp)
    return np.array(stamps, dtype=float), np.array(poses, dtype=float).reshape(-1, 3)


def associate_scans(scans, reference) -> np.ndarray:
    """For each record of ``reference`` (a corrected log's), the index of the record in
    ``scans`` (the raw log's) with the same ranges to 1 cm, or −1. A corrected log's scans are
    a subset of its raw log's, re-stamped (its stamps start near 0): the ranges name a scan
    where the time does not. Matches advance in log order, so a scan repeated exactly (a robot
    at rest) pairs with its first copy after the previous match."""

    def key(rec) -> bytes:
        r = np.asarray(rec.scan.ranges, float)
        return np.round(np.where(np.isfinite(r), r, -1.0) * 100.0).astype(np.int64).tobytes()

    where: dict[bytes, list[int]] = {}
    for i, rec in enumerate(scans):
        where.setdefault(key(rec), []).append(i)
    out = np.full(len(reference), -1, dtype=int)
    last = -1
    for k, rec in enumerate(reference):
        found = where.get(key(rec), [])
        j = bisect.bisect_right(found, last)
        if j < len(found):
            out[k] = last = found[j]
    return out
