"""LaserScan from ROS 1 bags and ROS 2 bag folders, with the ``rosbags`` package (no ROS install).

``read_bag_scans(path, topic=None)`` yields ``(timestamp [s], LaserScan)`` records for every
``sensor_msgs/msg/LaserScan`` message (of ``topic`` if given), stamped with the message header's
time (the bag's receive time when the header stamp is zero). Ranges outside
[range_min, range_max] or not finite are no-returns (``inf``, ``valid=False``), as ROS defines.
"""

from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from usvdrake.sensors.messages import LaserScan
from usvdrake.typed_yaml import ConfigError

LASER_SCAN = "sensor_msgs/msg/LaserScan"


class BagScan(NamedTuple):
    timestamp: float  # [s]
    scan: LaserScan


def is_bag(path: str | Path) -> bool:
    """A ROS 1 ``.bag`` file or a ROS 2 bag folder (with ``metadata.yaml``)."""
    p = Path(path)
    return p.suffix == ".bag" or (p.is_dir() and (p / "metadata.yaml").is_file())


def to_laser_scan(msg, stamp: float) -> LaserScan:
    """A ROS LaserScan message as our :class:`LaserScan`."""
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


def read_bag_scans(path: str | Path, topic: str | None = None) -> Iterator[BagScan]:
    path = Path(path)
    if not is_bag(path):
        raise ConfigError(path, "", "a ROS 1 .bag file or a ROS 2 bag folder", "neither")
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS1_NOETIC)) as reader:
        conns = [
            c
            for c in reader.connections
            if c.msgtype == LASER_SCAN and (topic is None or c.topic == topic)
        ]
        if not conns:
            found = sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections})
            wanted = f"LaserScan messages on {topic}" if topic else "LaserScan messages"
            raise ConfigError(path, "", wanted, "only " + (", ".join(found) or "no messages"))
        for conn, t_bag, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
            stamp = stamp if stamp > 0 else 1e-9 * t_bag
            yield BagScan(stamp, to_laser_scan(msg, stamp))
