"""The mission log's message codecs: bytes from and to the project's messages. JSON
encoders of states, named vectors, poses (``foxglove.PoseInFrame``), 2D scans
(``foxglove.LaserScan``), GPS fixes (``foxglove.LocationFix`` / ``usvdrake.GpsNoFix``) and IMU
samples, with the decoders of the sensor messages (scans of either encoding, GPS, IMU); and the
binary ``usvdrake/range-image-v1`` codec of 3D lidar sweeps (:func:`encode_cloud`,
:func:`decode_cloud`: a JSON header and a quantised, delta-filtered, zlib-compressed range
image), with its range quantum and limits. Also the shared helpers (log times in ns,
``{sec, nsec}`` stamps, compact JSON) the writer uses."""

import base64
import json
import math
import zlib
from collections.abc import Sequence

import numpy as np

from usvdrake.logs.mission_log.schema import CLOUD_FILTER, STATE_NAMES
from usvdrake.sensors.lidar3d import range_image_to_cloud
from usvdrake.sensors.messages import GpsFix, ImuSample, LaserScan, PointCloud


# --- encoders and decoders --------------------------------------------------------------------
def _ns(t: float) -> int:
    return max(int(round(t * 1e9)), 0)


def _stamp(t: float) -> dict:
    ns = _ns(t)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _yaw_quaternion(psi: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": math.sin(psi / 2), "w": math.cos(psi / 2)}


def _null_nonfinite(obj):
    """``obj`` with NaN and ±inf replaced by None (JSON null): JSON has no such numbers, and a
    value the simulation survives must not abort its log. Readers turn null back into NaN."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _null_nonfinite(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_null_nonfinite(v) for v in obj]
    return obj


def _json(obj: dict) -> bytes:
    try:  # the common case: every number finite
        return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode()
    except ValueError:
        return json.dumps(_null_nonfinite(obj), separators=(",", ":"), allow_nan=False).encode()


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


def encode_frame_transform(
    t: float, parent: str, child: str, x: float, y: float, z: float, yaw: float
) -> bytes:
    """``foxglove.FrameTransform`` JSON: ``child`` at (x, y, z) [m], rotated by ``yaw`` [rad]
    about z, in ``parent``."""
    return _json(
        {
            "timestamp": _stamp(t),
            "parent_frame_id": parent,
            "child_frame_id": child,
            "translation": {"x": float(x), "y": float(y), "z": float(z)},
            "rotation": _yaw_quaternion(float(yaw)),
        }
    )


def encode_hull_scene(
    t: float, length: float, beam: float, height: float, frame_id: str = "base_link"
) -> bytes:
    """``foxglove.SceneUpdate`` JSON: the hull as one cube entity (``hull``) of length × beam ×
    height [m] centred on ``frame_id`` (which it follows: ``frame_locked``), kept until
    replaced (``lifetime`` 0)."""
    cube = {
        "pose": {
            "position": {"x": 0.0, "y": 0.0, "z": 0.0},
            "orientation": _yaw_quaternion(0.0),
        },
        "size": {"x": float(length), "y": float(beam), "z": float(height)},
        "color": {"r": 0.95, "g": 0.55, "b": 0.1, "a": 0.8},
    }
    entity = {
        "timestamp": _stamp(t),
        "frame_id": frame_id,
        "id": "hull",
        "lifetime": {"sec": 0, "nsec": 0},
        "frame_locked": True,
        "metadata": [],
        "arrows": [],
        "cubes": [cube],
        "spheres": [],
        "cylinders": [],
        "lines": [],
        "triangles": [],
        "texts": [],
        "models": [],
    }
    return _json({"deletions": [], "entities": [entity]})


_FLOAT32 = 7  # foxglove.NumericType


def encode_point_cloud(cloud: PointCloud, frame_id: str = "lidar3d") -> bytes:
    """``foxglove.PointCloud`` JSON of a sweep's valid returns: little-endian float32 ``x, y,
    z`` [m] (sensor frame) and ``time`` [s from the sweep's start], 16 bytes a point, base64."""
    pts = np.asarray(cloud.points, float).reshape(-1, 3)
    pt = np.asarray(cloud.point_time, float)
    packed = np.zeros((len(pts), 4), "<f4")
    packed[:, :3] = pts
    if len(pt) == len(pts):
        packed[:, 3] = pt
    fields = [
        {"name": name, "offset": 4 * i, "type": _FLOAT32}
        for i, name in enumerate(("x", "y", "z", "time"))
    ]
    return _json(
        {
            "timestamp": _stamp(cloud.time),
            "frame_id": frame_id,
            "pose": {
                "position": {"x": 0.0, "y": 0.0, "z": 0.0},
                "orientation": _yaw_quaternion(0.0),
            },
            "point_stride": 16,
            "fields": fields,
            "data": base64.b64encode(packed.tobytes()).decode(),
        }
    )


def decode_point_cloud(data: bytes) -> np.ndarray:
    """The points (n × 4: x, y, z, time) of an :func:`encode_point_cloud` message."""
    m = json.loads(data)
    raw = np.frombuffer(base64.b64decode(m["data"]), "<f4")
    return raw.reshape(-1, 4).astype(float)


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
    t = float(sample.time)
    w = [float(v) for v in sample.angular_velocity]
    a = [float(v) for v in sample.linear_acceleration]
    q = [float(v) for v in sample.orientation]
    if len(w) == 3 and len(a) == 3 and len(q) == 4 and all(map(math.isfinite, [t, *w, *a, *q])):
        # written out (the log's most frequent message, 50-100 a second): the bytes json.dumps
        # gives, floats by their repr as json writes them (tests/test_mission_log.py)
        ns = _ns(t)
        return (
            f'{{"t":{t!r},"timestamp":{{"sec":{ns // 1_000_000_000},"nsec":'
            f'{ns % 1_000_000_000}}},"frame_id":{json.dumps(frame_id)},'
            f'"angular_velocity":{{"x":{w[0]!r},"y":{w[1]!r},"z":{w[2]!r}}},'
            f'"linear_acceleration":{{"x":{a[0]!r},"y":{a[1]!r},"z":{a[2]!r}}},'
            f'"orientation":{{"x":{q[0]!r},"y":{q[1]!r},"z":{q[2]!r},"w":{q[3]!r}}}}}'
        ).encode()
    return _encode_imu_json(t, w, a, q, frame_id)


def _encode_imu_json(t: float, w: list, a: list, q: list, frame_id: str) -> bytes:
    """:func:`encode_imu` through ``json`` (non-finite numbers become null)."""
    return _json(
        {
            "t": t,
            "timestamp": _stamp(t),
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
_UNIFORM_TOL = 1e-9  # [rad] / [s]: azimuths and column times this close to a line are a line


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
