"""``ImuSerialSource``: a real Xsens MTi (Xbus MTData2) on a serial port as a Drake system."""

from __future__ import annotations

from dataclasses import dataclass, replace

from hardware_io.codecs.imu import (
    MID_GOTO_MEASUREMENT,
    MtError,
    MtStream,
    encode_frame,
    to_imu_sample,
)
from hardware_io.systems.device_source import DeviceSource
from hardware_io.transport import SerialTransport
from usvdrake.sensors.messages import ImuSample

__all__ = ["GOTO_MEASUREMENT", "ImuSerialSource", "ImuSerialStatus"]


#: Xbus GoToMeasurement (MID 0x10, no data): ``FA FF 10 00 F1``, sent on the first update so
#: an MTi left in config mode starts streaming (an MTi already measuring ignores it).
GOTO_MEASUREMENT = encode_frame(MID_GOTO_MEASUREMENT, b"")


@dataclass(frozen=True)
class ImuSerialStatus:
    """Counters of an :class:`ImuSerialSource` (abstract state)."""

    bytes_read: int = 0
    frames: int = 0  #: checksum-valid MTData2 messages
    bad_frames: int = 0  #: candidates dropped (checksum or MTData2 content errors)
    samples: int = 0  #: messages converted to an ImuSample (need acc, gyro, ENU orientation)
    samples_lost: int = 0  #: gaps in the MTi's PacketCounter (messages never received)
    last_packet_counter: int | None = None
    requests_sent: int = 0  #: GoToMeasurement requests written


class ImuSerialSource(DeviceSource[ImuSample, ImuSerialStatus]):
    """Samples from an Xsens MTi (MTData2 output) on ``port``.

    .. pydrake_system::

        name: ImuSerialSource
        output_ports:
        - imu
        - diagnostics

    On the first update it writes :data:`GOTO_MEASUREMENT`. A periodic unrestricted update every
    ``period`` seconds (first at t = 0; the MTi's default output is 100 Hz, so 0.01 s) reads
    the bytes available, cuts them into Xbus messages with
    :class:`~hardware_io.codecs.imu.MtStream` (resynchronising on ``FA FF`` after garbage,
    checksum = sum of the bytes after the preamble ≡ 0 mod 256) and converts each MTData2
    message with :func:`~hardware_io.codecs.imu.to_imu_sample`. ``imu`` is the last
    :class:`~usvdrake.sensors.messages.ImuSample`: angular velocity [rad/s], specific force
    [m/s²] in the sensor frame (x forward, y left, z up), orientation sensor -> ENU as
    (x, y, z, w), all float32 on the wire. Its ``time`` is the simulation time of the update
    that received it (the host receive time, as for GpsSerialSource), not the MTi's
    SampleTimeFine. Messages lacking acceleration, rate of turn or an ENU orientation count in
    ``frames`` but not ``samples``.

    The sample and the :class:`ImuSerialStatus` counters are abstract state; the transport and
    the stream parser's partial-message buffer are I/O on the system object, as for every
    :class:`~hardware_io.systems.device_source.DeviceSource` (contexts share the one port; call
    :meth:`close` to release it).
    """

    def __init__(
        self,
        port: str,
        baudrate: int = 115200,
        period: float = 0.01,
        transport: SerialTransport | None = None,
    ):
        super().__init__(
            transport if transport is not None else SerialTransport(port, baudrate),
            "imu",
            ImuSample(),
            ImuSerialStatus(),
            period,
        )
        self._stream = MtStream()

    def poll(
        self, t: float, sample: ImuSample, st: ImuSerialStatus
    ) -> tuple[ImuSample, ImuSerialStatus]:
        requests = st.requests_sent
        if requests == 0:
            self.transport.write(GOTO_MEASUREMENT)
            requests = 1
        data, _host_time = self.transport.read()
        s = self._stream
        bad_before = s.checksum_errors + s.frame_errors
        messages = s.feed(data) if data else []
        n_samples = lost = 0
        counter = st.last_packet_counter
        for m in messages:
            if m.packet_counter is not None:
                if counter is not None:
                    lost += (m.packet_counter - counter - 1) & 0xFFFF
                counter = m.packet_counter
            try:
                sample = to_imu_sample(m, time=t)
            except MtError:
                continue
            n_samples += 1
        st = replace(
            st,
            bytes_read=st.bytes_read + len(data),
            frames=st.frames + len(messages),
            bad_frames=st.bad_frames + s.checksum_errors + s.frame_errors - bad_before,
            samples=st.samples + n_samples,
            samples_lost=st.samples_lost + lost,
            last_packet_counter=counter,
            requests_sent=requests,
        )
        return sample, st
