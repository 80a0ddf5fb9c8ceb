"""Recording a Drake diagram into a mission log: :class:`RecordedPort` (one recorded input:
its port, topic, kind and rate), :class:`MissionRecorder` (a LeafSystem that writes its vector
inputs periodically and each new sensor message once, with publish events, to a
:class:`~usvdrake.logs.mission_log.writer.MissionLogWriter`), :data:`MISSION_PORTS` (what a
vessel or hardware-in-the-loop diagram is recorded by default), :func:`mission_ports` and
:func:`add_mission_recorder` (what ``run_mission`` and the hardware-in-the-loop runner call),
with :func:`sensor_frames` and :func:`hull_size`, what it learns of the vessel's sensor mounts
and hull from the diagram for Foxglove's 3D panel (``/tf``, ``/vessel_hull``)."""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import Diagram, LeafSystem, PortDataType

from usvdrake.logs.mission_log.writer import MissionLogWriter, vector_names
from usvdrake.sensors.gps import Gps
from usvdrake.sensors.imu import Imu
from usvdrake.sensors.lidar2d import Lidar2D
from usvdrake.sensors.lidar3d import Lidar3D
from usvdrake.sensors.messages import GpsFix, ImuSample, LaserScan, PointCloud
from usvdrake.vessel import VesselParams

# --- Foxglove's 3D panel: frames, topics ------------------------------------------------------
WORLD_FRAME = "world"
BODY_FRAME = "base_link"
TF_TOPIC = "/tf"
VESSEL_POSE_TOPIC = "/vessel_pose"
HULL_TOPIC = "/vessel_hull"
FOXGLOVE_CLOUD_SUFFIX = "_foxglove"  # /lidar_points → /lidar_points_foxglove
# the recorded state the vessel's pose (world → base_link) is taken from, in order of preference
TF_SOURCES = ("ground_truth_state", "state_estimate")

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

    For Foxglove's 3D panel it also writes, each time it samples the state port ``tf_port``
    (default: the first of :data:`TF_SOURCES` among its ``state`` ports; None: none), the
    transform world → base_link on ``/tf`` (``foxglove.FrameTransform``) and the pose on
    ``/vessel_pose`` (``foxglove.PoseInFrame``); once at the start the static transforms
    base_link → each of ``frames`` ({frame_id: [x y z yaw]} [m, rad], the sensor mounts) on
    ``/tf`` and, given ``hull`` = (length, beam, height) [m], the hull as a cube on
    ``/vessel_hull`` (``foxglove.SceneUpdate``); and each sweep of a ``cloud`` port also as a
    ``foxglove.PointCloud`` on ``<topic>_foxglove``, at most ``cloud_preview_hz`` sweeps a
    second (a sweep is ~0.4 MB there against ~20 kB as a range image; None: every sweep, 0:
    none).
    """

    def __init__(
        self,
        writer: MissionLogWriter,
        ports: Sequence[RecordedPort] | None = None,
        rate_hz: float = 10.0,
        scan_period: float | None = None,
        *,
        frames: Mapping[str, Sequence[float]] | None = None,
        hull: Sequence[float] | None = None,
        tf_port: str | None = "auto",
        cloud_preview_hz: float | None = 1.0,
    ):
        super().__init__()
        if ports is None:
            ports = _legacy_ports(scan_period)
        self._writer = writer
        self._ports = list(ports)
        self._last: dict[str, tuple] = {}
        self._frames = {str(k): [float(v) for v in m] for k, m in (frames or {}).items()}
        for frame, mount in self._frames.items():
            if len(mount) != 4:
                raise ValueError(f"MissionRecorder: frame {frame!r} mount is not [x y z yaw]")
        self._hull = None if hull is None else tuple(float(v) for v in hull)
        if self._hull is not None and len(self._hull) != 3:
            raise ValueError("MissionRecorder: hull is (length, beam, height)")
        states = [p.port for p in self._ports if p.kind == "state"]
        if tf_port == "auto":
            tf_port = next((s for s in TF_SOURCES if s in states), None)
        elif tf_port is not None and tf_port not in states:
            raise ValueError(f"MissionRecorder: tf_port {tf_port!r} is not a recorded state")
        self._tf_port = tf_port
        self._cloud_preview_hz = cloud_preview_hz
        self._last_preview: dict[str, float] = {}
        if self._frames or self._hull is not None:
            self.DeclareInitializationPublishEvent(self._write_static)
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

    @property
    def frames(self) -> dict[str, list[float]]:
        """The static sensor frames written to ``/tf``: {frame_id: [x y z yaw]}."""
        return {k: list(v) for k, v in self._frames.items()}

    @property
    def tf_port(self) -> str | None:
        """The state port the world → base_link transform is taken from (None: none)."""
        return self._tf_port

    def _write_static(self, context) -> None:
        w = self._writer
        if w.closed:
            return
        t = context.get_time()
        for frame, mount in self._frames.items():
            w.write_transform(TF_TOPIC, t, BODY_FRAME, frame, mount)
        if self._hull is not None:
            w.write_hull(HULL_TOPIC, t, self._hull, BODY_FRAME)

    def _write_vector(self, context, p: RecordedPort, port) -> None:
        w = self._writer
        if w.closed:
            return
        v = port.Eval(context)
        t = context.get_time()
        if p.kind == "state":
            w.write_state(p.topic, t, v)
            if p.port == self._tf_port:
                x, y, psi = (float(c) for c in v[:3])
                w.write_transform(TF_TOPIC, t, WORLD_FRAME, BODY_FRAME, (x, y, 0.0, psi))
                w.write_pose(VESSEL_POSE_TOPIC, t, v, WORLD_FRAME)
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
            frame = p.frame_id or "lidar3d"
            w.write_cloud(p.topic, msg, frame, context.get_time())
            if self._preview_due(p.port, msg.time):
                topic = p.topic + FOXGLOVE_CLOUD_SUFFIX
                w.write_point_cloud(topic, msg, frame, context.get_time())
        else:
            w.write_imu(p.topic, msg, p.frame_id or "imu", context.get_time())

    def _preview_due(self, port: str, t: float) -> bool:
        hz = self._cloud_preview_hz
        if hz is not None and hz <= 0:
            return False
        last = self._last_preview.get(port)
        if hz is not None and last is not None and t - last < 1.0 / hz - 1e-9:
            return False
        self._last_preview[port] = t
        return True


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


def _subsystems(system):
    yield system
    if isinstance(system, Diagram):
        for s in system.GetSystems():
            yield from _subsystems(s)


# the frame of each sensor system (the recorder's default frame_id of the port it feeds)
_SENSOR_FRAMES = ((Lidar2D, "lidar"), (Lidar3D, "lidar3d"), (Imu, "imu"), (Gps, "gps"))


def sensor_frames(system) -> dict[str, list[float]]:
    """{frame_id: [x y z yaw] in base_link [m, rad]} of the simulated sensors in ``system``
    (searched through nested diagrams): ``lidar`` / ``lidar3d`` at their ``mount``, ``imu`` at
    its lever arm, ``gps`` at its antenna height. Empty for a hardware station (its devices
    do not know their mounts)."""
    out: dict[str, list[float]] = {}
    for s in _subsystems(system):
        for cls, frame in _SENSOR_FRAMES:
            if not isinstance(s, cls) or frame in out:
                continue
            cfg = s.model.cfg
            if frame == "imu":
                lx, ly = (float(v) for v in cfg.lever_arm[:2])
                out[frame] = [lx, ly, 0.0, 0.0]
            elif frame == "gps":
                out[frame] = [0.0, 0.0, float(cfg.antenna_height), 0.0]
            else:
                out[frame] = [float(v) for v in cfg.mount]
    return out


def hull_size(system) -> tuple[float, float, float] | None:
    """(length, beam, height) [m] of the first vessel plant (a system with ``params``, a
    :class:`~usvdrake.vessel.VesselParams`) in ``system``; None if there is none."""
    for s in _subsystems(system):
        params = getattr(s, "params", None)
        if isinstance(params, VesselParams):
            h = params.hull
            return (float(h.length), float(h.beam), float(h.height))
    return None


def add_mission_recorder(
    builder,
    system,
    writer: MissionLogWriter,
    rate_hz: float = 10.0,
    extra: Sequence[RecordedPort] = (),
    name: str = "mission_recorder",
    *,
    frames: Mapping[str, Sequence[float]] | None = None,
    hull: Sequence[float] | None = None,
    cloud_preview_hz: float | None = 1.0,
) -> MissionRecorder:
    """Add a :class:`MissionRecorder` to ``builder`` recording whichever of
    :data:`MISSION_PORTS` ``system`` (already in ``builder``) has as outputs — ground truth in
    simulation, inputs (sensor messages, measured thrust), outputs (thruster command, applied
    thrust) and estimates (state estimate, SLAM pose) — plus ``extra`` ports of ``system``,
    vectors at ``rate_hz``. Connects it and returns it.

    Foxglove's 3D panel: ``frames`` (sensor mounts, {frame_id: [x y z yaw]}) and ``hull``
    ((length, beam, height) [m]) default to what ``system`` holds (:func:`sensor_frames`,
    :func:`hull_size`); pass ``{}`` / ``()`` for none. ``cloud_preview_hz``: see
    :class:`MissionRecorder`."""
    ports = mission_ports(system, extra)
    frames = sensor_frames(system) if frames is None else frames
    hull = hull_size(system) if hull is None else (tuple(hull) or None)
    recorder = builder.AddNamedSystem(
        name,
        MissionRecorder(
            writer,
            ports,
            rate_hz,
            frames=frames,
            hull=hull,
            cloud_preview_hz=cloud_preview_hz,
        ),
    )
    for p in ports:
        builder.Connect(system.GetOutputPort(p.port), recorder.GetInputPort(p.port))
    return recorder
