"""The project's mission logs: MCAP files (``DIR/log.mcap``) that every run — simulation,
hardware-in-the-loop, hardware — writes while it runs, that open in Foxglove and replay into the
SLAM runners (``usvdrake slam2d DIR/log.mcap``).

Encoding
--------
Every channel but ``/lidar_points`` has message encoding ``json`` and a ``jsonschema`` schema
(Foxglove decodes both natively); the schema *name* says what the message is — Foxglove's 3D and
Map panels draw the ``foxglove.*`` ones, its Plot panel plots any numeric field by path
(``/ground_truth.x``, ``/thruster_command.thruster_2``, ``/imu.angular_velocity.z``). Besides
the fields their schema requires, messages carry ``t`` [s] (the time as a plain number, for
plotting) and whatever the ``foxglove.*`` schema lacks to restore our own message exactly (JSON
Schema allows extra properties).

================== ======================= ====================================================
default topic      schema                  message
================== ======================= ====================================================
/ground_truth      usvdrake.VesselState    ``{"t", "x", "y", "psi", "u", "v", "r"}`` [m, rad,
/state_estimate                            m/s, rad/s]; ground truth only in simulation
/thruster_command  usvdrake.Vector.<name>  ``{"t", <name_0>: v0, ...}``: one named number per
/thrust_applied                            vector entry (``thruster_0``...; ``reference``:
/thrust_measured                           ``psi_d, u_d, e``; ``pose_measurement``: ``x, y,
/pose_measurement                          psi, r``); the schema lists the names in order
/reference
/slam_pose         foxglove.PoseInFrame    ``timestamp``, ``frame_id`` ("world"), ``pose``
                                           (yaw-only quaternion), plus ``t, x, y, psi``
/lidar_scan        foxglove.LaserScan      ``timestamp``, ``frame_id`` ("lidar"), ``pose``
                                           (identity), ``start_angle``, ``end_angle``,
                                           ``ranges`` [m] (no return: **0**; JSON has no inf),
                                           ``intensities`` (empty), plus ``t, angle_increment,
                                           range_min, range_max, scan_time``
/gps               foxglove.LocationFix    valid fixes only: ``timestamp``, ``frame_id``
                                           ("gps"), ``latitude``, ``longitude``, ``altitude``,
                                           ``position_covariance`` (ENU, row-major),
                                           ``position_covariance_type`` (3, known),
                                           ``metadata``, plus ``t, hdop, satellites, speed,
                                           course``
/gps/no_fix        usvdrake.GpsNoFix       invalid fixes (no position: Foxglove's map would
                                           draw them at 0°, 0°): ``{"t", "timestamp",
                                           "hdop", "satellites"}``
/imu               usvdrake.Imu            ``{"t", "timestamp", "frame_id", "angular_velocity":
                                           {x, y, z}, "linear_acceleration": {x, y, z},
                                           "orientation": {x, y, z, w}}`` (body frame)
/lidar_points      usvdrake.RangeImage     message encoding ``usvdrake/range-image-v1`` (not
                                           JSON: a VLP-16 sweep is 16 × 1800 ranges at 10 Hz):
                                           a JSON header ``{"t", "timestamp", "frame_id",
                                           "sweep_time", "motion_applied", "rings", "columns",
                                           "elevations", "azimuth_start", "azimuth_step",
                                           "column_time_start", "column_time_step",
                                           "range_step", "filter"}`` (``azimuths`` /
                                           ``column_time`` listed instead when not evenly
                                           spaced), a newline, then the range image as uint16
                                           codes of 2 mm (error ≤ 1 mm; 0xFFFF: no return or
                                           beyond 131.068 m), differenced along the rings,
                                           byte planes, zlib; decoded by
                                           :func:`decode_cloud` (points on the nominal beam
                                           directions). The schema describes the header
================== ======================= ====================================================

Times: a message's log time is the time it describes — the sample time for vectors, the
message's own ``time`` for sensor messages (a scan's last beam) — and its publish time the
recorder's clock when it was written; both in ns of the run's clock (simulation time, or the
host clock on hardware). ``timestamp`` fields are the same time as ``{sec, nsec}``.

Crash safety: the file is written without chunks (one MCAP record per message) and flushed to
the operating system whenever the log time or the wall clock has advanced by ``flush_period``
(0.5 s) since the last flush, and by a background timer when nothing is written; a killed
process therefore loses at most the last second (the OS is not asked to fsync: a power cut
may lose more). A file that was never finished (no footer) is
still read: :func:`read_mission_log` streams the records and stops at the first incomplete one;
:func:`log_summary` says whether the footer is there.

API: :class:`MissionLogWriter` (``write_state``, ``write_vector``, ``write_pose``,
``write_scan``, ``write_gps``, ``write_imu``, ``write_cloud``; ``flush``, ``close``);
:class:`MissionRecorder`, a LeafSystem writing a list of :class:`RecordedPort` with publish
events; :func:`add_mission_recorder` (what ``run_mission`` and the hardware-in-the-loop runner
call: records whichever of :data:`MISSION_PORTS` a system has); :func:`read_mission_log`,
:func:`read_log_scans`, :func:`read_log_states`, :func:`read_log_vectors`, :func:`log_summary`.

Logs written before this encoding (``usvdrake/state-v1``, ``usvdrake/laserscan-v1``) are still
read by the same functions.
"""

import json
import math
import threading
import time
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem, PortDataType

from usvdrake.logs.rosbag import BagScan
from usvdrake.sensors.lidar3d import range_image_to_cloud
from usvdrake.sensors.messages import GpsFix, ImuSample, LaserScan, PointCloud

# --- the encodings of earlier logs (read only) -------------------------------------------------
STATE_ENCODING = "usvdrake/state-v1"
SCAN_ENCODING = "usvdrake/laserscan-v1"

STATE_NAMES = ("x", "y", "psi", "u", "v", "r")
STATE_SCHEMA = "usvdrake.VesselState"
VECTOR_SCHEMA_PREFIX = "usvdrake.Vector."
POSE_SCHEMA = "foxglove.PoseInFrame"
SCAN_SCHEMA = "foxglove.LaserScan"
GPS_SCHEMA = "foxglove.LocationFix"
NO_FIX_SCHEMA = "usvdrake.GpsNoFix"
IMU_SCHEMA = "usvdrake.Imu"
CLOUD_SCHEMA = "usvdrake.RangeImage"
CLOUD_ENCODING = "usvdrake/range-image-v1"  # binary: JSON header, newline, zlib body

# --- JSON schemas -----------------------------------------------------------------------------
_NUM = {"type": "number"}
_TIME = {
    "type": "object",
    "title": "time",
    "properties": {
        "sec": {"type": "integer", "minimum": 0},
        "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999},
    },
    "required": ["sec", "nsec"],
}
_VEC3 = {
    "title": "foxglove.Vector3",
    "type": "object",
    "properties": {"x": _NUM, "y": _NUM, "z": _NUM},
    "required": ["x", "y", "z"],
}
_QUAT = {
    "title": "foxglove.Quaternion",
    "type": "object",
    "properties": {"x": _NUM, "y": _NUM, "z": _NUM, "w": _NUM},
    "required": ["x", "y", "z", "w"],
}
_POSE = {
    "title": "foxglove.Pose",
    "type": "object",
    "properties": {"position": _VEC3, "orientation": _QUAT},
    "required": ["position", "orientation"],
}
_NUMBERS = {"type": "array", "items": _NUM}


def _object(title: str, properties: dict, required: Sequence[str], description: str) -> dict:
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": title,
        "description": description,
        "type": "object",
        "properties": properties,
        "required": list(required),
    }


def state_schema() -> dict:
    return _object(
        STATE_SCHEMA,
        {"t": _NUM, **{n: _NUM for n in STATE_NAMES}},
        ("t", *STATE_NAMES),
        "Vessel state [x y psi u v r]: world ENU position [m], heading [rad], body velocities "
        "[m/s, m/s, rad/s]",
    )


def vector_schema(name: str, names: Sequence[str]) -> dict:
    return _object(
        VECTOR_SCHEMA_PREFIX + name,
        {"t": _NUM, **{n: _NUM for n in names}},
        ("t", *names),
        f"The vector {name!r}, one named field per entry in order: {', '.join(names)}",
    )


def pose_schema() -> dict:
    return _object(
        POSE_SCHEMA,
        {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "pose": _POSE,
            "t": _NUM,
            "x": _NUM,
            "y": _NUM,
            "psi": _NUM,
        },
        ("timestamp", "frame_id", "pose"),
        "A timestamped planar pose (yaw-only quaternion); t, x, y, psi repeat it for plotting",
    )


def scan_schema() -> dict:
    return _object(
        SCAN_SCHEMA,
        {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "pose": _POSE,
            "start_angle": _NUM,
            "end_angle": _NUM,
            "ranges": _NUMBERS,
            "intensities": _NUMBERS,
            "t": _NUM,
            "angle_increment": _NUM,
            "range_min": _NUM,
            "range_max": _NUM,
            "scan_time": _NUM,
        },
        ("timestamp", "frame_id", "pose", "start_angle", "end_angle", "ranges", "intensities"),
        "A single scan from a planar laser range-finder; a range of 0 is a beam without return",
    )


def gps_schema() -> dict:
    return _object(
        GPS_SCHEMA,
        {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "latitude": _NUM,
            "longitude": _NUM,
            "altitude": _NUM,
            "position_covariance": {**_NUMBERS, "minItems": 9, "maxItems": 9},
            "position_covariance_type": {"type": "integer", "enum": [0, 1, 2, 3]},
            "metadata": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {"key": {"type": "string"}, "value": {"type": "string"}},
                    "required": ["key", "value"],
                },
            },
            "t": _NUM,
            "hdop": _NUM,
            "satellites": {"type": "integer"},
            "speed": _NUM,
            "course": _NUM,
        },
        (
            "timestamp",
            "frame_id",
            "latitude",
            "longitude",
            "altitude",
            "position_covariance",
            "position_covariance_type",
            "metadata",
        ),
        "A GNSS fix (WGS84); covariance in ENU [m^2] about the reported position",
    )


def no_fix_schema() -> dict:
    return _object(
        NO_FIX_SCHEMA,
        {"t": _NUM, "timestamp": _TIME, "hdop": _NUM, "satellites": {"type": "integer"}},
        ("t", "timestamp", "hdop", "satellites"),
        "The GNSS receiver reported no valid fix",
    )


def imu_schema() -> dict:
    return _object(
        IMU_SCHEMA,
        {
            "t": _NUM,
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "angular_velocity": _VEC3,
            "linear_acceleration": _VEC3,
            "orientation": _QUAT,
        },
        ("t", "timestamp", "angular_velocity", "linear_acceleration", "orientation"),
        "One IMU sample in the body frame (x forward, y left, z up): rad/s, m/s^2 specific "
        "force, orientation quaternion",
    )


# --- encoders and decoders --------------------------------------------------------------------
def _ns(t: float) -> int:
    return max(int(round(t * 1e9)), 0)


def _stamp(t: float) -> dict:
    ns = _ns(t)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _yaw_quaternion(psi: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": math.sin(psi / 2), "w": math.cos(psi / 2)}


def _json(obj: dict) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()


def _finite(v: float) -> float:
    v = float(v)
    return v if math.isfinite(v) else 0.0


def encode_state(t: float, q) -> bytes:
    return _json({"t": float(t), **{n: float(v) for n, v in zip(STATE_NAMES, q, strict=True)}})


def encode_vector(t: float, values, names: Sequence[str]) -> bytes:
    return _json({"t": float(t), **{n: float(v) for n, v in zip(names, values, strict=True)}})


def encode_pose(t: float, pose, frame_id: str = "world") -> bytes:
    x, y, psi = (float(v) for v in pose[:3])
    return _json(
        {
            "timestamp": _stamp(t),
            "frame_id": frame_id,
            "pose": {"position": {"x": x, "y": y, "z": 0.0}, "orientation": _yaw_quaternion(psi)},
            "t": float(t),
            "x": x,
            "y": y,
            "psi": psi,
        }
    )


def encode_scan(scan: LaserScan, frame_id: str = "lidar") -> bytes:
    """``foxglove.LaserScan`` JSON; beams without a return (not ``valid``) are written as 0."""
    r = np.asarray(scan.ranges, float)
    valid = np.asarray(scan.valid, bool) if len(scan.valid) == len(r) else np.isfinite(r)
    r = np.where(valid & np.isfinite(r), np.round(r, 5), 0.0)
    n = len(r)
    return _json(
        {
            "timestamp": _stamp(scan.time),
            "frame_id": frame_id,
            "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": _yaw_quaternion(0)},
            "start_angle": float(scan.angle_min),
            "end_angle": float(scan.angle_min + scan.angle_increment * max(n - 1, 0)),
            "ranges": r.tolist(),
            "intensities": [],
            "t": float(scan.time),
            "angle_increment": float(scan.angle_increment),
            "range_min": float(scan.range_min),
            "range_max": _finite(scan.range_max),
            "scan_time": float(scan.scan_time),
            "time_increment": float(scan.time_increment),
        }
    )


def _decode_scan_v1(data: bytes) -> LaserScan:
    head_raw, _, body = data.partition(b"\n")
    head = json.loads(head_raw)
    r = np.frombuffer(body, "<f4", count=head["n"]).astype(float)
    return LaserScan(
        time=head["t"],
        angle_min=head["angle_min"],
        angle_increment=head["angle_increment"],
        range_min=head["range_min"],
        range_max=head["range_max"],
        scan_time=head["scan_time"],
        time_increment=head.get("time_increment", 0.0),
        ranges=r,
        valid=np.isfinite(r),
    )


def _time_of(m: dict) -> float:
    if "t" in m:
        return float(m["t"])
    s = m.get("timestamp", {})
    return s.get("sec", 0) + s.get("nsec", 0) * 1e-9


def decode_scan(data: bytes) -> LaserScan:
    """A scan of either encoding (``foxglove.LaserScan`` JSON, or ``usvdrake/laserscan-v1``).
    Ranges of 0, below ``range_min`` or beyond ``range_max`` become ``inf`` / not valid."""
    if b"\n" in data:  # v1: JSON head, newline, float32 body (the JSON encoders write no newline)
        return _decode_scan_v1(data)
    m = json.loads(data)
    r = np.asarray(m["ranges"], float)
    n = len(r)
    inc = m.get("angle_increment")
    if inc is None:
        inc = (m["end_angle"] - m["start_angle"]) / (n - 1) if n > 1 else 0.0
    range_min = float(m.get("range_min", 0.0))
    range_max = float(m.get("range_max", 0.0)) or np.inf
    valid = np.isfinite(r) & (r > 0) & (r >= range_min) & (r <= range_max)
    return LaserScan(
        time=_time_of(m),
        angle_min=float(m["start_angle"]),
        angle_increment=float(inc),
        range_min=range_min,
        range_max=float(m.get("range_max", 0.0)),
        scan_time=float(m.get("scan_time", 0.0)),
        time_increment=float(m.get("time_increment", 0.0)),
        ranges=np.where(valid, r, np.inf),
        valid=valid,
    )


def encode_gps(fix: GpsFix, frame_id: str = "gps") -> bytes:
    if not fix.valid:
        return _json(
            {
                "t": float(fix.time),
                "timestamp": _stamp(fix.time),
                "hdop": _finite(fix.hdop),
                "satellites": int(fix.satellites),
            }
        )
    cov = np.asarray(fix.covariance_enu, float).reshape(3, 3)
    return _json(
        {
            "timestamp": _stamp(fix.time),
            "frame_id": frame_id,
            "latitude": float(fix.latitude),
            "longitude": float(fix.longitude),
            "altitude": float(fix.altitude),
            "position_covariance": [_finite(c) for c in cov.ravel()],
            "position_covariance_type": 3,
            "metadata": [],
            "t": float(fix.time),
            "hdop": _finite(fix.hdop),
            "satellites": int(fix.satellites),
            "speed": _finite(fix.speed),
            "course": _finite(fix.course),
        }
    )


def decode_gps(data: bytes) -> GpsFix:
    m = json.loads(data)
    if "latitude" not in m:
        return GpsFix(
            time=_time_of(m), valid=False, hdop=m.get("hdop", 99.0), satellites=m["satellites"]
        )
    return GpsFix(
        time=_time_of(m),
        valid=True,
        latitude=m["latitude"],
        longitude=m["longitude"],
        altitude=m["altitude"],
        covariance_enu=np.asarray(m["position_covariance"], float).reshape(3, 3),
        hdop=m.get("hdop", 99.0),
        satellites=m.get("satellites", 0),
        speed=m.get("speed", 0.0),
        course=m.get("course", 0.0),
    )


def encode_imu(sample: ImuSample, frame_id: str = "imu") -> bytes:
    w = [float(v) for v in sample.angular_velocity]
    a = [float(v) for v in sample.linear_acceleration]
    q = [float(v) for v in sample.orientation]
    return _json(
        {
            "t": float(sample.time),
            "timestamp": _stamp(sample.time),
            "frame_id": frame_id,
            "angular_velocity": dict(zip("xyz", w, strict=True)),
            "linear_acceleration": dict(zip("xyz", a, strict=True)),
            "orientation": dict(zip("xyzw", q, strict=True)),
        }
    )


def decode_imu(data: bytes) -> ImuSample:
    m = json.loads(data)
    return ImuSample(
        time=_time_of(m),
        angular_velocity=np.array([m["angular_velocity"][k] for k in "xyz"]),
        linear_acceleration=np.array([m["linear_acceleration"][k] for k in "xyz"]),
        orientation=np.array([m["orientation"][k] for k in "xyzw"]),
    )


# --- point clouds: a quantised, compressed range image ----------------------------------------
RANGE_STEP = 0.002  # [m] range quantum of the cloud encoding
NO_RETURN = 0xFFFF  # the uint16 code of a pixel without return
RANGE_LIMIT = (NO_RETURN - 1) * RANGE_STEP  # [m] 131.068: farther returns are written as none
CLOUD_FILTER = "delta-byteplanes"  # how the codes are laid out before zlib (see cloud_schema)
_UNIFORM_TOL = 1e-9  # [rad] / [s]: azimuths and column times this close to a line are a line


def cloud_schema() -> dict:
    """The JSON Schema of a cloud message's *header* (the body that follows it is binary)."""
    return _object(
        CLOUD_SCHEMA,
        {
            "t": _NUM,
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "sweep_time": _NUM,
            "motion_applied": {"type": "boolean"},
            "rings": {"type": "integer", "minimum": 0},
            "columns": {"type": "integer", "minimum": 0},
            "elevations": _NUMBERS,
            "azimuth_start": _NUM,
            "azimuth_step": _NUM,
            "azimuths": _NUMBERS,
            "column_time_start": _NUM,
            "column_time_step": _NUM,
            "column_time": _NUMBERS,
            "range_step": _NUM,
            "filter": {"type": "string", "enum": [CLOUD_FILTER]},
        },
        ("t", "sweep_time", "motion_applied", "rings", "columns", "elevations", "range_step"),
        "A lidar sweep as a range image (message encoding usvdrake/range-image-v1): this JSON "
        "header, one newline, then zlib(uint16 range codes, rings x columns row-major, each "
        "ring's codes as differences mod 2^16 from the previous column (the first from 0), "
        "stored as all high bytes then all low bytes): range = code * range_step [m], "
        "0xFFFF = no return. Azimuths [rad] / column times [s] are start + step * column, "
        "or listed when not evenly spaced",
    )


def _line(values: np.ndarray) -> tuple[float, float] | None:
    """(start, step) if ``values`` are evenly spaced (within :data:`_UNIFORM_TOL`), else None."""
    v = np.asarray(values, float)
    if len(v) == 0 or not np.all(np.isfinite(v)):
        return None
    start = float(v[0])
    step = float((v[-1] - v[0]) / (len(v) - 1)) if len(v) > 1 else 0.0
    fit = start + step * np.arange(len(v))
    return (start, step) if np.max(np.abs(fit - v)) <= _UNIFORM_TOL else None


def cloud_column_time(cloud: PointCloud) -> np.ndarray:
    """The time offset [s] of each column of ``cloud``: the mean ``point_time`` of the column's
    points (all equal in a :class:`~usvdrake.sensors.lidar3d.Lidar3D` sweep), linearly
    interpolated over the columns without points; zeros if the cloud has no point times."""
    n = np.shape(cloud.range_image)[1] if np.ndim(cloud.range_image) == 2 else 0
    col = np.asarray(cloud.column, int)
    pt = np.asarray(cloud.point_time, float)
    if n == 0 or len(col) == 0 or len(pt) != len(col):
        return np.zeros(n)
    count = np.bincount(col, minlength=n)
    total = np.bincount(col, weights=pt, minlength=n)
    have = count > 0
    out = np.zeros(n)
    out[have] = total[have] / count[have]
    if not have.all():
        k = np.arange(n)
        out[~have] = np.interp(k[~have], k[have], out[have])
    return out


def quantise_ranges(range_image: np.ndarray) -> np.ndarray:
    """uint16 codes of a range image [m]: round(r / :data:`RANGE_STEP`), so the decoded range
    ``code * RANGE_STEP`` is within RANGE_STEP / 2 = 1 mm of r (plus float rounding, < 1e-12
    m); no return (inf, NaN, r ≤ 0) and r beyond :data:`RANGE_LIMIT` (131.068 m) → 0xFFFF."""
    r = np.asarray(range_image, float)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        q = np.rint(r / RANGE_STEP)
        ok = np.isfinite(q) & (r > 0) & (q < NO_RETURN)
    return np.where(ok, q, NO_RETURN).astype(np.uint16)


def encode_cloud(cloud: PointCloud, frame_id: str = "lidar") -> bytes:
    """A :class:`PointCloud` as one ``usvdrake/range-image-v1`` message (:func:`cloud_schema`):
    a JSON header (time, sweep time, motion flag, ring elevations, column azimuths and firing
    times, as start + step when evenly spaced) and the range image quantised by
    :func:`quantise_ranges` (2 mm steps: error ≤ 1 mm; beyond 131.068 m: no return),
    differenced along each ring, split into byte planes and zlib-compressed (a VLP-16 sweep of
    17 000 returns: ≈ 3 kB noise-free, ≈ 19 kB with 3 cm range noise). Only the range image is
    stored: the decoded points lie on the nominal beam directions (ring elevation, column
    azimuth), and each point's time is its column's time (:func:`cloud_column_time`)."""
    img = np.asarray(cloud.range_image, float)
    if img.ndim != 2:
        img = np.zeros((len(cloud.elevations), len(cloud.azimuths)))
    rings, columns = img.shape
    codes = quantise_ranges(img)
    delta = np.diff(codes, axis=1, prepend=np.uint16(0)).astype("<u2")  # mod 2^16 along rings
    planes = delta.view(np.uint8).reshape(-1, 2)  # little-endian: [low, high] per code
    body = zlib.compress(np.concatenate([planes[:, 1], planes[:, 0]]).tobytes(), 6)
    head = {
        "t": float(cloud.time),
        "timestamp": _stamp(cloud.time),
        "frame_id": frame_id,
        "sweep_time": float(cloud.sweep_time),
        "motion_applied": bool(cloud.motion_applied),
        "rings": rings,
        "columns": columns,
        "elevations": [float(e) for e in np.asarray(cloud.elevations, float)],
        "range_step": RANGE_STEP,
        "filter": CLOUD_FILTER,
    }
    for name, values in (
        ("azimuth", np.asarray(cloud.azimuths, float)),
        ("column_time", cloud_column_time(cloud)),
    ):
        line = _line(values) if len(values) == columns else None
        if line is not None:
            head[f"{name}_start"], head[f"{name}_step"] = line
        else:
            head["azimuths" if name == "azimuth" else name] = [float(v) for v in values]
    return _json(head) + b"\n" + body


def _spaced(head: dict, name: str, listed: str, n: int) -> np.ndarray:
    if listed in head:
        return np.asarray(head[listed], float)
    return head[f"{name}_start"] + head[f"{name}_step"] * np.arange(n)


def decode_cloud(data: bytes) -> PointCloud:
    """The :class:`PointCloud` of an :func:`encode_cloud` message, rebuilt from its range
    image by :func:`~usvdrake.sensors.lidar3d.range_image_to_cloud` (no return: inf)."""
    head_raw, _, body = bytes(data).partition(b"\n")
    head = json.loads(head_raw)
    rings, columns = int(head["rings"]), int(head["columns"])
    if head.get("filter") != CLOUD_FILTER:
        raise ValueError(f"cloud message: unknown filter {head.get('filter')!r}")
    raw = np.frombuffer(zlib.decompress(body), np.uint8)
    high, low = raw[: rings * columns], raw[rings * columns :]
    delta = ((high.astype(np.uint16) << 8) | low).reshape(rings, columns)
    codes = np.cumsum(delta, axis=1, dtype=np.uint16)  # wraps mod 2^16: undoes the delta
    ranges = np.where(codes == NO_RETURN, np.inf, codes * float(head["range_step"]))
    return range_image_to_cloud(
        ranges,
        _spaced(head, "azimuth", "azimuths", columns),
        np.asarray(head["elevations"], float),
        _spaced(head, "column_time", "column_time", columns),
        float(head["t"]),
        float(head["sweep_time"]),
        bool(head["motion_applied"]),
    )


# --- writing ----------------------------------------------------------------------------------
class MissionLogWriter:
    """An MCAP mission log being written: channels are registered on first use, each message is
    one record, and the file is flushed to the OS every ``flush_period`` of log or wall time (a
    background thread covers quiet periods). ``close()`` (or ``with``) writes the summary and
    footer; until then the file is readable by :func:`read_mission_log` as far as it got."""

    def __init__(self, path: str | Path, flush_period: float = 0.5, profile: str = "usvdrake"):
        from mcap.writer import Writer

        self.path = Path(path)
        self.flush_period = float(flush_period)
        self._file = open(self.path, "wb")  # noqa: SIM115 - closed by close()
        self._writer = Writer(self._file, use_chunking=False)
        self._writer.start(profile=profile, library="usvdrake")
        self._lock = threading.Lock()
        self._channels: dict[str, int] = {}
        self._dirty = False
        self._closed = False
        self._last_flush_wall = time.monotonic()
        self._last_flush_log: float | None = None
        self._max_log = -math.inf
        self._file.flush()
        self._stop = threading.Event()
        self._timer = threading.Thread(target=self._flush_loop, name="mcap-flush", daemon=True)
        self._timer.start()

    # channels
    def channel(self, topic: str, schema: dict, message_encoding: str = "json") -> int:
        """The channel id of ``topic`` (messages of ``schema``, a JSON Schema, in
        ``message_encoding``; registered on first use)."""
        ch = self._channels.get(topic)
        if ch is None:
            with self._lock:
                ch = self._channels.get(topic)
                if ch is None:
                    schema_id = self._writer.register_schema(
                        name=schema["title"], encoding="jsonschema", data=_json(schema)
                    )
                    ch = self._writer.register_channel(topic, message_encoding, schema_id)
                    self._channels[topic] = ch
                    self._dirty = True
        return ch

    @property
    def state_channel(self) -> int:
        """``/ground_truth`` (kept from the first version's API)."""
        return self.channel("/ground_truth", state_schema())

    @property
    def scan_channel(self) -> int:
        """``/lidar_scan`` (kept from the first version's API)."""
        return self.channel("/lidar_scan", scan_schema())

    # messages
    def write(self, channel: int, t: float, data: bytes, publish_time: float | None = None) -> None:
        """One message of log time ``t`` [s] (and ``publish_time``, default ``t``)."""
        ns = _ns(t)
        pub = ns if publish_time is None else _ns(publish_time)
        with self._lock:
            if self._closed:
                raise ValueError(f"{self.path}: the mission log is closed")
            self._writer.add_message(channel_id=channel, log_time=ns, data=data, publish_time=pub)
            self._dirty = True
            self._max_log = max(self._max_log, t)
            now = time.monotonic()
            if (
                self._last_flush_log is None
                or self._max_log - self._last_flush_log >= self.flush_period
                or now - self._last_flush_wall >= self.flush_period
            ):
                self._flush_locked(now)

    def write_state(self, topic: str, t: float, q, publish_time: float | None = None) -> None:
        self.write(self.channel(topic, state_schema()), t, encode_state(t, q), publish_time)

    def write_vector(
        self,
        topic: str,
        t: float,
        values,
        names: Sequence[str] | None = None,
        schema_name: str | None = None,
        publish_time: float | None = None,
    ) -> None:
        names = tuple(names) if names else vector_names(len(values))
        ch = self._channels.get(topic)
        if ch is None:
            ch = self.channel(topic, vector_schema(schema_name or topic.strip("/"), names))
        self.write(ch, t, encode_vector(t, values, names), publish_time)

    def write_pose(
        self,
        topic: str,
        t: float,
        pose,
        frame_id: str = "world",
        publish_time: float | None = None,
    ) -> None:
        self.write(
            self.channel(topic, pose_schema()), t, encode_pose(t, pose, frame_id), publish_time
        )

    def write_scan(
        self,
        topic: str,
        scan: LaserScan,
        frame_id: str = "lidar",
        publish_time: float | None = None,
    ) -> None:
        ch = self.channel(topic, scan_schema())
        self.write(ch, scan.time, encode_scan(scan, frame_id), publish_time)

    def write_gps(
        self, topic: str, fix: GpsFix, frame_id: str = "gps", publish_time: float | None = None
    ) -> None:
        if fix.valid:
            ch = self.channel(topic, gps_schema())
        else:
            ch = self.channel(topic.rstrip("/") + "/no_fix", no_fix_schema())
        self.write(ch, fix.time, encode_gps(fix, frame_id), publish_time)

    def write_imu(
        self,
        topic: str,
        sample: ImuSample,
        frame_id: str = "imu",
        publish_time: float | None = None,
    ) -> None:
        ch = self.channel(topic, imu_schema())
        self.write(ch, sample.time, encode_imu(sample, frame_id), publish_time)

    def write_cloud(
        self,
        topic: str,
        cloud: PointCloud,
        frame_id: str = "lidar",
        publish_time: float | None = None,
    ) -> None:
        """One sweep as a ``usvdrake/range-image-v1`` message (:func:`encode_cloud`)."""
        ch = self.channel(topic, cloud_schema(), CLOUD_ENCODING)
        self.write(ch, cloud.time, encode_cloud(cloud, frame_id), publish_time)

    # flushing and closing
    def _flush_locked(self, now: float | None = None) -> None:
        self._file.flush()
        self._dirty = False
        self._last_flush_wall = time.monotonic() if now is None else now
        if self._max_log > -math.inf:
            self._last_flush_log = self._max_log

    def flush(self) -> None:
        """Hand everything written so far to the operating system (no fsync)."""
        with self._lock:
            if not self._closed:
                self._flush_locked()

    def _flush_loop(self) -> None:
        while not self._stop.wait(self.flush_period / 2):
            with self._lock:
                if self._closed:
                    return
                if (
                    self._dirty
                    and time.monotonic() - self._last_flush_wall >= self.flush_period / 2
                ):
                    self._flush_locked()

    @property
    def closed(self) -> bool:
        return self._closed

    def close(self) -> None:
        """Write the summary and footer and close the file (idempotent)."""
        self._stop.set()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            self._writer.finish()
            self._file.close()
        if self._timer is not threading.current_thread():
            self._timer.join(timeout=1.0)

    def __enter__(self) -> "MissionLogWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def vector_names(n: int, prefix: str = "v") -> tuple[str, ...]:
    return tuple(f"{prefix}{i}" for i in range(n))


# --- the recorder system ----------------------------------------------------------------------
KINDS = ("state", "vector", "pose", "scan", "gps", "imu", "cloud")
_MESSAGES = {"scan": LaserScan, "gps": GpsFix, "imu": ImuSample, "cloud": PointCloud}


@dataclass(frozen=True)
class RecordedPort:
    """One input of a :class:`MissionRecorder`, written to ``topic``.

    ``kind``: ``state`` (6-vector [x y ψ u v r]), ``vector`` (named fields ``names``, default
    ``v0, v1, ...``), ``pose`` (first three entries [x y ψ] as ``foxglove.PoseInFrame``) — all
    sampled every ``1 / rate_hz`` s (default: the recorder's rate) — or ``scan`` / ``gps`` /
    ``imu`` / ``cloud`` (abstract :class:`LaserScan` / :class:`GpsFix` / :class:`ImuSample` /
    :class:`PointCloud` ports: each new message, told by its ``time`` and content, is written
    once; checked after every simulator step, or every ``1 / rate_hz`` s if given). ``port``
    names the recorder's input port.
    """

    port: str
    topic: str
    kind: str = "vector"
    size: int = 0  # vector kinds: the input's size (0: infer from ``names``, or 6 for "state")
    names: tuple[str, ...] = ()
    rate_hz: float | None = None
    frame_id: str = ""

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"RecordedPort {self.port!r}: kind {self.kind!r} not in {KINDS}")

    @property
    def vector_size(self) -> int:
        if self.kind == "state":
            return 6
        return self.size or len(self.names)


def _message_key(kind: str, msg) -> tuple:
    """What tells one sensor message from the next (the time, and enough content to tell a
    default message from the first real one stamped at the same time)."""
    if kind == "scan":
        r = np.asarray(msg.ranges)
        return (msg.time, len(r), float(np.sum(r[np.isfinite(r)])) if len(r) else 0.0)
    if kind == "gps":
        return (msg.time, bool(msg.valid), msg.latitude, msg.longitude, msg.satellites)
    if kind == "cloud":  # one sum over the returns' x per step: cheap beside the sweep
        pts = np.asarray(msg.points)
        return (
            msg.time,
            np.shape(msg.range_image),
            len(pts),
            float(pts[:, 0].sum()) if len(pts) else 0.0,
        )
    return (
        msg.time,
        tuple(np.asarray(msg.angular_velocity, float)),
        tuple(np.asarray(msg.linear_acceleration, float)),
    )


def _is_placeholder(kind: str, msg) -> bool:
    """The message a sensor port holds before its first measurement (time 0, nothing in it)."""
    if msg.time != 0.0:
        return False
    if kind == "scan":
        return not np.any(msg.valid)
    if kind == "gps":
        return not msg.valid and msg.satellites == 0
    if kind == "cloud":
        return not np.isfinite(np.asarray(msg.range_image, float)).any()
    return not np.any(msg.angular_velocity) and not np.any(msg.linear_acceleration)


def _legacy_ports(scan_period) -> list[RecordedPort]:
    ports = [RecordedPort("ground_truth_state", "/ground_truth", "state")]
    if scan_period is not None:
        ports.append(RecordedPort("lidar_scan", "/lidar_scan", "scan"))
    return ports


class MissionRecorder(LeafSystem):
    """Writes its inputs to a :class:`MissionLogWriter` with publish events (the file is an
    output, like Meshcat, not simulation state): vector inputs every ``1 / rate_hz`` s from
    t = 0, sensor messages each once when a new one appears (see :class:`RecordedPort`).

    .. pydrake_system::

        name: MissionRecorder
        input_ports:
        - <port of each RecordedPort>

    Without ``ports`` (the first version's ``MissionRecorder(writer, rate_hz=...,
    scan_period=...)``) it records ``ground_truth_state`` and, with a ``scan_period``,
    ``lidar_scan``.
    """

    def __init__(
        self,
        writer: MissionLogWriter,
        ports: Sequence[RecordedPort] | None = None,
        rate_hz: float = 10.0,
        scan_period: float | None = None,
    ):
        super().__init__()
        if ports is None:
            ports = _legacy_ports(scan_period)
        self._writer = writer
        self._ports = list(ports)
        self._last: dict[str, tuple] = {}
        if len({p.port for p in self._ports}) != len(self._ports):
            raise ValueError("MissionRecorder: two RecordedPorts share an input port name")
        per_step = []
        for p in self._ports:
            if p.kind in _MESSAGES:
                port = self.DeclareAbstractInputPort(
                    p.port, AbstractValue.Make(_MESSAGES[p.kind]())
                )
                if p.rate_hz:
                    self.DeclarePeriodicPublishEvent(
                        1.0 / p.rate_hz, 0.0, self._publisher(self._write_message, p, port)
                    )
                else:
                    per_step.append((p, port))
            else:
                n = p.vector_size
                if n <= 0:
                    raise ValueError(f"RecordedPort {p.port!r}: give its size or names")
                port = self.DeclareVectorInputPort(p.port, n)
                period = 1.0 / (p.rate_hz or rate_hz)
                self.DeclarePeriodicPublishEvent(
                    period, 0.0, self._publisher(self._write_vector, p, port)
                )
        if per_step:
            self._per_step = per_step

            def on_step(context):
                for p, port in self._per_step:
                    self._write_message(context, p, port)

            self.DeclarePerStepPublishEvent(on_step)

    @property
    def recorded_ports(self) -> list[RecordedPort]:
        return list(self._ports)

    @staticmethod
    def _publisher(fn, p, port):
        return lambda context: fn(context, p, port)

    def _write_vector(self, context, p: RecordedPort, port) -> None:
        w = self._writer
        if w.closed:
            return
        v = port.Eval(context)
        t = context.get_time()
        if p.kind == "state":
            w.write_state(p.topic, t, v)
        elif p.kind == "pose":
            w.write_pose(p.topic, t, v, p.frame_id or "world")
        else:
            names = p.names if len(p.names) == len(v) else vector_names(len(v))
            w.write_vector(p.topic, t, v, names, schema_name=p.port)

    def _write_message(self, context, p: RecordedPort, port) -> None:
        w = self._writer
        if w.closed:
            return
        msg = port.Eval(context)
        key = _message_key(p.kind, msg)
        if self._last.get(p.port) == key:
            return
        self._last[p.port] = key
        if _is_placeholder(p.kind, msg):
            return
        if p.kind == "scan":
            w.write_scan(p.topic, msg, p.frame_id or "lidar", context.get_time())
        elif p.kind == "gps":
            w.write_gps(p.topic, msg, p.frame_id or "gps", context.get_time())
        elif p.kind == "cloud":
            w.write_cloud(p.topic, msg, p.frame_id or "lidar", context.get_time())
        else:
            w.write_imu(p.topic, msg, p.frame_id or "imu", context.get_time())


# What :func:`add_mission_recorder` records of a vessel (or hardware-in-the-loop) diagram, when
# the diagram has the output port: (port, topic, kind, field names).
MISSION_PORTS: tuple[tuple[str, str, str, tuple[str, ...]], ...] = (
    ("ground_truth_state", "/ground_truth", "state", ()),  # simulation only
    ("state_estimate", "/state_estimate", "state", ()),
    ("thruster_command", "/thruster_command", "vector", ()),
    ("thrust_applied", "/thrust_applied", "vector", ()),
    ("thrust_measured", "/thrust_measured", "vector", ()),
    ("pose_measurement", "/pose_measurement", "vector", ("x", "y", "psi", "r")),
    ("reference", "/reference", "vector", ("psi_d", "u_d", "e")),
    ("slam_pose", "/slam_pose", "pose", ()),
    ("lidar_scan", "/lidar_scan", "scan", ()),
    ("gps", "/gps", "gps", ()),
    ("imu", "/imu", "imu", ()),
    ("lidar_points", "/lidar_points", "cloud", ()),
)
_THRUST_PORTS = ("thruster_command", "thrust_applied", "thrust_measured")


def mission_ports(system, extra: Sequence[RecordedPort] = ()) -> list[RecordedPort]:
    """The :class:`RecordedPort` of every :data:`MISSION_PORTS` entry that ``system`` has as an
    output port (sizes and names from the port), then ``extra``."""
    out = []
    for name, topic, kind, names in MISSION_PORTS:
        if not system.HasOutputPort(name):
            continue
        port = system.GetOutputPort(name)
        if kind in _MESSAGES:
            if port.get_data_type() != PortDataType.kAbstractValued:
                continue
            out.append(RecordedPort(name, topic, kind))
            continue
        if port.get_data_type() != PortDataType.kVectorValued:
            continue
        n = port.size()
        if kind == "state" and n != 6:
            kind = "vector"
        if kind == "pose" and n < 3:
            kind = "vector"
        if kind == "vector" and len(names) != n:
            names = vector_names(n, "thruster_" if name in _THRUST_PORTS else "v")
        out.append(RecordedPort(name, topic, kind, size=n, names=tuple(names)))
    taken = {p.port for p in out}
    out += [p for p in extra if p.port not in taken]
    return out


def add_mission_recorder(
    builder,
    system,
    writer: MissionLogWriter,
    rate_hz: float = 10.0,
    extra: Sequence[RecordedPort] = (),
    name: str = "mission_recorder",
) -> MissionRecorder:
    """Add a :class:`MissionRecorder` to ``builder`` recording whichever of
    :data:`MISSION_PORTS` ``system`` (already in ``builder``) has as outputs — ground truth in
    simulation, inputs (sensor messages, measured thrust), outputs (thruster command, applied
    thrust) and estimates (state estimate, SLAM pose) — plus ``extra`` ports of ``system``,
    vectors at ``rate_hz``. Connects it and returns it."""
    ports = mission_ports(system, extra)
    recorder = builder.AddNamedSystem(name, MissionRecorder(writer, ports, rate_hz))
    for p in ports:
        builder.Connect(system.GetOutputPort(p.port), recorder.GetInputPort(p.port))
    return recorder


# --- reading ----------------------------------------------------------------------------------
def _iter_records(path: str | Path):
    """The records of an MCAP file, finished or not: stops quietly at the end of the last
    complete record of a file that was cut off (a crashed writer)."""
    import struct

    from mcap.exceptions import EndOfFile
    from mcap.stream_reader import StreamReader

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
    from mcap.records import Channel, Message, Schema

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
    from mcap.records import Channel, Footer, Message, Schema

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


def _state_row(m: dict) -> list[float]:
    return list(m["q"]) if "q" in m else [m[k] for k in STATE_NAMES]


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
            m = {"t": m["t"], **dict(zip(STATE_NAMES, m["q"], strict=True))}
        if names is None:
            skip = {"t", "timestamp", "frame_id", "pose"}
            names = [k for k in m if k not in skip and isinstance(m[k], int | float)]
        times.append(t)
        rows.append([m[k] for k in names])
    names = names or []
    return np.array(times), np.array(rows, float).reshape(len(times), len(names)), names
