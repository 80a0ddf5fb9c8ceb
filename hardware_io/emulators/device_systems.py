"""The emulated devices of the HIL rig as Drake systems, driven by the simulated station.

Each system owns a :class:`~hardware_io.emulators.pty_link.PtyDevice` (the device end of a
pseudo-terminal) and plays one real device on it, in the protocol the hardware station's serial
source speaks:

* :class:`McuEmulator` — the thruster microcontroller (``hardware_io/PROTOCOL.md``): reads
  command frames, runs the firmware watchdog, outputs the forces its PWM makes through the T200
  curve as the simulated station's ``thruster_command``, and sends telemetry back.
* :class:`GpsEmulator` — an NMEA 0183 receiver sending GGA: the simulated station's ``gps``
  fix when the scenario simulates a GPS, else an RTK-class fix made from the true position with
  the pose sensor's σ (Roboat II eq. 16: RT = 0.0005 m² → σ ≈ 2.2 cm), fix quality 4.
* :class:`RplidarEmulator` — a Slamtec RPLIDAR A1 sending the simulated 2D scans.
* :class:`ImuEmulator` — an Xsens MTi sending MTData2 (quaternion, acceleration, rate of
  turn): the simulated ``imu`` when simulated, else an AHRS from the true heading and yaw rate
  with the pose sensor's σψ, σr.

These are I/O programs, not models: the devices (firmware, noise generators, ptys) live on the
system objects and the emulator diagram is simulated once, in real time.
"""

from __future__ import annotations

import math
import time

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from hardware_io.codecs.imu import encode_mtdata2, from_imu_sample
from hardware_io.codecs.nmea import GGA, encode_gga
from hardware_io.emulators.devices import RplidarDevice
from hardware_io.emulators.firmware import McuFirmware
from hardware_io.emulators.pty_link import PtyDevice
from usvdrake.sensors.geodesy import LocalFrame
from usvdrake.sensors.imu_model import yaw_quaternion
from usvdrake.sensors.messages import GpsFix, ImuSample, LaserScan
from usvdrake.systems.vessel.thrusters import command_size

__all__ = ["GpsEmulator", "ImuEmulator", "McuEmulator", "RplidarEmulator", "TruthRecorder"]

GRAVITY = 9.80665  # [m/s²]


class McuEmulator(LeafSystem):
    """The thruster microcontroller on ``pty``.

    Every ``tick`` seconds (first at 0): read the host's bytes, feed them to the
    :class:`~hardware_io.emulators.firmware.McuFirmware` with the wall-clock time, run its
    watchdog, and hold the forces of the PWM it outputs (the station's ``thruster_command`` layout)
    in discrete state; every ``telemetry_period`` send a telemetry frame.
    """

    def __init__(
        self,
        thrusters,
        pty: PtyDevice,
        firmware: McuFirmware,
        tick: float = 0.005,
        telemetry_period: float = 0.02,
    ):
        super().__init__()
        self.thrusters, self.pty, self.firmware = thrusters, pty, firmware
        self._every = max(1, round(telemetry_period / tick))
        self._ticks = 0
        self._command = self.DeclareDiscreteState(command_size(thrusters))
        self.DeclarePeriodicDiscreteUpdateEvent(tick, 0.0, self._update)
        self.DeclareStateOutputPort("thruster_command", self._command)

    def _update(self, context, discrete_state):
        now = time.monotonic()
        data = self.pty.read()
        if data:
            self.firmware.feed(data, now)
        self.firmware.tick(now)
        self._ticks += 1
        if self._ticks % self._every == 0:
            self.pty.write(self.firmware.telemetry(now))
        vec = self.firmware.command_vector(self.thrusters)
        discrete_state.get_mutable_vector(self._command).SetFromVector(vec)


class GpsEmulator(LeafSystem):
    """A GNSS receiver on ``pty`` sending a GGA sentence at ``rate_hz``.

    Inputs: ``state`` (ground truth [x y ψ u v r]) and, with ``simulated_gps``, ``gps`` (the
    simulated station's :class:`GpsFix`, sent as it is: quality 1 when valid, 0 when not).
    Without it the fix is RTK-like: true position plus N(0, σ²) per axis, quality 4, HDOP 0.7.
    """

    def __init__(
        self,
        pty: PtyDevice,
        datum,
        rate_hz: float = 20.0,
        position_std: float = math.sqrt(0.0005),
        simulated_gps: bool = False,
        seed: int = 0,
    ):
        super().__init__()
        self.pty = pty
        self._frame = LocalFrame(datum)
        self._std = position_std
        self._rng = np.random.default_rng(seed)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._gps = (
            self.DeclareAbstractInputPort("gps", AbstractValue.Make(GpsFix()))
            if simulated_gps
            else None
        )
        self.sentences = 0
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._send)

    def _send(self, context):
        self.pty.read()  # receivers accept configuration input; this one ignores it
        t = context.get_time()
        if self._gps is not None:
            fix: GpsFix = self._gps.Eval(context)
            lat, lon, h, quality = fix.latitude, fix.longitude, fix.altitude, 1
            if not fix.valid:
                quality = 0
            hdop, sats = fix.hdop, fix.satellites
        else:
            x, y = self._state.Eval(context)[:2] + self._rng.normal(0.0, self._std, 2)
            lat, lon, h = (float(v) for v in self._frame.to_geodetic(x, y, 0.0))
            quality, hdop, sats = 4, 0.7, 14
        msg = GGA(
            time_of_day_s=round(t % 86400.0, 2),
            latitude_deg=lat if quality else None,
            longitude_deg=lon if quality else None,
            fix_quality=quality,
            satellites=sats,
            hdop=min(hdop, 99.0),
            altitude_msl_m=h if quality else None,
            geoid_separation_m=0.0 if quality else None,
        )
        self.pty.write(encode_gga(msg))
        self.sentences += 1


class ImuEmulator(LeafSystem):
    """An Xsens MTi on ``pty`` sending MTData2 at ``rate_hz``.

    Inputs: ``state`` and, with ``simulated_imu``, ``imu`` (the simulated station's
    :class:`ImuSample`, sent as it is). Without it: orientation = yaw ψ + N(0, σψ²), rate of
    turn z = r + N(0, σr²), specific force = gravity only (an AHRS heading with Roboat II eq. 16's
    σ; the NMHE reads only ψ and r).
    """

    def __init__(
        self,
        pty: PtyDevice,
        rate_hz: float = 100.0,
        yaw_std: float = math.sqrt(0.0005),
        rate_std: float = math.sqrt(0.0001),
        simulated_imu: bool = False,
        seed: int = 0,
    ):
        super().__init__()
        self.pty = pty
        self._std = (yaw_std, rate_std)
        self._rng = np.random.default_rng(seed + 1)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._imu = (
            self.DeclareAbstractInputPort("imu", AbstractValue.Make(ImuSample()))
            if simulated_imu
            else None
        )
        self.counter = 0
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._send)

    def _send(self, context):
        self.pty.read()
        t = context.get_time()
        if self._imu is not None:
            sample = self._imu.Eval(context)
        else:
            q = self._state.Eval(context)
            yaw = float(q[2]) + self._rng.normal(0.0, self._std[0])
            r = float(q[5]) + self._rng.normal(0.0, self._std[1])
            sample = ImuSample(
                time=t,
                angular_velocity=np.array([0.0, 0.0, r]),
                linear_acceleration=np.array([0.0, 0.0, GRAVITY]),
                orientation=yaw_quaternion(yaw),
            )
        self.pty.write(encode_mtdata2(from_imu_sample(sample, self.counter)))
        self.counter += 1


class TruthRecorder(LeafSystem):
    """Keeps (wall-clock time, simulation time, ground truth) at ``rate_hz`` in :attr:`rows`,
    so the HIL runner can put the truth on the host's clock afterwards."""

    def __init__(self, rate_hz: float = 20.0):
        super().__init__()
        self._state = self.DeclareVectorInputPort("state", 6)
        self.rows: list[list[float]] = []
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._record)

    def _record(self, context):
        q = self._state.Eval(context)
        self.rows.append([time.monotonic(), context.get_time(), *map(float, q)])


class RplidarEmulator(LeafSystem):
    """A Slamtec RPLIDAR A1 on ``pty`` (:class:`hardware_io.emulators.devices.RplidarDevice`).

    Input ``lidar_scan``: the simulated station's :class:`LaserScan`. Every ``poll_period`` it
    answers the host's requests (STOP, SCAN, GET_INFO ...); once the host has started a scan,
    every ``scan_period`` (half a period after each simulated sweep ends, so that sweep is on
    the port) it sends that revolution as measurement nodes.
    """

    def __init__(self, pty: PtyDevice, scan_period: float, poll_period: float = 0.01):
        super().__init__()
        self.pty = pty
        self.device = RplidarDevice()
        self.revolutions = 0
        self._scan = self.DeclareAbstractInputPort("lidar_scan", AbstractValue.Make(LaserScan()))
        self.DeclarePeriodicPublishEvent(poll_period, 0.0, self._answer)
        self.DeclarePeriodicPublishEvent(scan_period, 1.5 * scan_period, self._send_scan)

    def _answer(self, context):
        data = self.pty.read()
        if data:
            self.pty.write(self.device.feed(data))

    def _send_scan(self, context):
        scan = self._scan.Eval(context)
        if self.device.scanning and scan.valid.size:
            self.pty.write(self.device.scan_bytes(scan))
            self.revolutions += 1
