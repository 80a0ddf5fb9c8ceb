"""LaserScan from ROS 1 bags and ROS 2 bag folders, with the ``rosbags`` package (no ROS install).

``read_bag_scans(path, topic=None)`` yields ``(timestamp [s], LaserScan, odometry pose)`` records
for every ``sensor_msgs/msg/LaserScan`` message (of ``topic`` if given), stamped with the message
header's time (the bag's receive time when the header stamp is zero). The odometry pose is the
bag's wheel odometry (``nav_msgs/msg/Odometry`` on ``/odom``, or its only Odometry topic)
interpolated to the scan's time, or None (no odometry, or the scan outside its span); it is
the robot's base pose, not the laser's (no tf is read), which only the odometry's steps use.
Ranges outside [range_min, range_max] or not finite are no-returns (``inf``, ``valid=False``),
as ROS defines.

Damage: a bag the ``rosbags`` package cannot open (garbage, a foreign or cut-off file) is
refused with one line (:class:`ConfigError`); a message that does not deserialise or convert
is skipped, and a bag whose messages stop being readable part-way ends there, both counted in
a :class:`~usvdrake.logs.damage.ReadDamage` (:func:`open_bag`, :func:`bag_messages`).
"""

import itertools
import struct
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

import numpy as np
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag1 import ReaderError as Ros1ReaderError
from rosbags.rosbag2 import ReaderError as Ros2ReaderError
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, TypesysError, get_typestore

from usvdrake.logs.damage import ReadDamage, count_into
from usvdrake.sensors.messages import LaserScan
from usvdrake.typed_yaml import ConfigError

LASER_SCAN = "sensor_msgs/msg/LaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
# what the rosbags package raises on damaged bytes: its own errors, and what its parsers hit in
# bytes they do not check (short structs, bad UTF-8, indexes and sizes out of range, broken
# bz2 / lz4 chunks: OSError, EOFError, RuntimeError; a message's time that does not match its
# index entry: an assert in rosbag1's reader)
BAG_ERRORS = (
    AssertionError,
    AnyReaderError,
    Ros1ReaderError,
    Ros2ReaderError,
    SerdeError,
    TypesysError,
    struct.error,
    zlib.error,
    ValueError,
    KeyError,
    IndexError,
    TypeError,
    AttributeError,
    OverflowError,
    MemoryError,
    OSError,
    EOFError,
    RuntimeError,
)


class BagScan(NamedTuple):
    timestamp: float  # [s]
    scan: LaserScan
    # (x [m], y [m], yaw [rad]) of the bag's wheel odometry at the scan's time, or None
    odometry_pose: np.ndarray | None = None


def is_bag(path: str | Path) -> bool:
    """A ROS 1 ``.bag`` file or a ROS 2 bag folder (with ``metadata.yaml``)."""
    p = Path(path)
    return p.suffix == ".bag" or (p.is_dir() and (p / "metadata.yaml").is_file())


def to_laser_scan(msg, stamp: float) -> LaserScan:
    """A ROS LaserScan message as our :class:`LaserScan`."""
    with np.errstate(invalid="ignore"):  # NaN ranges are no-returns, not worth a warning
        r = np.asarray(msg.ranges, dtype=float)
        valid = np.isfinite(r) & (r >= msg.range_min) & (r <= msg.range_max)
    return LaserScan(
        time=stamp,
        angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment),
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        scan_time=float(msg.scan_time),
        time_increment=float(msg.time_increment),
        ranges=np.where(valid, r, np.inf),
        valid=valid,
    )


def _one_line(e: BaseException) -> str:
    text = " ".join(str(e).split())[:200]
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


@contextmanager
def open_bag(path: Path, store: Stores):
    """An open :class:`AnyReader` of a bag (``store``: the types of a bag that carries no
    message definitions); ConfigError, one line, if the bag cannot be opened."""
    try:
        reader = AnyReader([path], default_typestore=get_typestore(store))
        reader.open()
    except BAG_ERRORS as e:
        raise ConfigError(path, "", "a readable ROS bag", _one_line(e)) from None
    try:
        yield reader
    finally:
        reader.close()


def bag_messages(reader, connections, path, damage: ReadDamage, convert):
    """``convert(connection, bag time [ns], message)`` of every message of ``connections``
    that deserialises and converts; the others skipped and counted in ``damage``, and the
    rest of the bag when reading it breaks off."""
    it = reader.messages(connections=connections)
    for i in itertools.count():
        try:
            conn, t_bag, raw = next(it)
        except StopIteration:
            return
        except BAG_ERRORS as e:  # the reader cannot go on: what it read stays
            damage.skip(path, ("bag", i), f"unreadable rest of the bag ({type(e).__name__})")
            return
        try:
            out = convert(conn, t_bag, reader.deserialize(raw, conn.msgtype))
        except BAG_ERRORS:
            damage.skip(path, ("bag", i), f"corrupt {conn.topic} message")
            continue
        yield out


def read_bag_scans(
    path: str | Path, topic: str | None = None, damage: ReadDamage | None = None
) -> Iterator[BagScan]:
    """The LaserScan messages of a bag (of ``topic`` if given) as :class:`BagScan` records;
    damage skipped and counted in ``damage`` (module doc)."""
    path = Path(path)
    damage = count_into(damage)
    if not is_bag(path):
        raise ConfigError(path, "", "a ROS 1 .bag file or a ROS 2 bag folder", "neither")
    with open_bag(path, Stores.ROS1_NOETIC) as reader:
        conns = [
            c
            for c in reader.connections
            if c.msgtype == LASER_SCAN and (topic is None or c.topic == topic)
        ]
        if not conns:
            found = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
            wanted = f"LaserScan messages on {topic}" if topic else "LaserScan messages"
            raise ConfigError(path, "", wanted, "only " + (", ".join(found) or "no messages"))
        odom = [c for c in reader.connections if c.msgtype == ODOMETRY]
        # /odom if the bag has it, else its one Odometry topic (several others: which is the
        # wheels' is not ours to guess)
        odom = [c for c in odom if c.topic == "/odom"] or (odom if len(odom) == 1 else [])
        if not odom:
            yield from bag_messages(reader, conns, path, damage, _bag_scan)
            return
        records = list(bag_messages(reader, conns + odom, path, damage, _scan_or_odometry))
    scans = [r for r in records if isinstance(r, BagScan)]
    odometry = np.array([r for r in records if not isinstance(r, BagScan)], float).reshape(-1, 4)
    poses = odometry_at(odometry, np.array([s.timestamp for s in scans], float))
    for rec, pose in zip(scans, poses, strict=True):
        yield rec._replace(odometry_pose=pose if np.all(np.isfinite(pose)) else None)


def odometry_at(odometry: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Poses (n × 3) at the times ``t`` of an odometry stream ``odometry`` (rows t, x, y,
    yaw), interpolated linearly (yaw unwrapped first); NaN outside its time span or without
    two readings."""
    out = np.full((len(t), 3), np.nan)
    odometry = odometry[np.argsort(odometry[:, 0], kind="stable")] if len(odometry) else odometry
    if len(odometry) < 2:
        return out
    ts = odometry[:, 0]
    inside = (t >= ts[0]) & (t <= ts[-1])
    yaw = np.unwrap(odometry[:, 3])
    for k, column in enumerate((odometry[:, 1], odometry[:, 2], yaw)):
        out[inside, k] = np.interp(t[inside], ts, column)
    return out


def _scan_or_odometry(conn, t_bag: int, msg):
    """A :class:`BagScan`, or an odometry reading (t, x, y, yaw) of a nav_msgs/Odometry."""
    if conn.msgtype != ODOMETRY:
        return _bag_scan(conn, t_bag, msg)
    stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
    stamp = stamp if stamp > 0 else 1e-9 * t_bag
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    yaw = np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    row = (stamp, float(p.x), float(p.y), float(yaw))
    if not np.all(np.isfinite(row)):
        raise ValueError(f"{conn.topic}: an odometry reading with a non-finite field")
    return row


def _bag_scan(conn, t_bag: int, msg) -> BagScan:
    stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
    stamp = stamp if stamp > 0 else 1e-9 * t_bag
    if not np.isfinite([stamp, msg.angle_min, msg.angle_increment]).all():
        raise ValueError(f"{conn.topic}: a scan with a non-finite time or angle")
    return BagScan(stamp, to_laser_scan(msg, stamp))
