"""``LidarSerialSource``: a real 2D lidar on a serial port (RPLIDAR A1 or Hokuyo SCIP 2.0) as a
Drake system."""

from __future__ import annotations

from dataclasses import dataclass, replace

from hardware_io.codecs import rplidar as rp
from hardware_io.codecs import scip
from hardware_io.systems.device_source import DeviceSource
from hardware_io.transport import SerialTransport
from usvdrake.sensors.messages import LaserScan

__all__ = [
    "PROTOCOLS",
    "LidarSerialSource",
    "LidarSerialStatus",
    "SalvagingScipStream",
    "salvage_scan_data",
]

PROTOCOLS = ("rplidar", "scip")
_FULL_TURN_Q6 = 360 * 64  # RPLIDAR angle of a full turn [1/64 deg]


@dataclass(frozen=True)
class LidarSerialStatus:
    """Counters of a :class:`LidarSerialSource` (abstract state)."""

    bytes_read: int = 0
    bytes_written: int = 0
    frames: int = 0  #: RPLIDAR measurement nodes / SCIP responses decoded
    bad_frames: int = 0  #: RPLIDAR nodes failing the check bits / SCIP blocks not decoded
    discarded_bytes: int = 0  #: bytes skipped while resynchronising
    scans: int = 0  #: complete revolutions published
    partial_scans: int = 0  #: SCIP scans salvaged with data lines lost (those beams invalid)
    dropped_scans: int = 0  #: RPLIDAR fragments of fewer than ``min_nodes`` nodes dropped
    implausible_nodes: int = 0  #: RPLIDAR nodes at ≥ 360° dropped / start flags ignored
    starts: int = 0  #: start sequences sent (the first one, then one per restart)


@dataclass(frozen=True)
class _Link:
    """Where the start sequence is (abstract state)."""

    next_request: int = 0  #: index of the next request of the start sequence to send
    last_progress: float = 0.0  #: [s] simulation time of the last (re)start or scan


# ------------------------------------------------------------------------------------------
# SCIP: salvaging scans with corrupted data lines


def salvage_scan_data(block: bytes, command: scip.ScipCommand) -> tuple[scip.ScanData, int] | None:
    """A data response of ``command`` (MD/MS/GD/GS) whose strict decoding failed ->
    ``(scan, bad_lines)``, or None.

    A block (ending with the blank line) is salvageable when its last ``3 + L`` lines have
    exactly the layout of ``command``'s response -- echo of the same length, a 2-character
    status (``99``/``00`` if its checksum holds), a 4-character timestamp and ``L`` data lines of
    64 characters (the last one shorter) -- so that every character's position is known.
    Data lines whose checksum fails, and characters outside the 6-bit range, make the values
    they carry 0 mm (an error code: invalid beams); a wrong timestamp line gives 0 ms. Lines
    before the echo are garbage. None if the layout differs (a lost or extra LF) or no data
    line survives.
    """
    nchars = scip.SCAN_COMMANDS.get(command.name)
    if nchars is None:
        return None
    expected = scip.num_clusters(command) * nchars
    n_lines = -(-expected // scip.LINE_DATA_MAX)
    if not block.endswith(b"\n\n"):
        return None
    lines = block[:-2].split(b"\n")
    if len(lines) < 3 + n_lines:
        return None
    lines = lines[len(lines) - (3 + n_lines) :]
    echo, status, stamp, data = lines[0], lines[1], lines[2], lines[3:]
    c = command
    echo_len = len(
        scip.encode_scan_command(
            c.name, c.start_step, c.end_step, c.cluster_count,
            c.scan_interval or 0, c.num_scans or 0, c.string,
        )
    ) - 1  # fmt: skip
    if len(echo) != echo_len:
        return None
    if len(status) != 3 or len(stamp) != 5:
        return None
    data_status = "00" if command.name[0] == "G" else "99"
    if scip.checksum(status[:2]) == status[2] and status[:2] != data_status.encode():
        return None  # a genuine non-data status
    last = expected - scip.LINE_DATA_MAX * (n_lines - 1)
    chars = bytearray()
    good: list[bool] = []
    bad_lines = 0
    for k, line in enumerate(data):
        if len(line) != (scip.LINE_DATA_MAX if k < n_lines - 1 else last) + 1:
            return None
        ok = scip.checksum(line[:-1]) == line[-1]
        bad_lines += not ok
        chars += line[:-1]
        good += [ok] * (len(line) - 1)
    if bad_lines == n_lines:
        return None
    values = []
    for i in range(0, expected, nchars):
        v = 0
        for c, ok in zip(chars[i : i + nchars], good[i : i + nchars], strict=True):
            if not ok or not 0x30 <= c <= 0x6F:
                v = -1
                break
            v = (v << 6) | (c - 0x30)
        values.append(max(v, 0))
    ts = 0
    if scip.checksum(stamp[:4]) == stamp[4]:
        try:
            (ts,) = scip.decode_values(stamp[:4], 4)
        except scip.ScipError:
            ts = 0
    return scip.ScanData(command, data_status, ts, tuple(values)), bad_lines


class SalvagingScipStream(scip.ScipStream):
    """:class:`~hardware_io.codecs.scip.ScipStream` that also

    * recognises the reply to ``SCIP2.0`` (which the codec does not decode) and drops it
      silently (``handshake_replies``), and
    * when a block does not decode strictly and :attr:`command` (the MD/MS the host started) is
      set, salvages a data response with :func:`salvage_scan_data` (``salvaged``; such a block
      then counts neither in ``errors`` nor in ``discarded_bytes``).

    With 1 % of the bytes corrupted a full UTM-30LX scan (~3.4 kB) essentially never arrives
    intact, but about half of its 51 data lines do.
    """

    def __init__(self, max_buffer: int = 16384):
        super().__init__(max_buffer)
        self.command: scip.ScipCommand | None = None
        self.salvaged = 0
        self.salvaged_bad_lines = 0
        self.handshake_replies = 0

    def _decode_block(self, block: bytes):
        if block.startswith(b"SCIP2.0\n"):
            self.handshake_replies += 1
            self.discarded_bytes += len(block)
            return None
        errors, discarded = self.errors, self.discarded_bytes
        msg = super()._decode_block(block)
        if msg is None and self.command is not None:
            got = salvage_scan_data(block, self.command)
            if got is not None:
                msg, bad = got
                self.errors, self.discarded_bytes = errors, discarded
                self.salvaged += 1
                self.salvaged_bad_lines += bad
        return msg


# ------------------------------------------------------------------------------------------
# The system


class LidarSerialSource(DeviceSource[LaserScan, LidarSerialStatus]):
    """Scans from a 2D lidar on ``port``: ``protocol`` ``"rplidar"`` (Slamtec RPLIDAR A1,
    115200 8N1) or ``"scip"`` (Hokuyo UTM-30LX, SCIP 2.0 over USB; the baud rate is ignored by
    the CDC-ACM driver).

    .. pydrake_system::

        name: LidarSerialSource
        output_ports:
        - lidar_scan
        - diagnostics

    A periodic unrestricted update every ``period`` seconds (first at t = 0) first sends the
    next request of the start sequence, one request per update:

    * RPLIDAR: STOP ``A5 25`` (the protocol asks ≥ 1 ms before the next request, so SCAN goes
      one update later), then SCAN ``A5 20``; the device answers ``A5 5A 05 00 00 40 81`` and
      streams 5-byte nodes.
    * SCIP: ``QT\\nSCIP2.0\\nBM\\nMDssss eeee cc 0 00\\n`` in one write (stop a stale stream, SCIP
      2.0 mode, laser on, continuous scans of ``start_step`` .. ``end_step`` -- default the
      whole field, steps 0 .. 1080 -- grouped by ``cluster_count``, every revolution, until QT);
      e.g. ``MD0000108001000``.

    If no complete revolution arrives for ``restart_timeout`` seconds of simulation time after
    the start (or the last scan), the sequence is sent again (``starts`` counts them) -- a
    request lost on a noisy line, a device power-cycled.

    It then reads the available bytes and parses them, resynchronising after garbage:

    * RPLIDAR: :class:`~hardware_io.codecs.rplidar.ScanNodeParser` (byte-wise on the node check
      bits) and :class:`~hardware_io.codecs.rplidar.RplidarScanAssembler` (a revolution is
      complete when the next start flag arrives), binned by
      :meth:`~hardware_io.codecs.rplidar.RplidarRevolution.to_laser_scan` onto ``num_beams``
      beams from -π (counter-clockwise; the RPLIDAR's clockwise degrees are negated), keeping
      ``range_min`` .. ``range_max`` [m] (A1: 0.15 .. 12 m) and nodes of at least
      ``min_quality``. Distances are ¼ mm, angles 1/64° on the wire. The nodes carry only two
      check bits, so after line noise the byte-wise resynchronisation decodes some misaligned
      garbage nodes, which would cut revolutions at spurious start flags. Hence plausibility
      filters (``implausible_nodes``): a node at ≥ 360° (the A1 sends 0 .. 360°, the wire
      allows 512°) is dropped, a start flag is only honoured at an angle below
      ``start_window_deg`` (the first node after the 0° crossing; default 10°), and a
      "revolution" of fewer than ``min_nodes`` nodes (default ``num_beams // 4``) is dropped
      (``dropped_scans``).
    * SCIP: :class:`SalvagingScipStream` (blocks ending with a blank line; lines with a bad
      checksum lose only their beams), converted by :func:`~hardware_io.codecs.scip.
      to_laser_scan` with ``geometry`` (UTM-30LX: step 0 at -135°, 0.25° per step, 0.023 ..
      30 m, distances in mm).

    ``lidar_scan`` is the :class:`~usvdrake.sensors.messages.LaserScan` of the last complete
    revolution; its ``time`` is the simulation time of the update that completed it (the host
    receive time, as for GpsSerialSource); ``scan_time`` is the RPLIDAR revolution period
    measured on the host clock (0 when two start flags arrive in one read), or the geometry's
    nominal one for SCIP.

    The scan, the :class:`LidarSerialStatus` counters and the start-sequence position are
    abstract state; the transport and the parsers' partial buffers are I/O on the system object,
    as for every :class:`~hardware_io.systems.device_source.DeviceSource` (contexts share the
    one port). Call :meth:`close` to release the port (it sends no STOP/QT: the device keeps
    streaming until the next start sequence).
    """

    def __init__(
        self,
        port: str,
        baudrate: int,
        protocol: str,
        period: float = 0.02,
        transport: SerialTransport | None = None,
        *,
        num_beams: int = 360,
        range_min: float = 0.15,
        range_max: float = 12.0,
        min_quality: int = 0,
        min_nodes: int | None = None,
        start_window_deg: float = 10.0,
        geometry: scip.SensorGeometry = scip.UTM30LX,
        start_step: int = 0,
        end_step: int | None = None,
        cluster_count: int = 1,
        restart_timeout: float = 2.0,
    ):
        if protocol not in PROTOCOLS:
            raise ValueError(f"unknown lidar protocol {protocol!r}; expected 'rplidar' or 'scip'")
        self.protocol = protocol
        self.num_beams, self.range_min, self.range_max = num_beams, range_min, range_max
        self.min_quality = min_quality
        self.min_nodes = max(num_beams // 4, 1) if min_nodes is None else int(min_nodes)
        self._start_window_q6 = round(start_window_deg * 64)
        self.geometry = geometry
        self.restart_timeout = float(restart_timeout)
        if protocol == "rplidar":
            if num_beams < 1:
                raise ValueError(f"num_beams must be positive, got {num_beams}")
            self.start_sequence = (rp.encode_request(rp.CMD_STOP), rp.encode_request(rp.CMD_SCAN))
        else:
            end = geometry.steps - 1 if end_step is None else end_step
            if not 0 <= start_step <= end <= geometry.steps - 1:
                raise ValueError(
                    f"steps {start_step} .. {end} outside 0 .. {geometry.steps - 1} of the sensor"
                )
            md = scip.encode_scan_command("MD", start_step, end, cluster_count, 0, 0)
            self.scan_command = scip.decode_command(md)
            self.start_sequence = (
                scip.encode_command("QT") + b"SCIP2.0\n" + scip.encode_command("BM") + md,
            )
        super().__init__(
            transport if transport is not None else SerialTransport(port, baudrate),
            "lidar_scan",
            LaserScan(),
            LidarSerialStatus(),
            period,
        )
        self._link = self._declare_polled_state(_Link())
        if protocol == "rplidar":
            self._nodes = rp.ScanNodeParser()
            self._assembler = rp.RplidarScanAssembler()
        else:
            self._stream = SalvagingScipStream()
            self._stream.command = self.scan_command

    def poll(
        self, t: float, scan: LaserScan, st: LidarSerialStatus, link: _Link
    ) -> tuple[LaserScan, LidarSerialStatus, _Link]:
        written = starts = 0
        if link.next_request >= len(self.start_sequence) and (
            t - link.last_progress >= self.restart_timeout
        ):
            link = _Link(0, t)  # nothing for too long: start again
        if link.next_request < len(self.start_sequence):
            request = self.start_sequence[link.next_request]
            self.transport.write(request)
            written += len(request)
            starts += link.next_request == 0
            link = _Link(link.next_request + 1, t if link.next_request == 0 else link.last_progress)

        data, host_time = self.transport.read()
        if self.protocol == "rplidar":
            scans, counts = self._parse_rplidar(data, host_time, t)
        else:
            scans, counts = self._parse_scip(data, t)
        if scans:
            scan = scans[-1]
            link = replace(link, last_progress=t)
        st = replace(
            st,
            dropped_scans=st.dropped_scans + counts[4],
            implausible_nodes=st.implausible_nodes + counts[5],
            bytes_read=st.bytes_read + len(data),
            bytes_written=st.bytes_written + written,
            frames=st.frames + counts[0],
            bad_frames=st.bad_frames + counts[1],
            discarded_bytes=st.discarded_bytes + counts[2],
            scans=st.scans + len(scans),
            partial_scans=st.partial_scans + counts[3],
            starts=st.starts + starts,
        )
        return scan, st, link

    def _parse_rplidar(self, data: bytes, host_time: float, t: float):
        p = self._nodes
        bad0, disc0 = p.check_errors, p.discarded_bytes
        nodes = p.feed(data) if data else []
        n_nodes, implausible, plausible = len(nodes), 0, []
        for n in nodes:
            if n.angle_q6 >= _FULL_TURN_Q6:
                implausible += 1
                continue
            if n.start and n.angle_q6 >= self._start_window_q6:
                implausible += 1
                n = replace(n, start=False)
            plausible.append(n)
        revs = self._assembler.feed(plausible, host_time)
        scans = [
            replace(
                r.to_laser_scan(self.num_beams, self.range_min, self.range_max, self.min_quality),
                time=t,
            )
            for r in revs
            if len(r.nodes) >= self.min_nodes
        ]
        dropped = len(revs) - len(scans)
        return scans, (
            n_nodes, p.check_errors - bad0, p.discarded_bytes - disc0, 0, dropped, implausible
        )  # fmt: skip

    def _parse_scip(self, data: bytes, t: float):
        s = self._stream
        err0, disc0, salv0 = s.errors, s.discarded_bytes, s.salvaged
        msgs = s.feed(data) if data else []
        scans = [
            scip.to_laser_scan(m, time=t, geometry=self.geometry)
            for m in msgs
            if isinstance(m, scip.ScanData)
        ]
        return scans, (
            len(msgs), s.errors - err0, s.discarded_bytes - disc0, s.salvaged - salv0, 0, 0
        )  # fmt: skip
