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
Schema allows extra properties). Every ``foxglove.*`` message is valid against Foxglove's
published JSON Schema (``tests/test_foxglove_log.py`` checks it against ``@foxglove/schemas``,
which ``make test`` installs from npm); the channels are registered with our own schemas of
what we write, under Foxglove's names.

Foxglove's 3D panel: ``/tf`` connects the frames ``world`` → ``base_link`` → ``lidar``,
``lidar3d``, ``imu``, ``gps`` (the frame ids the sensor messages carry; a sensor frame is
there when the recorder knows its mount — :func:`add_mission_recorder` takes them from the
simulated sensors; a hardware log has ``world`` → ``base_link`` only), ``/vessel_pose`` and
``/vessel_hull`` draw the boat, ``/lidar_points_foxglove`` the 3D sweeps (a copy of a sweep
every second, not every sweep: ~0.4 MB each against ~20 kB as a range image).

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
/vessel_pose                               (yaw-only quaternion), plus ``t, x, y, psi``;
                                           ``/vessel_pose``: the pose of ``/tf``'s world →
                                           base_link, at the same times
/tf                foxglove.FrameTransform ``timestamp``, ``parent_frame_id``,
                                           ``child_frame_id``, ``translation``, ``rotation``
                                           (yaw-only): world → base_link at the recorder's
                                           rate from the ground truth (without it: the state
                                           estimate); once at the start, base_link → each
                                           sensor frame (the mount [x y z yaw]: lidar,
                                           lidar3d, imu at its lever arm, gps at its antenna
                                           height)
/vessel_hull       foxglove.SceneUpdate    once at the start: one entity ``hull`` (frame
                                           base_link, ``frame_locked``, lifetime 0) with one
                                           cube of the hull's length × beam × height
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
                                           a JSON header ``{"t", "timestamp", "frame_id"
                                           ("lidar3d"; "lidar" in earlier logs),
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
/lidar_points_     foxglove.PointCloud     at most one sweep a second (``cloud_preview_hz``):
foxglove                                   ``timestamp``, ``frame_id`` ("lidar3d"), ``pose``
                                           (identity), ``point_stride`` 16, ``fields`` x, y,
                                           z, time (float32; time [s] from the sweep's
                                           start), ``data`` (base64): the valid returns in the
                                           sensor frame. For Foxglove only: our readers
                                           decode ``/lidar_points``
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
:func:`log_summary` says whether the footer is there. Damage is skipped, not raised: a record
or message that does not parse or decode, a corrupt record length (the reader finds the records
again after it) and an incomplete last record are counted in a
:class:`~usvdrake.logs.damage.ReadDamage` (``damage=`` of the readers; ``skipped_records`` of
:func:`log_summary`, of ``usvdrake slam2d`` / ``slam3d``'s metrics); see
:mod:`~usvdrake.logs.mission_log.records`.

API: :class:`MissionLogWriter` (``write_state``, ``write_vector``, ``write_pose``,
``write_scan``, ``write_gps``, ``write_imu``, ``write_cloud``, ``write_transform``,
``write_hull``, ``write_point_cloud``; ``flush``, ``close``);
:class:`MissionRecorder`, a LeafSystem writing a list of :class:`RecordedPort` with publish
events; :func:`add_mission_recorder` (what ``run_mission`` and the hardware-in-the-loop runner
call: records whichever of :data:`MISSION_PORTS` a system has, with the sensor frames and hull
of :func:`sensor_frames` and :func:`hull_size`); :func:`read_mission_log`,
:func:`read_log_scans`, :func:`read_log_states`, :func:`read_log_vectors`, :func:`log_summary`.

Logs written before this encoding (``usvdrake/state-v1``, ``usvdrake/laserscan-v1``) are still
read by the same functions; so are logs without the Foxglove-only channels (they are never
needed to read a log back).

The package's modules, lowest first (each imports only those before it): ``schema`` (encoding
and schema names, JSON Schemas, Foxglove's official ones), ``codecs`` (message encoders and
decoders, the range-image cloud codec), ``writer`` (:class:`MissionLogWriter`), ``records``
(the MCAP records of a file, damage skipped and counted), ``reader``
(:func:`read_mission_log`, :func:`log_summary`, ``read_log_*``), ``recorder``
(:class:`MissionRecorder`, :func:`add_mission_recorder`). This module re-exports the names used
elsewhere.
"""

from usvdrake.logs.mission_log.codecs import (
    RANGE_LIMIT,
    decode_cloud,
    decode_scan,
    encode_cloud,
    encode_scan,
    quantise_ranges,
)
from usvdrake.logs.mission_log.reader import (
    log_summary,
    read_log_scans,
    read_log_states,
    read_log_vectors,
    read_mission_log,
)
from usvdrake.logs.mission_log.recorder import (
    MISSION_PORTS,
    MissionRecorder,
    RecordedPort,
    add_mission_recorder,
    hull_size,
    sensor_frames,
)
from usvdrake.logs.mission_log.schema import CLOUD_ENCODING, CLOUD_SCHEMA
from usvdrake.logs.mission_log.writer import MissionLogWriter

__all__ = [
    "CLOUD_ENCODING",
    "CLOUD_SCHEMA",
    "MISSION_PORTS",
    "RANGE_LIMIT",
    "MissionLogWriter",
    "MissionRecorder",
    "RecordedPort",
    "add_mission_recorder",
    "decode_cloud",
    "decode_scan",
    "encode_cloud",
    "encode_scan",
    "hull_size",
    "log_summary",
    "quantise_ranges",
    "read_log_scans",
    "read_log_states",
    "read_log_vectors",
    "read_mission_log",
    "sensor_frames",
]
