"""Pure-Python device models (no Drake, no I/O) for the HIL emulators and tests.

Each model turns simulated sensor messages into the bytes the real device sends, and reacts to
the bytes a host sends it, using only the codecs in :mod:`hardware_io.codecs`. A model is fed
whatever arrived on the wire (split anywhere, garbage included) and returns the reply bytes;
put it behind a :class:`~hardware_io.emulators.pty_link.PtyDevice` (serial) or a UDP socket to
emulate the
sensor for a host driver.

* :class:`RplidarDevice`: Slamtec RPLIDAR A1 (serial, 115200 8N1).
* :class:`ScipDevice`: Hokuyo UTM-30LX speaking SCIP 2.0 (USB CDC-ACM, the baud rate is moot).
* :class:`XsensDevice`: Xsens MTi (Xbus MTData2 output, default 115200 8N1).
* :class:`Vlp16Device`: Velodyne VLP-16 data packets (UDP port 2368), output only.

The models are deliberately forgiving about timing (a reply is produced as soon as a request is
complete; the RPLIDAR's "wait 1 ms after STOP" or the SCIP motor spin-up are not modelled) and
strict about bytes: everything they emit decodes with the project's codecs.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from hardware_io.codecs import imu as mt
from hardware_io.codecs import rplidar as rp
from hardware_io.codecs import scip
from hardware_io.codecs import velodyne as vlp
from hardware_io.codecs.imu import MID_GOTO_MEASUREMENT, MID_GOTO_MEASUREMENT_ACK
from usvdrake.sensors.messages import ImuSample, LaserScan, PointCloud

__all__ = ["RplidarDevice", "ScipDevice", "Vlp16Device", "XsensDevice"]


# ------------------------------------------------------------------------------------------
# RPLIDAR A1


class RplidarDevice:
    """A Slamtec RPLIDAR A1 on its serial line.

    Requests (:func:`feed`): ``A5 cmd`` or, with bit 7 of ``cmd`` set, ``A5 cmd size payload
    xor``; bytes before an ``0xA5`` and payload requests with a wrong XOR are skipped
    (``ignored_bytes``). Replies:

    ======================  ===================================================================
    SCAN ``A5 20``          descriptor ``A5 5A 05 00 00 40 81``; :attr:`scanning` becomes True
    STOP ``A5 25``          nothing; scanning stops
    RESET ``A5 40``         nothing (the real A1 prints an ASCII boot banner that hosts discard;
                            not modelled); scanning stops
    GET_INFO ``A5 50``      descriptor ``A5 5A 14 00 00 00 04`` + model, firmware minor, firmware
                            major, hardware, 16-byte serial number (20 bytes)
    GET_HEALTH ``A5 52``    descriptor ``A5 5A 03 00 00 00 06`` + status (0 good) + uint16 LE
                            error code (0)
    ======================  ===================================================================

    GET_INFO / GET_HEALTH are ignored while scanning (the host must STOP first), as are unknown
    commands and payload commands such as SET_MOTOR_PWM ``0xF0`` (the A1's motor is driven by
    the adapter's DTR line, not by requests).

    :meth:`scan_bytes` is one revolution as measurement nodes (5 bytes each, the first with the
    start flag; ¼ mm and 1/64° quantisation, see :func:`hardware_io.codecs.rplidar.
    laser_scan_to_nodes`) while scanning, else ``b""``.
    """

    #: GET_INFO fields of an A1M8 (model 0x18, firmware 1.29, hardware 7)
    MODEL = 0x18
    FIRMWARE = (1, 29)  # (major, minor)
    HARDWARE = 7

    def __init__(self, quality: int = 15, serial_number: bytes = bytes(range(16))):
        if len(serial_number) != 16:
            raise ValueError("serial_number must be 16 bytes")
        self.quality = quality
        self.serial_number = bytes(serial_number)
        self.scanning = False
        self.requests = 0  #: complete requests received (known or not)
        self.ignored_bytes = 0  #: bytes skipped while looking for 0xA5 / bad payload requests
        self.revolutions = 0  #: revolutions sent by :meth:`scan_bytes`
        self._buf = bytearray()

    def feed(self, data: bytes) -> bytes:
        """Consume host bytes; return the device's reply bytes (possibly ``b""``)."""
        self._buf += bytes(data)
        buf, out, i = self._buf, bytearray(), 0
        while i < len(buf):
            if buf[i] != rp.SYNC_BYTE:
                self.ignored_bytes += 1
                i += 1
                continue
            if len(buf) - i < 2:
                break
            cmd = buf[i + 1]
            if cmd & rp.CMD_FLAG_HAS_PAYLOAD:
                if len(buf) - i < 3:
                    break
                total = 4 + buf[i + 2]
                if len(buf) - i < total:
                    break
                x = 0
                for b in buf[i : i + total - 1]:
                    x ^= b
                if x != buf[i + total - 1]:
                    self.ignored_bytes += 1
                    i += 1
                    continue
                self.requests += 1
                i += total
                continue  # payload commands: accepted, no reply
            i += 2
            self.requests += 1
            out += self._handle(cmd)
        del buf[:i]
        return bytes(out)

    def _handle(self, cmd: int) -> bytes:
        if cmd == rp.CMD_SCAN:
            self.scanning = True
            return rp.SCAN_DESCRIPTOR
        if cmd in (rp.CMD_STOP, rp.CMD_RESET):
            self.scanning = False
            return b""
        if self.scanning:
            return b""
        if cmd == rp.CMD_GET_INFO:
            major, minor = self.FIRMWARE
            return (
                rp.encode_descriptor(rp.ResponseDescriptor(20, 0, rp.ANS_TYPE_DEVINFO))
                + bytes([self.MODEL, minor, major, self.HARDWARE])
                + self.serial_number
            )
        if cmd == rp.CMD_GET_HEALTH:
            return rp.encode_descriptor(rp.ResponseDescriptor(3, 0, rp.ANS_TYPE_DEVHEALTH)) + (
                b"\x00\x00\x00"
            )
        return b""

    def scan_bytes(self, scan: LaserScan) -> bytes:
        """The node stream of one revolution while scanning, else ``b""``."""
        if not self.scanning:
            return b""
        self.revolutions += 1
        return b"".join(rp.encode_node(n) for n in rp.laser_scan_to_nodes(scan, self.quality))


# ------------------------------------------------------------------------------------------
# Hokuyo UTM-30LX (SCIP 2.0)

#: Distance [mm] sent for a beam without a return: an error code below DMIN (the UTM-30LX
#: reports values < 20 mm as error codes), so hosts read it as "no return".
SCIP_NO_RETURN_MM = 1

_SCIP_STATUS_OK = "00"
_SCIP_STATUS_DATA = "99"
_SCIP_LASER_ALREADY_ON = "02"
_SCIP_STATUS_BAD_STEP = "04"  # MD/GD: end step out of range
_SCIP_STATUS_LASER_OFF = "10"  # GD/GS with the laser off
_SCIP_STATUS_BAD_PARAMS = "0C"  # command with insufficient/invalid parameters
_SCIP_STATUS_UNDEFINED = "0E"  # undefined command


class ScipDevice:
    """A Hokuyo UTM-30LX (SCIP 2.0) on its USB serial line.

    Commands (:meth:`feed`) are lines ended by LF (a CR is also accepted and dropped). Replies,
    each an echo of the command, a status line and a blank line (see
    :mod:`hardware_io.codecs.scip`):

    * ``SCIP2.0``: status ``00`` (the UTM-30LX speaks only SCIP 2.0; the mode switch of the
      URG-04LX is accepted as a no-op) -- ``SCIP2.0\\n00P\\n\\n``.
    * ``BM``: laser on, ``00`` (``02`` if it already was). ``QT``: laser off and any MD/MS
      stopped, ``00``. ``RS``: the same plus GD requests dropped, ``00``.
    * ``VV`` / ``PP`` / ``II``: ``00`` and the info lines (``PP``: ``DMIN:23``, ``DMAX:30000``,
      ``ARES:1440``, ``AMIN:0``, ``AMAX:1080``, ``AFRT:540``, ``SCAN:2400`` for the default
      geometry).
    * ``MD``/``MS ssss eeee cc i nn``: ``00`` and the laser on; from then on every
      :meth:`scan_bytes` (one revolution, 25 ms on the real sensor) after skipping ``i`` of them
      yields one data response (status ``99``, echo with the remaining number of scans, ``00``
      for an unlimited ``nn = 00``) until ``nn`` scans were sent or QT/RS. An end step beyond
      AMAX: status ``04``.
    * ``GD``/``GS``: answered by the next :meth:`scan_bytes` with status ``00`` and that scan;
      with the laser off: status ``10`` at once.
    * A line that does not decode: echoed with status ``0C`` if it starts with a known command
      name, else ``0E``.

    Distances: each step takes the nearest beam of the :class:`LaserScan` (within half a
    ``angle_increment``), rounded to 1 mm; invalid / missing beams are sent as
    :data:`SCIP_NO_RETURN_MM`; a cluster reports the smallest valid distance of its steps. The
    timestamp is ``round(scan.time · 1000) mod 2**24`` ms. Values that do not fit the encoding
    (MS/GS: 2 characters, 4095 mm; MD/GD: 262143 mm) are clipped.
    """

    def __init__(self, geometry: scip.SensorGeometry = scip.UTM30LX):
        self.geometry = geometry
        self.laser_on = False
        self.command: scip.ScipCommand | None = None  #: the running MD/MS, if any
        self.commands = 0  #: command lines received
        self.bad_commands = 0  #: lines answered with 0C / 0E
        self.scans_sent = 0  #: MD/MS/GD/GS data responses sent
        self._remaining = 0  # MD/MS scans left (0 = unlimited)
        self._skip = 0  # revolutions left to skip before the next MD/MS scan
        self._pending: list[scip.ScipCommand] = []  # GD/GS waiting for the next revolution
        self._buf = bytearray()

    # -- host commands -------------------------------------------------------------------

    def feed(self, data: bytes) -> bytes:
        """Consume host bytes; return the replies to every complete command line."""
        self._buf += bytes(data).replace(b"\r", b"\n")
        out = bytearray()
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                break
            line = bytes(self._buf[:i])
            del self._buf[: i + 1]
            if line:
                self.commands += 1
                out += self._handle(line)
        if len(self._buf) > 256:  # no SCIP command is that long: drop line noise
            del self._buf[:-64]
        return bytes(out)

    def _raw_reply(self, line: bytes, status: str) -> bytes:
        s = status.encode("ascii")
        return line + b"\n" + s + bytes([scip.checksum(s)]) + b"\n\n"

    def _handle(self, line: bytes) -> bytes:
        if line == b"SCIP2.0":
            return self._raw_reply(line, _SCIP_STATUS_OK)
        try:
            c = scip.decode_command(line)
        except scip.ScipError:
            self.bad_commands += 1
            known = line[:2].decode("latin-1") in scip.KNOWN_COMMANDS
            return self._raw_reply(
                line, _SCIP_STATUS_BAD_PARAMS if known else _SCIP_STATUS_UNDEFINED
            )
        g = self.geometry
        if c.name == "BM":
            status = _SCIP_LASER_ALREADY_ON if self.laser_on else _SCIP_STATUS_OK
            self.laser_on = True
            return scip.encode_response(c, status)
        if c.name in ("QT", "RS"):
            self.laser_on, self.command = False, None
            if c.name == "RS":
                self._pending.clear()
            return scip.encode_response(c, _SCIP_STATUS_OK)
        if c.name in scip.INFO_COMMANDS:
            return scip.encode_response(c, _SCIP_STATUS_OK, self._info(c.name))
        # scan commands
        if c.end_step > g.steps - 1:
            return scip.encode_response(c, _SCIP_STATUS_BAD_STEP)
        if c.name in ("MD", "MS"):
            self.command, self.laser_on = c, True
            self._remaining, self._skip = c.num_scans, 0
            return scip.encode_response(c, _SCIP_STATUS_OK)
        if not self.laser_on:
            return scip.encode_response(c, _SCIP_STATUS_LASER_OFF)
        self._pending.append(c)
        return b""

    def _info(self, name: str) -> list[bytes]:
        g = self.geometry
        if name == "VV":
            lines = [
                "VEND:Hokuyo Automatic Co.,Ltd.",
                "PROD:SOKUIKI Sensor TOP-URG UTM-30LX",
                "FIRM:1.1.3(usvdrake emulator)",
                "PROT:SCIP 2.0",
                "SERI:H0000000",
            ]
        elif name == "PP":
            lines = [
                "MODL:UTM-30LX",
                f"DMIN:{round(g.range_min * 1000)}",
                f"DMAX:{round(g.range_max * 1000)}",
                f"ARES:{round(360.0 / g.step_deg)}",
                "AMIN:0",
                f"AMAX:{g.steps - 1}",
                f"AFRT:{g.front_step}",
                f"SCAN:{round(60.0 / g.scan_time)}",
            ]
        else:
            lines = [
                "MODL:UTM-30LX",
                f"LASR:{'ON' if self.laser_on else 'OFF'}",
                f"SCSP:Initial({round(60.0 / g.scan_time)}[rpm])",
                f"MESM:{'Measuring' if self.command else 'Idle'}",
                "SBPS:USB only",
                "TIME:000000",
                "STAT:Sensor works well.",
            ]
        return [s.encode("ascii") for s in lines]

    # -- measurements --------------------------------------------------------------------

    def step_distances_mm(self, scan: LaserScan) -> np.ndarray:
        """Distance [mm] of every step 0 .. steps-1 (``SCIP_NO_RETURN_MM`` = no return)."""
        g = self.geometry
        n = len(scan.ranges)
        out = np.full(g.steps, SCIP_NO_RETURN_MM, np.int64)
        if n == 0 or not scan.angle_increment:
            return out
        a = np.radians(g.step0_deg + g.step_deg * np.arange(g.steps))
        inc = float(scan.angle_increment)
        j = np.rint((a - scan.angle_min) / inc).astype(np.int64)
        inside = (j >= 0) & (j < n)
        jj = np.clip(j, 0, n - 1)
        close = np.abs(a - (scan.angle_min + jj * inc)) <= abs(inc) / 2 + 1e-9
        r = np.asarray(scan.ranges, float)[jj]
        ok = inside & close & np.asarray(scan.valid, bool)[jj] & np.isfinite(r) & (r >= 0)
        out[ok] = np.rint(r[ok] * 1000.0).astype(np.int64)
        return out

    def _scan_data(self, c: scip.ScipCommand, status: str, scan: LaserScan) -> bytes:
        steps = self.step_distances_mm(scan)[c.start_step : c.end_step + 1]
        k = max(c.cluster_count, 1)
        hi = (1 << (6 * scip.SCAN_COMMANDS[c.name])) - 1
        values = []
        for i in range(0, len(steps), k):
            v = steps[i : i + k]
            v = v[v >= 20]  # smallest valid distance; error codes only if nothing else
            values.append(int(min(v.min(), hi)) if v.size else SCIP_NO_RETURN_MM)
        ts = round(float(scan.time) * 1000.0) % (1 << 24)
        self.scans_sent += 1
        return scip.encode_scan_data(scip.ScanData(c, status, ts, tuple(values)))

    def scan_bytes(self, scan: LaserScan) -> bytes:
        """One revolution: the answers to pending GD/GS and, if an MD/MS runs, its data
        response (``b""`` if nothing is due)."""
        out = bytearray()
        for c in self._pending:
            out += self._scan_data(c, _SCIP_STATUS_OK, scan)
        self._pending.clear()
        c = self.command
        if c is None:
            return bytes(out)
        if self._skip > 0:
            self._skip -= 1
            return bytes(out)
        self._skip = c.scan_interval
        if c.num_scans:
            self._remaining -= 1
            echo = replace(c, num_scans=self._remaining)
            if self._remaining <= 0:
                self.command = None
        else:
            echo = c
        out += self._scan_data(echo, _SCIP_STATUS_DATA, scan)
        return bytes(out)


# ------------------------------------------------------------------------------------------
# Xsens MTi

MID_REQ_DID = 0x00
MID_DEVICE_ID = 0x01
MID_REQ_PRODUCT_CODE = 0x1C
MID_PRODUCT_CODE = 0x1D
MID_GOTO_CONFIG = 0x30
MID_GOTO_CONFIG_ACK = 0x31
MID_WAKEUP = 0x3E
MID_WAKEUP_ACK = 0x3F
MID_RESET = 0x40
MID_RESET_ACK = 0x41
MID_SET_OUTPUT_CONFIGURATION = 0xC0
MID_OUTPUT_CONFIGURATION = 0xC1


class XsensDevice:
    """An Xsens MTi streaming MTData2 (Xbus, BID 0xFF) on its serial line.

    :meth:`sample_bytes`: one MTData2 message per sample in measurement mode (PacketCounter,
    SampleTimeFine, Quaternion, Acceleration, RateOfTurn as float32 -- see
    :func:`hardware_io.codecs.imu.from_imu_sample`), the packet counter incrementing by one
    per message (uint16, wraps); ``b""`` in config mode. The device starts in measurement mode
    (as an MTi does when the host does not answer its WakeUp).

    :meth:`feed` answers host messages (checksum-valid Xbus frames; anything else is skipped,
    ``ignored_bytes``):

    ==========================  ==============================================================
    GoToConfig 0x30             ack 0x31, config mode
    GoToMeasurement 0x10        ack 0x11, measurement mode (``FA FF 11 00 F0``)
    ReqDID 0x00                 DeviceID 0x01, uint32 :attr:`device_id`
    ReqProductCode 0x1C         ProductCode 0x1D, ASCII :attr:`product_code`
    SetOutputConfiguration C0   ack 0xC1 echoing the requested configuration (not applied)
    Reset 0x40                  ack 0x41, then WakeUp 0x3E; measurement mode
    WakeUpAck 0x3F              config mode
    ==========================  ==============================================================

    Other messages are ignored.
    """

    def __init__(self, device_id: int = 0x03301234, product_code: str = "MTi-30-2A8G4"):
        self.device_id = device_id
        self.product_code = product_code
        self.measuring = True
        self.packet_counter = 0  #: counter of the next MTData2 message
        self.messages = 0  #: host messages received
        self.ignored_bytes = 0
        self._buf = bytearray()

    def sample_bytes(self, sample: ImuSample) -> bytes:
        if not self.measuring:
            return b""
        frame = mt.encode_mtdata2(mt.from_imu_sample(sample, self.packet_counter))
        self.packet_counter = (self.packet_counter + 1) & 0xFFFF
        return frame

    def feed(self, data: bytes) -> bytes:
        self._buf += bytes(data)
        buf, out = self._buf, bytearray()
        while True:
            i = buf.find(bytes([mt.PREAMBLE]))
            if i < 0:
                self.ignored_bytes += len(buf)
                buf.clear()
                break
            if i:
                self.ignored_bytes += i
                del buf[:i]
            if len(buf) < 4:
                break
            if buf[3] == 0xFF:
                if len(buf) < 6:
                    break
                size, n = 6, (buf[4] << 8) | buf[5]
            else:
                size, n = 4, buf[3]
            if n > mt.MAX_PAYLOAD:
                self.ignored_bytes += 1
                del buf[:1]
                continue
            total = size + n + 1
            if len(buf) < total:
                break
            try:
                _bid, mid, payload = mt.decode_frame(bytes(buf[:total]))
            except mt.MtError:
                self.ignored_bytes += 1
                del buf[:1]
                continue
            del buf[:total]
            self.messages += 1
            out += self._handle(mid, payload)
        return bytes(out)

    def _handle(self, mid: int, payload: bytes) -> bytes:
        if mid == MID_GOTO_CONFIG:
            self.measuring = False
            return mt.encode_frame(MID_GOTO_CONFIG_ACK, b"")
        if mid == MID_GOTO_MEASUREMENT:
            self.measuring = True
            return mt.encode_frame(MID_GOTO_MEASUREMENT_ACK, b"")
        if mid == MID_REQ_DID:
            return mt.encode_frame(MID_DEVICE_ID, self.device_id.to_bytes(4, "big"))
        if mid == MID_REQ_PRODUCT_CODE:
            return mt.encode_frame(MID_PRODUCT_CODE, self.product_code.encode("ascii"))
        if mid == MID_SET_OUTPUT_CONFIGURATION:
            return mt.encode_frame(MID_OUTPUT_CONFIGURATION, payload)
        if mid == MID_RESET:
            self.measuring = True
            return mt.encode_frame(MID_RESET_ACK, b"") + mt.encode_frame(MID_WAKEUP, b"")
        if mid == MID_WAKEUP_ACK:
            self.measuring = False
        return b""


# ------------------------------------------------------------------------------------------
# Velodyne VLP-16


class Vlp16Device:
    """Velodyne VLP-16 data packets (1206-byte UDP payloads) from simulated sweeps.

    :meth:`sweep_packets` turns a :class:`PointCloud` with 16 rings (``elevations`` the VLP-16's
    -15° .. 15° in 2° steps, within 0.1°) into firings, one per column, sent in the sensor's
    order: increasing Velodyne azimuth α = −azimuth (clockwise from forward) starting at 0°.
    Firings are packed 24 to a packet (12 blocks × 2 firings, strongest-return mode); a partial
    packet is kept for the next sweep. Distances are rounded to 2 mm, no return (``inf``) or
    beyond 131.07 m is sent as 0; reflectivity is ``reflectivity`` for every return. Only the
    first firing of each block carries its azimuth (the host interpolates the second one), so
    columns should be evenly spaced (e.g. 1800 columns of 0.2°, the VLP-16 at 600 rpm).

    The device clock (timestamp, µs past the hour) starts at 0 and advances 55.296 µs per
    firing -- the VLP-16's firing period, not the simulated sweep times.
    """

    def __init__(self, reflectivity: int = 100):
        self.reflectivity = int(reflectivity)
        self.firings_sent = 0
        self._pending: list[vlp.Firing] = []
        self._first_index = 0  # firing index of the first pending firing

    def sweep_packets(self, cloud: PointCloud) -> list[bytes]:
        image = np.asarray(cloud.range_image, float)
        elev = np.degrees(np.asarray(cloud.elevations, float))
        if image.shape[0] != vlp.LASERS or elev.shape != (vlp.LASERS,):
            raise ValueError(f"a VLP-16 sweep has 16 rings, got {image.shape[0]}")
        if np.max(np.abs(elev - vlp.RING_ELEVATIONS_DEG)) > 0.1:
            raise ValueError("ring elevations are not the VLP-16's -15 .. 15 deg")
        alpha = np.mod(-np.degrees(np.asarray(cloud.azimuths, float)), 360.0)
        alpha = np.where(np.rint(alpha * 100.0) >= 36000, 0.0, alpha)
        refl = (self.reflectivity,) * vlp.LASERS
        for col in np.argsort(alpha, kind="stable"):
            r = image[vlp.LASER_RING, col]  # by laser id
            d = tuple(
                float(v) if math.isfinite(v) and 0 <= v <= vlp.MAX_DISTANCE_M else 0.0 for v in r
            )
            self._pending.append(
                vlp.Firing(
                    float(alpha[col]),
                    d,
                    tuple(rv if x > 0 else 0 for rv, x in zip(refl, d, strict=True)),
                )
            )
        out = []
        per = 2 * vlp.BLOCKS
        while len(self._pending) >= per:
            firings, self._pending = self._pending[:per], self._pending[per:]
            ts = round(self._first_index * vlp.SEQUENCE_US) % vlp.US_PER_HOUR
            out.append(vlp.encode_firings(firings, ts))
            self._first_index += per
            self.firings_sent += per
        return out
