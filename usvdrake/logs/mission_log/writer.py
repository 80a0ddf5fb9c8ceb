"""Writing mission logs: :class:`MissionLogWriter`, an MCAP file written without chunks (one
record per message) that registers each topic's channel and schema on first use, encodes
states, vectors, poses, scans, GPS fixes, IMU samples and point clouds with the codecs, and
flushes to the operating system every ``flush_period`` of log or wall time (a background thread
covers quiet periods) so a crashed run loses at most the last second; and
:func:`vector_names`, the default field names of a vector.

A killed writer leaves a valid MCAP file: :class:`_TailKeepingFile` ends the file, after every
flush, with a provisional DataEnd + Footer (no summary) + magic, and writes the next records
over that tail in one ``pwrite``. So the ``mcap`` package's own reader (which seeks to the footer
first) and Foxglove read a crashed run's log up to its last flush."""

import math
import os
import threading
import time
from collections.abc import Sequence
from pathlib import Path

from mcap.data_stream import RecordBuilder
from mcap.records import DataEnd, Footer
from mcap.writer import MCAP0_MAGIC, Writer

from usvdrake.logs.mission_log.codecs import (
    _json,
    _ns,
    encode_cloud,
    encode_frame_transform,
    encode_gps,
    encode_hull_scene,
    encode_imu,
    encode_point_cloud,
    encode_pose,
    encode_scan,
    encode_state,
    encode_vector,
)
from usvdrake.logs.mission_log.schema import (
    CLOUD_ENCODING,
    cloud_schema,
    frame_transform_schema,
    gps_schema,
    imu_schema,
    no_fix_schema,
    point_cloud_schema,
    pose_schema,
    scan_schema,
    scene_update_schema,
    state_schema,
    vector_schema,
)
from usvdrake.sensors.messages import GpsFix, ImuSample, LaserScan, PointCloud


# --- writing ----------------------------------------------------------------------------------
def _provisional_tail() -> bytes:
    """DataEnd (no CRC) + a Footer without a summary + the closing magic: what makes a file cut
    after it a complete, unindexed MCAP file (readers then read it linearly)."""
    b = RecordBuilder()
    DataEnd(data_section_crc=0).write(b)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(b)
    return b.end() + MCAP0_MAGIC


_TAIL = _provisional_tail()


class _TailKeepingFile:
    """The output stream of the mcap ``Writer``: bytes wait in memory until :meth:`flush`, which
    writes them and a provisional tail at the end of the records already on disk, in one
    ``pwrite`` (a process killed in a system call finishes it, so the file never ends mid-record;
    the next flush overwrites the tail). :meth:`close` writes the real tail and truncates."""

    def __init__(self, path: Path):
        self._fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._committed = 0  # bytes of records on disk, before the provisional tail
        self._pending = bytearray()

    def write(self, data) -> int:
        self._pending += data
        return len(data)

    def tell(self) -> int:
        return self._committed + len(self._pending)

    def flush(self) -> None:
        if self._pending:
            data = bytes(self._pending) + _TAIL
            if os.pwrite(self._fd, data, self._committed) != len(data):
                raise OSError(f"short write to the mission log ({len(data)} bytes)")
            self._committed += len(self._pending)
            self._pending.clear()

    def close(self) -> None:
        """Write what is pending as the file's real end (``Writer.finish()`` wrote the summary,
        footer and magic) and cut the provisional tail that was after it."""
        if self._fd < 0:
            return
        if self._pending:
            data = bytes(self._pending)
            os.pwrite(self._fd, data, self._committed)
            self._committed += len(data)
            self._pending.clear()
        os.ftruncate(self._fd, self._committed)
        os.close(self._fd)
        self._fd = -1


class MissionLogWriter:
    """An MCAP mission log being written: channels are registered on first use, each message is
    one record, and the file is flushed to the OS every ``flush_period`` of log or wall time (a
    background thread covers quiet periods). ``close()`` (or ``with``) writes the summary and
    footer; until then the file is readable by :func:`read_mission_log` as far as it got."""

    def __init__(
        self, path: str | Path, flush_period: float = 0.5, profile: str = "usvdrake", live=None
    ):
        self.path = Path(path)
        # a FoxgloveLive (usvdrake.logs.mission_log.live) also streaming every message, or None
        self._live = live
        self.flush_period = float(flush_period)
        self._file = _TailKeepingFile(self.path)
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
                    if self._live is not None:
                        self._live.add_channel(ch, topic, schema, message_encoding)
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
            if self._live is not None:
                self._live.log(channel, ns, data)
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

    def write_transform(
        self,
        topic: str,
        t: float,
        parent: str,
        child: str,
        mount,
        publish_time: float | None = None,
    ) -> None:
        """A ``foxglove.FrameTransform``: ``child`` at ``mount`` = [x y z yaw] [m, rad] in
        ``parent``."""
        x, y, z, yaw = (float(v) for v in mount)
        ch = self.channel(topic, frame_transform_schema())
        self.write(ch, t, encode_frame_transform(t, parent, child, x, y, z, yaw), publish_time)

    def write_hull(
        self,
        topic: str,
        t: float,
        size,
        frame_id: str = "base_link",
        publish_time: float | None = None,
    ) -> None:
        """A ``foxglove.SceneUpdate`` drawing the hull, ``size`` = (length, beam, height) [m],
        as a cube on ``frame_id``."""
        length, beam, height = (float(v) for v in size)
        ch = self.channel(topic, scene_update_schema())
        self.write(ch, t, encode_hull_scene(t, length, beam, height, frame_id), publish_time)

    def write_point_cloud(
        self,
        topic: str,
        cloud: PointCloud,
        frame_id: str = "lidar3d",
        publish_time: float | None = None,
    ) -> None:
        """One sweep's returns as a ``foxglove.PointCloud`` (JSON, :func:`encode_point_cloud`),
        for Foxglove's 3D panel; our readers use the range image (:meth:`write_cloud`)."""
        ch = self.channel(topic, point_cloud_schema())
        self.write(ch, cloud.time, encode_point_cloud(cloud, frame_id), publish_time)

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
