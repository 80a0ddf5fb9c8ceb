"""The names and JSON Schemas of the mission log's channels: the message encodings
(``json``, ``usvdrake/range-image-v1``, and the read-only ``usvdrake/state-v1`` /
``usvdrake/laserscan-v1`` of earlier logs), the schema names (``foxglove.*``, ``usvdrake.*``),
the state's field names, and one function per schema returning the JSON Schema a channel is
registered with (:func:`state_schema`, :func:`vector_schema`, :func:`pose_schema`,
:func:`scan_schema`, :func:`gps_schema`, :func:`no_fix_schema`, :func:`imu_schema`, and
:func:`cloud_schema`, the header of a range-image message), and the Foxglove-only channels'
(:func:`frame_transform_schema`, :func:`scene_update_schema`, :func:`point_cloud_schema`). See
the package docstring for the table of topics, schemas and messages."""

from collections.abc import Sequence

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
CLOUD_FILTER = "delta-byteplanes"  # how the codes are laid out before zlib (see cloud_schema)
# Foxglove-only channels (the 3D panel's transform tree, vessel and cloud), official schemas
FRAME_TRANSFORM_SCHEMA = "foxglove.FrameTransform"
SCENE_UPDATE_SCHEMA = "foxglove.SceneUpdate"
POINT_CLOUD_SCHEMA = "foxglove.PointCloud"
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


# --- the Foxglove-only channels: our own JSON Schemas of what we write, under Foxglove's names
# (Foxglove picks the panel by the schema name; tests/test_foxglove_log.py validates every
# message against Foxglove's published schemas, which make test installs from npm)
_POSE = {
    "type": "object",
    "properties": {"position": _VEC3, "orientation": _QUAT},
    "required": ["position", "orientation"],
}


def _message(title: str, properties: dict, required=None) -> dict:
    return {
        "title": title,
        "type": "object",
        "properties": properties,
        "required": list(required if required is not None else properties),
    }


def frame_transform_schema() -> dict:
    return _message(
        FRAME_TRANSFORM_SCHEMA,
        {
            "timestamp": _TIME,
            "parent_frame_id": {"type": "string"},
            "child_frame_id": {"type": "string"},
            "translation": _VEC3,
            "rotation": _QUAT,
        },
    )


def scene_update_schema() -> dict:
    color = _message("foxglove.Color", {k: _NUM for k in "rgba"})
    cube = _message("foxglove.CubePrimitive", {"pose": _POSE, "size": _VEC3, "color": color})
    lists = ("metadata", "arrows", "spheres", "cylinders", "lines", "triangles", "texts", "models")
    entity = _message(
        "foxglove.SceneEntity",
        {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "id": {"type": "string"},
            "lifetime": _TIME,
            "frame_locked": {"type": "boolean"},
            "cubes": {"type": "array", "items": cube},
            **{k: {"type": "array"} for k in lists},
        },
    )
    return _message(
        SCENE_UPDATE_SCHEMA,
        {"deletions": {"type": "array"}, "entities": {"type": "array", "items": entity}},
    )


def point_cloud_schema() -> dict:
    field = _message(
        "foxglove.PackedElementField",
        {"name": {"type": "string"}, "offset": {"type": "integer"}, "type": {"type": "integer"}},
    )
    return _message(
        POINT_CLOUD_SCHEMA,
        {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "pose": _POSE,
            "point_stride": {"type": "integer", "minimum": 0},
            "fields": {"type": "array", "items": field},
            "data": {"type": "string", "contentEncoding": "base64"},
        },
    )
