"""``McuFirmware``: a pure-Python model of the thruster microcontroller's firmware.

What the STM32 (Roboat II) / Arduino (NTNU round vessel, Ueland 2017) does with the protocol of
``hardware_io/PROTOCOL.md`` (codec: :mod:`hardware_io.codecs.thrust`), without Drake and without
I/O, so a device emulator (a :class:`~hardware_io.emulators.pty_link.PtyDevice` loop) and tests
can stand in for the board:

* :meth:`McuFirmware.feed` — received bytes → :class:`~hardware_io.codecs.thrust.FrameParser`;
  each valid command frame with the right number of channels sets the outputs (PWM clamped to
  1100 … 1900 µs, angles as sent), records the time and ``seq`` and clears the watchdog.
  Frames with another channel count are counted (``frames_rejected``) and ignored; corrupted
  bytes are skipped by the parser and counted (``parser_errors``).
* :meth:`McuFirmware.tick` — the firmware's main-loop tick (every :data:`TICK_PERIOD_S` or
  faster on the board): the watchdog. More than ``timeout_s`` (PROTOCOL.md: 150 ms,
  :data:`~hardware_io.codecs.thrust.WATCHDOG_TIMEOUT_S`) after the last valid command, or before
  the first one, every ESC output is 1500 µs and status bit ``WATCHDOG_TRIPPED`` is set; the
  azimuth servos hold their angle. So the outputs reach neutral within ``timeout_s`` + one tick
  of the last frame.
* :meth:`McuFirmware.telemetry` — a telemetry frame: ``seq`` echo, status, battery and the PWM
  actually output. RPM is not sent (flag bit 0 clear): this model has no motor dynamics and we
  have no source figure for the T200's speed curve, so inventing RPM would add nothing a host
  could check.

All times are the caller's clock in seconds (``time.monotonic()`` in an emulator, simulated time
in a unit test); nothing here reads a clock.
"""

from __future__ import annotations

import numpy as np

from hardware_io import thrust_curve as tc
from hardware_io.codecs import thrust as th

__all__ = ["TICK_PERIOD_S", "UNDERVOLTAGE_MV", "McuFirmware"]

#: [s] Longest interval between two watchdog ticks of the firmware's main loop (PROTOCOL.md:
#: outputs are neutral within the watchdog timeout + one tick of the last frame).
TICK_PERIOD_S = 0.010
#: [mV] UNDERVOLTAGE threshold of this model: 3.5 V per cell of a 4S Li-ion/LiPo pack (our
#: choice; PROTOCOL.md leaves the threshold to the firmware).
UNDERVOLTAGE_MV = 14000


class McuFirmware:
    """The thruster MCU: ``n_channels`` ESC outputs (and servo angles if ``azimuth``).

    Args:
        n_channels: number of channels the board drives (1 … 16); command frames for another
            number are rejected.
        azimuth: the channels carry servo angles (NTNU round vessel). A board without servos
            ignores the angles of a frame; a board with servos keeps its angles when a frame
            has none.
        timeout_s: watchdog timeout [s] (PROTOCOL.md, default 150 ms).
        battery_mv: battery voltage [mV] reported in telemetry (attribute, may be changed).

    State (read freely): ``pwm_us`` [µs] and ``angles_cdeg`` [0.01°] as output now, ``seq``
    (last applied, 0 before any), ``last_command_time`` [s] (``None`` before any),
    ``watchdog_tripped``, ``watchdog_trip_time`` [s] (``now`` of the tick that tripped after the
    last valid command; ``None`` at power-up and after a new command), counters
    ``frames_ok``, ``frames_rejected``, ``parser_errors``, ``seq_gaps``, ``watchdog_trips`` (and
    their times ``trip_times``), ``telemetry_sent``. Set ``esc_fault = True`` to report status bit
    ``ESC_FAULT``.
    """

    def __init__(
        self,
        n_channels: int,
        azimuth: bool = False,
        timeout_s: float = th.WATCHDOG_TIMEOUT_S,
        battery_mv: int = 16000,
    ):
        if not 1 <= n_channels <= th.MAX_CHANNELS:
            raise ValueError(f"n_channels {n_channels} outside [1, {th.MAX_CHANNELS}]")
        if timeout_s <= 0.0:
            raise ValueError(f"timeout_s must be positive, got {timeout_s}")
        self.n_channels = n_channels
        self.azimuth = azimuth
        self.timeout_s = float(timeout_s)
        self.battery_mv = int(battery_mv)
        self.esc_fault = False
        self.parser = th.FrameParser()
        self._neutral = (tc.PWM_NEUTRAL,) * n_channels
        self.pwm_us: tuple[int, ...] = self._neutral  # power-up: ESCs armed at neutral
        self.angles_cdeg: tuple[int, ...] = (0,) * n_channels
        self.seq = 0
        self.last_command_time: float | None = None
        self.watchdog_tripped = True  # counts as tripped until the first command
        self.watchdog_trip_time: float | None = None
        self.watchdog_trips = 0  # trips after a valid command (not the power-up state)
        self.trip_times: list[float] = []  # ``now`` of each of those trips
        self.frames_ok = 0
        self.frames_rejected = 0
        self.seq_gaps = 0
        self.telemetry_sent = 0
        self.telemetry_frames_ignored = 0  # frames of type telemetry arriving at the MCU

    # ------------------------------------------------------------------ receive + watchdog

    @property
    def parser_errors(self) -> int:
        """Corrupted candidate frames skipped by the parser (CRC + header/content errors)."""
        return self.parser.crc_errors + self.parser.frame_errors

    def feed(self, data: bytes, now: float) -> None:
        """Bytes received at ``now`` [s]; applies every valid command frame among them."""
        for msg in self.parser.feed(data):
            if not isinstance(msg, th.ThrustCommand):
                self.telemetry_frames_ignored += 1
                continue
            if len(msg.pwm_us) != self.n_channels:
                self.frames_rejected += 1
                continue
            self.pwm_us = tuple(int(min(max(p, tc.PWM_MIN), tc.PWM_MAX)) for p in msg.pwm_us)
            if self.azimuth and msg.angles_cdeg is not None:
                self.angles_cdeg = tuple(int(a) for a in msg.angles_cdeg)
            if self.last_command_time is not None and msg.seq != (self.seq + 1) & 0xFFFF:
                self.seq_gaps += 1
            self.seq = msg.seq
            self.last_command_time = now
            self.frames_ok += 1
            self.watchdog_tripped = False
            self.watchdog_trip_time = None

    def tick(self, now: float) -> None:
        """Watchdog at ``now`` [s]: neutral outputs when no valid command arrived for more than
        ``timeout_s`` (or none ever); ``watchdog_trip_time`` = ``now`` of the tripping tick."""
        if self.last_command_time is not None and now - self.last_command_time <= self.timeout_s:
            return
        if not self.watchdog_tripped:
            self.watchdog_tripped = True
            self.watchdog_trip_time = now
            self.watchdog_trips += 1
            self.trip_times.append(now)
        self.pwm_us = self._neutral  # servos hold their angles

    # ------------------------------------------------------------------ outputs

    @property
    def status(self) -> th.Status:
        s = th.Status(0)
        if self.watchdog_tripped:
            s |= th.Status.WATCHDOG_TRIPPED
        if self.esc_fault:
            s |= th.Status.ESC_FAULT
        if self.battery_mv < UNDERVOLTAGE_MV:
            s |= th.Status.UNDERVOLTAGE
        return s

    def forces(self) -> np.ndarray:
        """Thrust [N] per channel the propellers push now (T200 16 V curve of the PWM)."""
        return np.atleast_1d(tc.pwm_to_force(np.array(self.pwm_us, dtype=float)))

    def command_vector(self, thrusters) -> np.ndarray:
        """The outputs in the diagrams' ``thruster_command`` layout for ``thrusters``
        (:class:`usvdrake.vessel.Thruster`, one per channel): [f] per fixed thruster and
        [f, α] per azimuth (force [N], angle [rad]); feeds the simulated plant."""
        if len(thrusters) != self.n_channels:
            raise ValueError(f"{len(thrusters)} thrusters for {self.n_channels} channels")
        f = self.forces()
        out = []
        for i, t in enumerate(thrusters):
            out.append(float(f[i]))
            if t.azimuth:
                out.append(float(np.deg2rad(self.angles_cdeg[i] / 100.0)))
        return np.array(out)

    def telemetry(self, now: float) -> bytes:
        """Ticks the watchdog at ``now`` [s], then encodes a telemetry frame: ``seq`` of the
        last applied command, status, battery [mV], output PWM [µs] per channel (no RPM)."""
        self.tick(now)
        self.telemetry_sent += 1
        return th.encode_telemetry(self.seq, self.status, self.battery_mv, pwm_us=self.pwm_us)
