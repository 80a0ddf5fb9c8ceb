"""Reading mission logs, finished or cut off by a crash: :func:`read_mission_log` streams the
MCAP records up to the last complete one and decodes each message by its channel's schema and
encoding (current and earlier encodings), skipping and counting what is damaged
(:mod:`~usvdrake.logs.mission_log.records`, ``damage=``); :func:`log_summary` says what a log
holds (topics, counts, times, whether the footer is there) without decoding it;
:func:`read_log_scans`, :func:`read_log_states` and :func:`read_log_vectors` turn topics into
the SLAM runners' scans and arrays."""

import json
import math
import struct
import zlib
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from mcap.records import Channel, Footer, Message, Schema

from usvdrake.logs.damage import ReadDamage, count_into
from usvdrake.logs.mission_log.codecs import decode_cloud, decode_gps, decode_imu, decode_scan
from usvdrake.logs.mission_log.records import iter_records
from usvdrake.logs.mission_log.schema import (
    CLOUD_ENCODING,
    GPS_SCHEMA,
    IMU_SCHEMA,
    NO_FIX_SCHEMA,
    SCAN_ENCODING,
    SCAN_SCHEMA,
    STATE_ENCODING,
    STATE_NAMES,
)
from usvdrake.logs.rosbag import BagScan
from usvdrake.sensors.messages import LaserScan

# what decoding a corrupt message may raise (JSON, UTF-8, zlib, missing or mistyped fields,
# a range image whose size does not match its header)
DECODE_ERRORS = (
    ValueError,
    KeyError,
    TypeError,
    IndexError,
    AttributeError,
    OverflowError,
    zlib.error,
    struct.error,
    MemoryError,
)


# --- reading ----------------------------------------------------------------------------------
def _decoder(schema_name: str, message_encoding: str):
    if message_encoding == CLOUD_ENCODING:
        return decode_cloud
    if message_encoding == SCAN_ENCODING:
        return decode_scan
    if message_encoding == STATE_ENCODING:
        return json.loads
    if message_encoding != "json":
        return None
    if schema_name == SCAN_SCHEMA:
        return decode_scan
    if schema_name in (GPS_SCHEMA, NO_FIX_SCHEMA):
        return decode_gps
    if schema_name == IMU_SCHEMA:
        return decode_imu
    return json.loads


def _read_unsorted(path, topics, damage: ReadDamage) -> Iterator[tuple[int, int, str, object]]:
    """(log time [ns], offset, topic, message) in file order; a message that does not decode,
    or of a channel the file never declared (a corrupt channel id or channel record), is
    skipped and counted."""
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, object]] = {}
    for offset, record in iter_records(path, damage):
        if isinstance(record, Message):
            if record.channel_id not in channels:
                damage.skip(path, offset, "message on an undeclared channel")
                continue
            topic, decode = channels[record.channel_id]
            if decode is None or (topics is not None and topic not in topics):
                continue
            try:
                msg = decode(record.data)
            except DECODE_ERRORS:
                damage.skip(path, offset, f"undecodable {topic} message")
                continue
            yield record.log_time, offset, topic, msg
        elif isinstance(record, Channel):
            decode = _decoder(schemas.get(record.schema_id, ""), record.message_encoding)
            channels[record.id] = (record.topic, decode)
        elif isinstance(record, Schema):
            schemas[record.id] = record.name


def read_mission_log(
    path: str | Path,
    topics: Sequence[str] | None = None,
    log_time_order: bool = True,
    damage: ReadDamage | None = None,
) -> Iterator[tuple[str, float, object]]:
    """(topic, log time [s], message) of every message — also of a log that was never finished
    (a crashed run): everything up to the last complete record. Messages: :class:`LaserScan`,
    :class:`GpsFix` (``valid`` False from ``/gps/no_fix``), :class:`ImuSample`,
    :class:`PointCloud` (``/lidar_points``, :func:`decode_cloud`), or the JSON
    object as a dict (states, vectors, poses). ``topics``: only these. ``log_time_order``: sorted
    by log time (sensor messages are written a little after the time they carry), else in file
    order. ``damage``: what a damaged file made the reader skip is counted there
    (:mod:`~usvdrake.logs.mission_log.records`); ConfigError if ``path`` is not an MCAP file."""
    for _, topic, t, msg in _read_messages(path, topics, log_time_order, count_into(damage)):
        yield topic, t, msg


def _read_messages(path, topics, log_time_order: bool, damage: ReadDamage):
    """(offset, topic, log time [s], message): :func:`read_mission_log` with each message's
    offset in the file, which names it in ``damage``."""
    wanted = None if topics is None else set(topics)
    it = _read_unsorted(path, wanted, damage)
    if log_time_order:
        it = iter(sorted(it, key=lambda m: (m[0], m[1])))
    for log_time, offset, topic, msg in it:
        yield offset, topic, log_time * 1e-9, msg


def log_summary(path: str | Path, damage: ReadDamage | None = None) -> dict:
    """What a mission log holds, without decoding it: ``{"complete": bool (the footer is there:
    the writer was closed), "messages": n, "first_time"/"last_time": s or None, "topics": {topic:
    {"schema", "encoding", "messages", "first_time", "last_time"}}, "bytes": file size,
    "skipped_records": n (damaged records left out; :mod:`~usvdrake.logs.mission_log.records`),
    "unread_bytes": n}``."""
    damage = count_into(damage)
    schemas: dict[int, str] = {}
    channels: dict[int, dict] = {}
    complete = False
    for offset, record in iter_records(path, damage):
        if isinstance(record, Message):
            c = channels.get(record.channel_id)
            if c is None:
                damage.skip(path, offset, "message on an undeclared channel")
                continue
            t = record.log_time * 1e-9
            c["messages"] += 1
            c["first_time"] = t if c["first_time"] is None else min(c["first_time"], t)
            c["last_time"] = t if c["last_time"] is None else max(c["last_time"], t)
        elif isinstance(record, Channel):
            channels.setdefault(
                record.id,
                {
                    "topic": record.topic,
                    "schema": schemas.get(record.schema_id, ""),
                    "encoding": record.message_encoding,
                    "messages": 0,
                    "first_time": None,
                    "last_time": None,
                },
            )
        elif isinstance(record, Schema):
            schemas[record.id] = record.name
        elif isinstance(record, Footer):
            # the writer's provisional footer (kept at the end while writing) has no summary
            complete = record.summary_start != 0
    topics = {c.pop("topic"): c for c in channels.values()}
    firsts = [c["first_time"] for c in topics.values() if c["first_time"] is not None]
    lasts = [c["last_time"] for c in topics.values() if c["last_time"] is not None]
    return {
        "complete": complete,
        "messages": sum(c["messages"] for c in topics.values()),
        "first_time": min(firsts) if firsts else None,
        "last_time": max(lasts) if lasts else None,
        "topics": topics,
        "bytes": Path(path).stat().st_size,
        "skipped_records": damage.records,
        "unread_bytes": damage.unread_bytes,
    }


# [s] how far a sensor message's own time may be from its log time (the writer logs it at that
# time): farther, one of them is a corrupt number
TIME_MISMATCH = 1.0


def sane_time(log_time: float, msg) -> bool:
    """Whether a decoded sensor message's own time is finite and agrees with its log time
    (within :data:`TIME_MISMATCH`): a bit flip in either makes them disagree."""
    try:
        t = float(msg.time)
    except (TypeError, ValueError, AttributeError):
        return False
    return bool(np.isfinite(t) and abs(t - log_time) <= TIME_MISMATCH)


def _sane_scan(log_time: float, m) -> bool:
    """Whether a decoded message is a scan a SLAM can use: a LaserScan with beams, its angles
    finite and its time its log time's (what a corrupt record that still decodes may not be)."""
    if not isinstance(m, LaserScan) or not len(m.ranges) or not sane_time(log_time, m):
        return False
    return bool(np.isfinite([m.angle_min, m.angle_increment]).all())


def read_log_scans(
    path: str | Path, topic: str = "/lidar_scan", damage: ReadDamage | None = None
) -> list[BagScan]:
    """The 2D scans of a mission log with at least one return, for ``usvdrake slam2d``; a
    message there that is not a usable scan is skipped and counted in ``damage``."""
    damage = count_into(damage)
    scans = []
    for offset, _, t, m in _read_messages(path, [topic], True, damage):
        if not _sane_scan(t, m):
            damage.skip(path, offset, f"corrupt {topic} message")
        elif m.valid.any():
            scans.append(BagScan(t, m))
    return scans


def _number(v) -> float:
    """A logged number; null (a non-finite value the writer could not put in JSON) is NaN."""
    return math.nan if v is None else v


def _state_row(m: dict) -> list[float]:
    return [_number(v) for v in m["q"]] if "q" in m else [_number(m[k]) for k in STATE_NAMES]


def read_log_states(
    path: str | Path, topic: str = "/ground_truth", damage: ReadDamage | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(times, states n × 6 [x y ψ u v r]) of ``topic`` (``/ground_truth`` or
    ``/state_estimate``) of a mission log; a message there that is not a state is skipped and
    counted in ``damage``."""
    damage = count_into(damage)
    rows = []
    for offset, _, t, m in _read_messages(path, [topic], True, damage):
        try:
            row = [float(v) for v in _state_row(m)]
        except DECODE_ERRORS:
            damage.skip(path, offset, f"corrupt {topic} message")
            continue
        if len(row) != 6:
            damage.skip(path, offset, f"corrupt {topic} message")
            continue
        rows.append((t, row))
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows], float).reshape(-1, 6)


def read_log_vectors(path: str | Path, topic: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(times, values n × m, field names) of a vector topic (states and poses too)."""
    times, rows, names = [], [], None
    for _, t, m in read_mission_log(path, [topic]):
        if not isinstance(m, dict):
            raise TypeError(f"{topic} holds {type(m).__name__} messages, not vectors")
        if "q" in m:  # state-v1
            m = {"t": m["t"], **dict(zip(STATE_NAMES, _state_row(m), strict=True))}
        if names is None:
            skip = {"t", "timestamp", "frame_id", "pose"}
            names = [
                k for k in m if k not in skip and (m[k] is None or isinstance(m[k], int | float))
            ]
        times.append(t)
        rows.append([_number(m[k]) for k in names])
    names = names or []
    return np.array(times), np.array(rows, float).reshape(len(times), len(names)), names
