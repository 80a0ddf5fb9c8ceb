"""``VelodyneUdpSource``: a real Velodyne VLP-16 (UDP data packets) as a Drake system."""

from __future__ import annotations

from dataclasses import dataclass, replace

from hardware_io.codecs.velodyne import SweepAssembler, VelodyneError, decode_packet
from hardware_io.systems.device_source import DeviceSource
from hardware_io.transport import UdpTransport
from usvdrake.sensors.messages import PointCloud

__all__ = ["VelodyneUdpSource", "VelodyneUdpStatus"]


@dataclass(frozen=True)
class VelodyneUdpStatus:
    """Counters of a :class:`VelodyneUdpSource` (abstract state)."""

    datagrams: int = 0
    bytes_read: int = 0
    bad_packets: int = 0  #: datagrams that are not VLP-16 data packets (size, flags, ...)
    sweeps: int = 0  #: complete 360° sweeps published
    partial_sweeps: int = 0  #: incomplete sweeps dropped (the first one after start)
    device_time: float = 0.0  #: [s] end of the last sweep on the sensor clock (past the hour)


class VelodyneUdpSource(DeviceSource[PointCloud, VelodyneUdpStatus]):
    """Sweeps from a VLP-16 sending data packets to ``address:port`` (default: every interface,
    port 2368 -- the sensor's factory destination port).

    .. pydrake_system::

        name: VelodyneUdpSource
        output_ports:
        - lidar_points
        - diagnostics

    A periodic unrestricted update every ``period`` seconds (first at t = 0; the VLP-16 sends
    ~754 packets/s, ~7.5 per 10 ms) reads every queued datagram, decodes it with
    :func:`~hardware_io.codecs.velodyne.decode_packet` (1206 bytes: 12 blocks × 32 channels,
    distances in 2 mm, azimuths in 0.01°; the packet has no checksum, so only structurally
    impossible packets are rejected and counted in ``bad_packets``) and assembles sweeps with
    :class:`~hardware_io.codecs.velodyne.SweepAssembler` (``resolution_deg`` columns, cut
    where the azimuth wraps past ``cut_azimuth_deg``; the first, partial sweep is dropped).
    ``lidar_points`` is the :class:`~usvdrake.sensors.messages.PointCloud` of the last complete
    sweep; its ``time`` is the simulation time of the update that completed it (the host
    receive time, like the serial sources), while ``point_time`` / ``sweep_time`` come from the
    sensor's µs timestamps (and ``device_time`` in the status is the sweep end on the sensor's
    clock).

    The cloud and the :class:`VelodyneUdpStatus` counters are abstract state; the socket and
    the assembler's partial sweep are I/O on the system object, as for every
    :class:`~hardware_io.systems.device_source.DeviceSource` (contexts share the one socket;
    call :meth:`close` to release it).
    """

    def __init__(
        self,
        address: str = "0.0.0.0",
        port: int = 2368,
        period: float = 0.01,
        transport: UdpTransport | None = None,
        *,
        resolution_deg: float = 0.2,
        cut_azimuth_deg: float = 0.0,
    ):
        self._assembler = SweepAssembler(resolution_deg, cut_azimuth_deg)
        super().__init__(
            transport if transport is not None else UdpTransport(address, port),
            "lidar_points",
            PointCloud(),
            VelodyneUdpStatus(),
            period,
        )

    def poll(
        self, t: float, cloud: PointCloud, st: VelodyneUdpStatus
    ) -> tuple[PointCloud, VelodyneUdpStatus]:
        datagrams, _host_time = self.transport.read()
        asm = self._assembler
        partial0 = asm.partial_sweeps
        bad = nbytes = 0
        sweeps: list[PointCloud] = []
        for d in datagrams:
            nbytes += len(d)
            try:
                packet = decode_packet(d)
            except VelodyneError:
                bad += 1
                continue
            sweeps += asm.feed(packet)
        device_time = st.device_time
        if sweeps:
            device_time = sweeps[-1].time
            cloud = replace(sweeps[-1], time=t)
        st = replace(
            st,
            datagrams=st.datagrams + len(datagrams),
            bytes_read=st.bytes_read + nbytes,
            bad_packets=st.bad_packets + bad,
            sweeps=st.sweeps + len(sweeps),
            partial_sweeps=st.partial_sweeps + asm.partial_sweeps - partial0,
            device_time=device_time,
        )
        return cloud, st
