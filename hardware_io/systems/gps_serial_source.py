"""``GpsSerialSource``: a real NMEA 0183 GNSS receiver on a serial port as a Drake system."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hardware_io.codecs.nmea import GGA, RMC, VTG, NmeaError, decode
from hardware_io.codecs.nmea_stream import NmeaStream
from hardware_io.systems.device_source import DeviceSource
from hardware_io.transport import SerialTransport
from usvdrake.sensors.geodesy import Datum, datum_by_name
from usvdrake.sensors.messages import GpsFix

__all__ = ["UERE_M", "GpsSerialSource", "GpsSerialStatus", "covariance_from_hdop"]

#: User equivalent range error [m] (1 σ) of a standalone GNSS receiver, used with HDOP to
#: estimate the position covariance.
UERE_M = 3.0
#: Assumed VDOP / HDOP ratio (GGA carries no VDOP).
VDOP_PER_HDOP = 1.5


def covariance_from_hdop(hdop: float, uere: float = UERE_M) -> np.ndarray:
    """ENU covariance [m²]: σ_E² = σ_N² = (HDOP·UERE)²/2 (HDOP·UERE is the horizontal RMS
    error), σ_U = VDOP_PER_HDOP·HDOP·UERE."""
    h2 = (hdop * uere) ** 2
    return np.diag([h2 / 2.0, h2 / 2.0, (VDOP_PER_HDOP * hdop * uere) ** 2])


@dataclass(frozen=True)
class GpsSerialStatus:
    """Counters of a :class:`GpsSerialSource` (abstract state)."""

    bytes_read: int = 0
    sentences: int = 0  #: sentences cut from the stream (good and bad)
    bad_sentences: int = 0  #: sentences that raised NmeaError (checksum, syntax ...)
    fixes: int = 0  #: GGA sentences applied to the fix


class GpsSerialSource(DeviceSource[GpsFix, GpsSerialStatus]):
    """Fixes from an NMEA receiver on ``port``.

    .. pydrake_system::

        name: GpsSerialSource
        output_ports:
        - gps
        - diagnostics

    A periodic unrestricted update every ``period`` seconds (first at t = 0) reads the bytes
    available on the serial port, cuts them into sentences and decodes them; sentences that do
    not decode are counted (``bad_sentences``) and skipped. ``gps`` is the last
    :class:`~usvdrake.sensors.messages.GpsFix` (WGS84; ``datum`` names the origin of the local
    ENU frame downstream consumers use, kept for them as :attr:`datum`):

    * GGA: latitude, longitude, altitude (MSL + geoid separation = ellipsoidal height when the
      separation is present, else MSL), HDOP, satellites, ``valid`` = fix quality > 0, and
      ``covariance_enu`` from :func:`covariance_from_hdop` (UERE = 3 m).
    * RMC (status A) and VTG: speed over ground [m/s] and course, converted from degrees true
      (clockwise from north) to ENU radians counter-clockwise from east:
      ``course = π/2 − radians(cog)``; an empty course field keeps the previous course.

    ``time`` is the simulation time of the update that received the sentence. The fix and the
    :class:`GpsSerialStatus` counters are abstract state; the transport and the partial-line
    buffer are I/O on the system object, as for every
    :class:`~hardware_io.systems.device_source.DeviceSource` (contexts share the one port; call
    :meth:`close` to release it).
    """

    def __init__(
        self,
        port: str,
        baudrate: int,
        datum: Datum | str,
        period: float = 0.05,
        transport: SerialTransport | None = None,
    ):
        self.datum = datum_by_name(datum) if isinstance(datum, str) else datum
        self._stream = NmeaStream()
        super().__init__(
            transport if transport is not None else SerialTransport(port, baudrate),
            "gps",
            GpsFix(),
            GpsSerialStatus(),
            period,
        )

    def poll(self, t: float, fix: GpsFix, st: GpsSerialStatus) -> tuple[GpsFix, GpsSerialStatus]:
        data, _host_time = self.transport.read()
        sentences = self._stream.feed(data) if data else []
        bad = fixes = 0
        for s in sentences:
            try:
                msg = decode(s)
            except NmeaError:
                bad += 1
                continue
            if isinstance(msg, GGA):
                fix = _apply_gga(fix, msg, t)
                fixes += 1
            elif isinstance(msg, RMC) and msg.valid:
                fix = _apply_motion(fix, msg.speed_over_ground_mps, msg.course_over_ground_deg, t)
            elif isinstance(msg, VTG):
                speed = msg.speed_mps_from_knots
                if speed is None:
                    speed = msg.speed_mps_from_kmh
                fix = _apply_motion(fix, speed, msg.course_true_deg, t)
        st = replace(
            st,
            bytes_read=st.bytes_read + len(data),
            sentences=st.sentences + len(sentences),
            bad_sentences=st.bad_sentences + bad,
            fixes=st.fixes + fixes,
        )
        return fix, st


def _apply_gga(fix: GpsFix, m: GGA, t: float) -> GpsFix:
    valid = (m.fix_quality or 0) > 0 and m.latitude_deg is not None and m.longitude_deg is not None
    if not valid:
        return replace(fix, time=t, valid=False, satellites=m.satellites or 0)
    altitude = fix.altitude
    if m.altitude_msl_m is not None:
        altitude = m.altitude_msl_m + (m.geoid_separation_m or 0.0)
    hdop = m.hdop if m.hdop is not None else 99.0
    return replace(
        fix,
        time=t,
        valid=True,
        latitude=m.latitude_deg,
        longitude=m.longitude_deg,
        altitude=altitude,
        hdop=hdop,
        satellites=m.satellites or 0,
        covariance_enu=covariance_from_hdop(hdop),
    )


def _apply_motion(fix: GpsFix, speed: float | None, cog_deg: float | None, t: float) -> GpsFix:
    if speed is None and cog_deg is None:
        return fix
    return replace(
        fix,
        time=t,
        speed=fix.speed if speed is None else speed,
        course=fix.course if cog_deg is None else math.pi / 2 - math.radians(cog_deg),
    )
