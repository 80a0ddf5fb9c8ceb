"""The project's own mission logs: MCAP files written by ``usvdrake run`` (``DIR/log.mcap``).

Channels (message encodings are ours, documented here so other tools can read them):

* ``/ground_truth`` — ``usvdrake/state-v1``: JSON ``{"t": s, "q": [x, y, psi, u, v, r]}``.
* ``/lidar_scan`` — ``usvdrake/laserscan-v1``: one JSON line ``{"t", "angle_min",
  "angle_increment", "range_min", "range_max", "scan_time", "n"}``, a newline, then n little-endian
  float32 ranges (inf for no return).

Log and publish times are the simulation time in nanoseconds.
"""

import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.logs.rosbag import BagScan
from usvdrake.sensors.messages import LaserScan

STATE_ENCODING = "usvdrake/state-v1"
SCAN_ENCODING = "usvdrake/laserscan-v1"


def encode_scan(scan: LaserScan) -> bytes:
    head = {
        "t": scan.time,
        "angle_min": scan.angle_min,
        "angle_increment": scan.angle_increment,
        "range_min": scan.range_min,
        "range_max": scan.range_max,
        "scan_time": scan.scan_time,
        "n": len(scan.ranges),
    }
    return json.dumps(head).encode() + b"\n" + np.asarray(scan.ranges, "<f4").tobytes()


def decode_scan(data: bytes) -> LaserScan:
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
        ranges=r,
        valid=np.isfinite(r),
    )


class MissionLogWriter:
    """Opens an MCAP file and registers the channels; ``close()`` finishes it."""

    def __init__(self, path: str | Path):
        from mcap.writer import Writer

        self._file = open(path, "wb")  # noqa: SIM115 - closed by close()
        self._writer = Writer(self._file)
        self._writer.start(profile="usvdrake", library="usvdrake")
        schema = self._writer.register_schema(name="usvdrake", encoding="", data=b"")
        self.state_channel = self._writer.register_channel("/ground_truth", STATE_ENCODING, schema)
        self.scan_channel = self._writer.register_channel("/lidar_scan", SCAN_ENCODING, schema)

    def write(self, channel: int, t: float, data: bytes) -> None:
        ns = int(round(t * 1e9))
        self._writer.add_message(channel_id=channel, log_time=ns, data=data, publish_time=ns)

    def close(self) -> None:
        self._writer.finish()
        self._file.close()


class MissionRecorder(LeafSystem):
    """Writes the ground truth at ``rate_hz`` and every new 2D scan to a :class:`MissionLogWriter`
    (publish events: the file is an output, like Meshcat, not simulation state).

    .. pydrake_system::

        name: MissionRecorder
        input_ports:
        - ground_truth_state
        - lidar_scan (optional)
    """

    def __init__(
        self, writer: MissionLogWriter, rate_hz: float = 10.0, scan_period: float | None = None
    ):
        super().__init__()
        self._writer = writer
        self._state = self.DeclareVectorInputPort("ground_truth_state", 6)
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._write_state)
        self._scan = None
        if scan_period is not None:
            self._scan = self.DeclareAbstractInputPort(
                "lidar_scan", AbstractValue.Make(LaserScan())
            )
            # half a period after each sweep, so the scan that ended then is on the port
            self.DeclarePeriodicPublishEvent(scan_period, 1.5 * scan_period, self._write_scan)

    def _write_state(self, context):
        q = self._state.Eval(context)
        t = context.get_time()
        self._writer.write(
            self._writer.state_channel, t, json.dumps({"t": t, "q": list(map(float, q))}).encode()
        )

    def _write_scan(self, context):
        scan = self._scan.Eval(context)
        if scan.valid.any():
            self._writer.write(self._writer.scan_channel, scan.time, encode_scan(scan))


def read_mission_log(path: str | Path) -> Iterator[tuple[str, float, object]]:
    """(topic, time [s], message) for every message: states as dicts, scans as LaserScan."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=True):
            if channel.message_encoding == SCAN_ENCODING:
                yield channel.topic, message.log_time * 1e-9, decode_scan(message.data)
            elif channel.message_encoding == STATE_ENCODING:
                yield channel.topic, message.log_time * 1e-9, json.loads(message.data)


def read_log_scans(path: str | Path) -> list[BagScan]:
    """The 2D scans of a mission log, for ``usvdrake slam2d``."""
    return [BagScan(t, m) for topic, t, m in read_mission_log(path) if topic == "/lidar_scan"]


def read_log_states(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Ground truth (times, states n × 6) of a mission log."""
    rows = [(t, m["q"]) for topic, t, m in read_mission_log(path) if topic == "/ground_truth"]
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows]).reshape(-1, 6)
