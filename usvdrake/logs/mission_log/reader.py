"""Reading mission logs, finished or cut off by a crash: :func:`read_mission_log` streams the
MCAP records up to the last complete one and decodes each message by its channel's schema and
encoding (current and earlier encodings); :func:`log_summary` says what a log holds (topics,
counts, times, whether the footer is there) without decoding it; :func:`read_log_scans`,
:func:`read_log_states` and :func:`read_log_vectors` turn topics into the SLAM runners' scans
and arrays."""

import json
import math
import struct
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
from mcap.exceptions import EndOfFile
from mcap.records import Channel, Footer, Message, Schema
from mcap.stream_reader import StreamReader

from usvdrake.logs.mission_log.codecs import decode_cloud, decode_gps, decode_imu, decode_scan
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


# --- reading ----------------------------------------------------------------------------------
def _iter_records(path: str | Path):
    """The records of an MCAP file, finished or not: stops quietly at the end of the last
    complete record of a file that was cut off (a crashed writer)."""
    with open(path, "rb") as f:
        try:
            yield from StreamReader(f, skip_magic=False).records
        except (EndOfFile, EOFError, struct.error):  # short reads at the cut
            return


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


def _read_unsorted(path, topics) -> Iterator[tuple[int, int, str, object]]:
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, object]] = {}
    for seq, record in enumerate(_iter_records(path)):
        if isinstance(record, Message):
            topic, decode = channels.get(record.channel_id, (None, None))
            if decode is None or (topics is not None and topic not in topics):
                continue
            yield record.log_time, seq, topic, decode(record.data)
        elif isinstance(record, Channel):
            decode = _decoder(schemas.get(record.schema_id, ""), record.message_encoding)
            channels[record.id] = (record.topic, decode)
        elif isinstance(record, Schema):
            schemas[record.id] = record.name


def read_mission_log(
    path: str | Path, topics: Sequence[str] | None = None, log_time_order: bool = True
) -> Iterator[tuple[str, float, object]]:
    """(topic, log time [s], message) of every message — also of a log that was never finished
    (a crashed run): everything up to the last complete record. Messages: :class:`LaserScan`,
    :class:`GpsFix` (``valid`` False from ``/gps/no_fix``), :class:`ImuSample`,
    :class:`PointCloud` (``/lidar_points``, :func:`decode_cloud`), or the JSON
    object as a dict (states, vectors, poses). ``topics``: only these. ``log_time_order``: sorted
    by log time (sensor messages are written a little after the time they carry), else in file
    order."""
    wanted = None if topics is None else set(topics)
    it = _read_unsorted(path, wanted)
    if log_time_order:
        it = iter(sorted(it, key=lambda m: (m[0], m[1])))
    for log_time, _, topic, msg in it:
        yield topic, log_time * 1e-9, msg


def log_summary(path: str | Path) -> dict:
    """What a mission log holds, without decoding it: ``{"complete": bool (the footer is there:
    the writer was closed), "messages": n, "first_time"/"last_time": s or None, "topics": {topic:
    {"schema", "encoding", "messages", "first_time", "last_time"}}, "bytes": file size}``."""
    schemas: dict[int, str] = {}
    channels: dict[int, dict] = {}
    complete = False
    for record in _iter_records(path):
        if isinstance(record, Message):
            c = channels.get(record.channel_id)
            if c is None:
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
            complete = True
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
    }


def read_log_scans(path: str | Path, topic: str = "/lidar_scan") -> list[BagScan]:
    """The 2D scans of a mission log with at least one return, for ``usvdrake slam2d``."""
    return [
        BagScan(t, m)
        for _, t, m in read_mission_log(path, [topic])
        if isinstance(m, LaserScan) and m.valid.any()
    ]


def _number(v) -> float:
    """A logged number; null (a non-finite value the writer could not put in JSON) is NaN."""
    return math.nan if v is None else v


def _state_row(m: dict) -> list[float]:
    return [_number(v) for v in m["q"]] if "q" in m else [_number(m[k]) for k in STATE_NAMES]


def read_log_states(
    path: str | Path, topic: str = "/ground_truth"
) -> tuple[np.ndarray, np.ndarray]:
    """(times, states n × 6 [x y ψ u v r]) of ``topic`` (``/ground_truth`` or
    ``/state_estimate``) of a mission log."""
    rows = [(t, _state_row(m)) for _, t, m in read_mission_log(path, [topic])]
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
