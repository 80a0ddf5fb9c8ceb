"""Recorded lidar, IMU and GNSS messages in time order, for running the 3D SLAM offline.

:func:`read_sensor_stream` reads either

* a mission log (MCAP, ``DIR/log.mcap`` or the run's folder ``DIR``; see
  :mod:`usvdrake.logs.mission_log`): ``/lidar_points`` (:class:`PointCloud`, range-image
  encoding), ``/imu`` (:class:`ImuSample`), ``/gps`` and ``/gps/no_fix`` (:class:`GpsFix`),
  decoded by :func:`~usvdrake.logs.mission_log.read_mission_log`; or
* a ROS 1 ``.bag`` or ROS 2 bag folder (:func:`~usvdrake.logs.rosbag.is_bag`) read with the
  ``rosbags`` package (no ROS install): ``sensor_msgs/PointCloud2``, ``sensor_msgs/Imu`` and
  ``sensor_msgs/NavSatFix`` (REP 145 / the sensor_msgs definitions), converted as below.

and yields :class:`SensorMessage` ``(time, kind, msg)`` with kind ``"lidar"``, ``"imu"`` or
``"gps"``, in time order.

Conversions (ROS → ours)
------------------------
* Times: the header stamp; the bag's receive time where the stamp is zero.
* PointCloud2: the fields ``x, y, z`` (and ``ring``, ``time`` or ``t`` if present) are read at
  their ``offset`` with their ``datatype`` (INT8 … FLOAT64), ``point_step``, ``row_step`` and
  ``is_bigendian``. Non-finite or zero-range points are dropped. With a ``ring`` field the ring
  is the field's value and each ring's elevation is ``elevations[ring]`` if ``elevations`` is
  given, else the median elevation of its points; without it the cloud is organised by
  :func:`~usvdrake.systems.slam.lidar_features.organise_cloud` (nearest of ``elevations``,
  default VLP-16: 16 rings, −15° … +15°). Column = azimuth bin ⌊(a + π) · columns / 2π⌋, the
  nearest return per pixel kept; ``points`` are the measured points. Per-point times
  (``time``: float seconds, or integer nanoseconds — Ouster's ``t``) are offsets from the
  header stamp (velodyne_pointcloud, LIO-SAM, Ouster); as :class:`PointCloud` asks, the cloud
  is stamped at its last point: ``time`` = stamp + max offset, ``point_time`` = offset − min
  offset (from the sweep's start), ``sweep_time`` = max − min offset, so a point's absolute
  time is ``time − sweep_time + point_time`` = stamp + its offset. ``motion_applied`` is True
  (a real sensor measures each point from where it was).
* Imu: ``angular_velocity``, ``linear_acceleration``, ``orientation`` (x, y, z, w) as they are.
* NavSatFix: valid when ``status.status >= 0`` (STATUS_FIX or better); ``position_covariance``
  is ENU row-major in ROS as in :class:`GpsFix`; when ``position_covariance_type`` is 0
  (COVARIANCE_TYPE_UNKNOWN) or the diagonal is not positive and finite it is replaced by
  :data:`UNKNOWN_COVARIANCE` (100 m² on the diagonal: the fix still counts, weakly). HDOP and
  the satellite count are not in the message (99, 0).

:func:`read_ground_truth` gives the ``/ground_truth`` states of a mission log (simulation).
"""

import heapq
import itertools
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np
from rosbags.typesys import Stores

from usvdrake.logs.damage import ReadDamage, count_into
from usvdrake.logs.mission_log import log_summary, read_log_states, read_mission_log
from usvdrake.logs.mission_log.reader import sane_time
from usvdrake.logs.rosbag import bag_messages, is_bag, open_bag
from usvdrake.sensors.messages import GpsFix, ImuSample, PointCloud
from usvdrake.systems.slam.lidar_features import (
    azimuth_column,
    column_azimuths,
    nearest_per_pixel,
    organise_cloud,
    uniform_elevations,
)
from usvdrake.typed_yaml import ConfigError

POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
IMU = "sensor_msgs/msg/Imu"
NAV_SAT_FIX = "sensor_msgs/msg/NavSatFix"
MISSION_TOPICS = {"lidar": "/lidar_points", "imu": "/imu", "gps": "/gps"}
UNKNOWN_COVARIANCE = np.diag([100.0, 100.0, 100.0])  # [m^2] ENU, for covariance type UNKNOWN
MCAP_MAGIC = b"\x89MCAP0\r\n"
MAX_RINGS = 512  # a ``ring`` field beyond this is not a ring number

# sensor_msgs/PointField datatypes → numpy types
_POINT_FIELD_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


class SensorMessage(NamedTuple):
    time: float  # [s]
    kind: str  # "lidar" | "imu" | "gps"
    msg: object  # PointCloud | ImuSample | GpsFix


def vlp16_elevations() -> np.ndarray:
    """The VLP-16's nominal ring elevations [rad]: 16, −15° … +15° every 2°."""
    return uniform_elevations(16, np.deg2rad(-15.0), np.deg2rad(15.0))


# --- the file ---------------------------------------------------------------------------------
def _mission_log_file(path: Path) -> Path | None:
    """The MCAP file of ``path`` (a ``.mcap`` file, or a run folder holding ``log.mcap``)."""
    p = path / "log.mcap" if path.is_dir() else path
    if not p.is_file():
        return None
    with open(p, "rb") as f:
        return p if f.read(len(MCAP_MAGIC)) == MCAP_MAGIC else None


# --- ordering ---------------------------------------------------------------------------------
def _time_ordered(messages: Iterator[SensorMessage], window: float) -> Iterator[SensorMessage]:
    """``messages`` (nearly in time order, as recorded) sorted by time with a bounded buffer: a
    message is released once one ``window`` [s] newer has been seen, so a stream may lag the
    others by up to ``window`` (a cloud is stamped at its sweep's end, a GNSS fix arrives late)
    without holding the whole recording in memory. Equal times keep their order."""
    heap: list = []
    newest = -np.inf
    seq = itertools.count()
    for m in messages:
        heapq.heappush(heap, (m.time, next(seq), m))
        newest = max(newest, m.time)
        while heap and heap[0][0] <= newest - window:
            yield heapq.heappop(heap)[2]
    while heap:
        yield heapq.heappop(heap)[2]


# --- mission logs -----------------------------------------------------------------------------
def _mission_log_topics(
    path: Path,
    lidar_topic: str | None,
    imu_topic: str | None,
    gps_topic: str | None,
    damage: ReadDamage,
) -> dict[str, str]:
    """{topic: kind} to read from a mission log; ConfigError if a requested topic is missing or
    there is none of the three."""
    asked = {"lidar": lidar_topic, "imu": imu_topic, "gps": gps_topic}
    have = log_summary(path, damage)["topics"]
    topics: dict[str, str] = {}
    for kind, topic in asked.items():
        t = topic or MISSION_TOPICS[kind]
        found = [x for x in (t, t.rstrip("/") + "/no_fix" if kind == "gps" else t) if x in have]
        if found:
            topics.update(dict.fromkeys(found, kind))
        elif topic is not None:
            got = _found_mission(have) + damage.note()
            raise ConfigError(path, "", f"{kind} messages on {topic}", got)
    if not topics:
        wanted = ", ".join(MISSION_TOPICS.values())
        got = _found_mission(have) + damage.note()
        raise ConfigError(path, "", f"sensor messages on {wanted}", got)
    return topics


def _mission_log_messages(
    path: Path, topics: dict[str, str], damage: ReadDamage
) -> Iterator[SensorMessage]:
    """The sensor messages of a mission log; one of another type than its topic's, or whose
    time is not finite or not its log time (what a corrupt record that still decodes can be),
    skipped and counted."""
    types = {"lidar": PointCloud, "imu": ImuSample, "gps": GpsFix}
    messages = read_mission_log(path, list(topics), log_time_order=False, damage=damage)
    for i, (topic, log_time, msg) in enumerate(messages):
        kind = topics[topic]
        if not isinstance(msg, types[kind]) or not sane_time(log_time, msg):
            damage.skip(path, ("sensor message", i), f"corrupt {topic} message")
            continue
        yield SensorMessage(float(msg.time), kind, msg)


def _found_mission(topics: dict) -> str:
    found = [f"{t} ({c['schema']})" for t, c in sorted(topics.items())]
    return "only " + (", ".join(found) or "no messages")


# --- ROS conversions --------------------------------------------------------------------------
def _stamp(msg, t_bag: int) -> float:
    s = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
    return s if s > 0 else 1e-9 * t_bag


def point_cloud2_fields(msg) -> dict[str, np.ndarray]:
    """The ``x, y, z`` and, when present, ``ring``, ``time`` / ``t`` columns of a ROS
    ``sensor_msgs/PointCloud2`` as numpy arrays (height · width points, row-major), read by
    each ``PointField``'s ``offset`` and ``datatype`` within ``point_step``-byte points,
    ``row_step``-byte rows, in the message's byte order (``is_bigendian``)."""
    order = ">" if msg.is_bigendian else "<"
    fields = {f.name: f for f in msg.fields}
    missing = [n for n in "xyz" if n not in fields]
    if missing:
        names = ", ".join(fields) or "none"
        raise ValueError(f"PointCloud2 without field(s) {', '.join(missing)} (fields: {names})")
    wanted = [n for n in ("x", "y", "z", "ring", "time", "t") if n in fields]
    for n in wanted:
        if fields[n].datatype not in _POINT_FIELD_TYPES:
            raise ValueError(f"PointCloud2 field {n!r}: unknown datatype {fields[n].datatype}")
    dtype = np.dtype(
        {
            "names": wanted,
            "formats": [order + _POINT_FIELD_TYPES[fields[n].datatype] for n in wanted],
            "offsets": [fields[n].offset for n in wanted],
            "itemsize": msg.point_step,
        }
    )
    height, width = int(msg.height), int(msg.width)
    raw = np.frombuffer(bytes(msg.data), np.uint8)
    if height * width == 0:
        return {n: np.zeros(0, dtype[n]) for n in wanted}
    rows = raw[: height * msg.row_step].reshape(height, msg.row_step)[:, : width * msg.point_step]
    pts = np.ascontiguousarray(rows).view(dtype).reshape(-1)
    out = {n: pts[n].astype(float if dtype[n].kind == "f" else np.int64) for n in wanted}
    for n in ("time", "t"):  # integer times are nanoseconds (Ouster's t)
        if n in out and dtype[n].kind != "f":
            out[n] = out[n] * 1e-9
    return out


def _organise_rings(
    xyz: np.ndarray,
    ring: np.ndarray,
    offsets: np.ndarray,
    elevations: np.ndarray | None,
    columns: int,
) -> PointCloud:
    """A range image with the given rings (row = ring value) and azimuth-bin columns as
    :func:`organise_cloud` bins them; the nearest return per pixel is kept."""
    rings = int(ring.max()) + 1 if len(ring) else 0
    if rings > MAX_RINGS:
        raise ValueError(f"PointCloud2 ring field up to {rings - 1}: not a ring number")
    if elevations is not None:
        rings = max(rings, len(elevations))
    r = np.linalg.norm(xyz, axis=1)
    e = np.arcsin(np.clip(xyz[:, 2] / r, -1.0, 1.0))
    a = np.arctan2(xyz[:, 1], xyz[:, 0])
    col = azimuth_column(a, columns)
    img, keep = nearest_per_pixel(r, ring, col, rings, columns)
    if elevations is not None and len(elevations) >= rings:
        elev = np.asarray(elevations, float)
    else:  # each ring's median measured elevation, interpolated over rings without points
        elev = np.full(rings, np.nan)
        for k in np.unique(ring):
            elev[k] = np.median(e[ring == k])
        ok = np.isfinite(elev)
        idx = np.arange(rings)
        elev = np.interp(idx, idx[ok], elev[ok]) if ok.any() else np.zeros(rings)
    return PointCloud(
        elevations=elev,
        azimuths=column_azimuths(columns),
        range_image=img,
        points=xyz[keep],
        ring=ring[keep],
        column=col[keep],
        point_time=offsets[keep],
    )


def _kept_offsets(xyz: np.ndarray, offsets: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """The offsets of the rows of ``xyz`` that :func:`organise_cloud` kept (its ``points`` are
    copies of input rows)."""
    index = {row.tobytes(): i for i, row in enumerate(xyz)}
    return offsets[[index[row.tobytes()] for row in np.ascontiguousarray(kept)]]


def to_point_cloud(
    msg, stamp: float, elevations: np.ndarray | None = None, columns: int = 1800
) -> PointCloud:
    """A ROS ``sensor_msgs/PointCloud2`` sweep as an organised :class:`PointCloud` (see the
    module's notes: rings from the ``ring`` field or by elevation, per-point times kept)."""
    f = point_cloud2_fields(msg)
    xyz = np.column_stack([f["x"], f["y"], f["z"]])
    time_field = f.get("time", f.get("t"))
    offsets = np.zeros(len(xyz)) if time_field is None else time_field
    r = np.linalg.norm(xyz, axis=1)
    ok = np.isfinite(r) & (r > 0) & np.isfinite(offsets)
    ring = f.get("ring")
    if ring is not None:
        ok &= ring >= 0
    xyz, offsets = np.ascontiguousarray(xyz[ok]), offsets[ok]
    if ring is not None:
        cloud = _organise_rings(xyz, ring[ok], offsets, elevations, columns)
    else:
        elev = vlp16_elevations() if elevations is None else np.asarray(elevations, float)
        cloud = organise_cloud(xyz, elev, columns)
        if time_field is not None:
            cloud.point_time = _kept_offsets(xyz, offsets, cloud.points)
    first = float(offsets.min()) if len(offsets) else 0.0
    last = float(offsets.max()) if len(offsets) else 0.0
    cloud.time = stamp + last
    cloud.point_time = np.asarray(cloud.point_time, float) - first
    cloud.sweep_time = last - first
    cloud.motion_applied = True
    return cloud


def to_imu_sample(msg, stamp: float) -> ImuSample:
    """A ROS ``sensor_msgs/Imu`` as an :class:`ImuSample` (same frame, orientation x y z w)."""
    w, a, q = msg.angular_velocity, msg.linear_acceleration, msg.orientation
    return ImuSample(
        time=stamp,
        angular_velocity=np.array([w.x, w.y, w.z], float),
        linear_acceleration=np.array([a.x, a.y, a.z], float),
        orientation=np.array([q.x, q.y, q.z, q.w], float),
    )


def to_gps_fix(msg, stamp: float) -> GpsFix:
    """A ROS ``sensor_msgs/NavSatFix`` as a :class:`GpsFix`: valid when ``status.status >= 0``;
    covariance = ``position_covariance`` (ENU, row-major), or :data:`UNKNOWN_COVARIANCE` when its
    type is UNKNOWN (0) or its diagonal is not positive and finite."""
    cov = np.asarray(msg.position_covariance, float).reshape(3, 3)
    d = np.diag(cov)
    if int(msg.position_covariance_type) == 0 or not np.all(np.isfinite(d) & (d > 0)):
        cov = UNKNOWN_COVARIANCE.copy()
    return GpsFix(
        time=stamp,
        valid=int(msg.status.status) >= 0,
        latitude=float(msg.latitude),
        longitude=float(msg.longitude),
        altitude=float(msg.altitude),
        covariance_enu=cov,
    )


# --- bags -------------------------------------------------------------------------------------
_BAG_TYPES = {"lidar": POINT_CLOUD2, "imu": IMU, "gps": NAV_SAT_FIX}


def _open_bag(path: Path):
    # used only for bags without message definitions (ROS 2 bags before Iron): ROS 1 bags
    # carry them, and ROS 1 and ROS 2 std_msgs/Header differ (seq)
    store = Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.ROS2_HUMBLE
    return open_bag(path, store)


def _bag_topics(path: Path, topics: dict[str, str | None]) -> dict[tuple[str, str], str]:
    """{(topic, message type): kind} to read from a bag; ConfigError if a requested topic is
    missing, a type is on several topics and none was chosen, or there is none of the three."""
    with _open_bag(path) as reader:
        conns = [(c.topic, c.msgtype) for c in reader.connections]
    have = "only " + (", ".join(sorted({f"{t} ({m})" for t, m in conns})) or "no messages")
    plan: dict[tuple[str, str], str] = {}
    for kind, msgtype in _BAG_TYPES.items():
        topic = topics[kind]
        names = sorted({t for t, m in conns if m == msgtype and topic in (None, t)})
        if topic is not None and not names:
            raise ConfigError(path, "", f"{msgtype} messages on {topic}", have)
        if len(names) > 1:
            wanted = f"one {msgtype} topic (choose one with {kind}_topic)"
            raise ConfigError(path, "", wanted, ", ".join(names))
        plan.update({(t, msgtype): kind for t in names})
    if not plan:
        raise ConfigError(path, "", f"messages of {', '.join(_BAG_TYPES.values())}", have)
    return plan


def _bag_messages(
    path: Path,
    plan: dict[tuple[str, str], str],
    elevations: np.ndarray | None,
    columns: int,
    damage: ReadDamage,
) -> Iterator[SensorMessage]:
    def convert(conn, t_bag: int, msg) -> SensorMessage:
        stamp = _stamp(msg, t_bag)
        kind = plan[(conn.topic, conn.msgtype)]
        if kind == "lidar":
            out = to_point_cloud(msg, stamp, elevations, columns)
        elif kind == "imu":
            out = to_imu_sample(msg, stamp)
        else:
            out = to_gps_fix(msg, stamp)
        if not np.isfinite(out.time):  # a corrupt stamp
            raise ValueError(f"{conn.topic}: a message with a non-finite time")
        return SensorMessage(float(out.time), kind, out)

    with _open_bag(path) as reader:
        conns = [c for c in reader.connections if (c.topic, c.msgtype) in plan]
        yield from bag_messages(reader, conns, path, damage, convert)


# --- API --------------------------------------------------------------------------------------
def read_sensor_stream(
    path: str | Path,
    lidar_topic: str | None = None,
    imu_topic: str | None = None,
    gps_topic: str | None = None,
    elevations: np.ndarray | None = None,
    columns: int = 1800,
    reorder_window: float = 2.0,
    damage: ReadDamage | None = None,
) -> Iterator[SensorMessage]:
    """The lidar sweeps, IMU samples and GNSS fixes of a mission log or ROS bag, in time order.

    Parameters
    ----------
    path
        A mission log (``.mcap`` file, or a run folder with ``log.mcap``), a ROS 1 ``.bag``
        file or a ROS 2 bag folder.
    lidar_topic, imu_topic, gps_topic
        The topics to read. None: a mission log's ``/lidar_points``, ``/imu``, ``/gps`` (with
        ``/gps/no_fix``) if present; in a bag, the one topic of each type (PointCloud2, Imu,
        NavSatFix) if there is one (several: an error). A topic given but missing is an error.
    elevations
        Bags: nominal ring elevations [rad] for organising clouds (default VLP-16, ±15°); with a
        ``ring`` field, the elevation of each ring (default: measured).
    columns
        Bags: azimuth bins of the organised range image (VLP-16 at 10 Hz: 1800).
    reorder_window
        [s] how far a message may be recorded after a newer one and still come out in order
        (:func:`_time_ordered`); the buffer holds this much of the recording.
    damage
        Where the records a damaged file made the readers skip are counted (filled as the
        messages are read; :class:`~usvdrake.logs.damage.ReadDamage`).

    Yields
    ------
    SensorMessage
        ``(time [s], kind, msg)``: ``"lidar"`` :class:`PointCloud` (time = end of the sweep),
        ``"imu"`` :class:`ImuSample`, ``"gps"`` :class:`GpsFix` (``valid`` False for no fix).

    Raises
    ------
    ConfigError
        (a ValueError) naming the path and what was expected: the path is neither a mission log
        nor a bag, a requested topic is missing (listing the topics and types there are), or
        there are no sensor messages at all; or the file cannot be read at all (garbage, a
        bag the reader cannot open). Raised by the call, before any message is read.
    """
    p = Path(path)
    damage = count_into(damage)
    if is_bag(p):
        topics = {"lidar": lidar_topic, "imu": imu_topic, "gps": gps_topic}
        it = _bag_messages(p, _bag_topics(p, topics), elevations, columns, damage)
    else:
        log = _require_mission_log(p)
        asked = _mission_log_topics(log, lidar_topic, imu_topic, gps_topic, damage)
        it = _mission_log_messages(log, asked, damage)
    return _time_ordered(it, reorder_window)


def _require_mission_log(p: Path) -> Path:
    log = _mission_log_file(p)
    if log is None:
        raise ConfigError(
            p,
            "",
            "an MCAP mission log (.mcap, or a folder with log.mcap), a ROS 1 .bag file or a ROS 2 "
            "bag folder (with metadata.yaml)",
            "nothing there" if not p.exists() else "neither",
        )
    return log


def read_ground_truth(
    path: str | Path, topic: str = "/ground_truth", damage: ReadDamage | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """(times [s], states n × 6 [x y ψ u v r]) of a mission log's ``topic`` (simulation ground
    truth; :func:`~usvdrake.logs.mission_log.read_log_states`), or None when there is none (a
    hardware run's log, or a ROS bag). ConfigError if ``path`` is neither. ``damage``: where
    damaged records are counted."""
    p = Path(path)
    if is_bag(p):
        return None
    log = _require_mission_log(p)
    if topic not in log_summary(log, damage)["topics"]:
        return None
    return read_log_states(log, topic, damage)
