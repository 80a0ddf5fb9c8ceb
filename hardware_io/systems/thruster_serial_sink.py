"""``ThrusterSerialSink``: the thruster microcontroller on a serial port as a Drake system.

Host side of ``hardware_io/PROTOCOL.md`` (codec :mod:`hardware_io.codecs.thrust`, thrust curve
:mod:`hardware_io.thrust_curve`).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from hardware_io import thrust_curve as tc
from hardware_io.codecs import thrust as th
from hardware_io.transport import LinkCounters, SerialTransport
from usvdrake.systems.vessel.thrusters import command_size

__all__ = ["LINK_FIELDS", "NO_TELEMETRY_AGE", "ThrusterLinkStatus", "ThrusterSerialSink"]

#: Entries of the ``thruster_link`` output vector.
LINK_FIELDS = (
    "telemetry_frames",  # telemetry frames received [-]
    "frames_sent",  # command frames written by the sender thread [-]
    "telemetry_age",  # [s] simulated time since the last telemetry frame
    "status",  # status byte of the last telemetry (PROTOCOL.md: bit 0 watchdog, ...)
    "errors",  # corrupted frames (CRC + header/contents) + telemetry with the wrong n [-]
)
#: ``telemetry_age`` [s] reported before any telemetry has arrived.
NO_TELEMETRY_AGE = 1e9


@dataclass(frozen=True)
class ThrusterLinkStatus:
    """Link state of a :class:`ThrusterSerialSink` (abstract state, updated by its event).

    ``frames_sent``, ``neutral_frames`` and ``stale_events`` are copies of the sender thread's
    counters taken at the last update, ``link`` of the transport's.
    """

    bytes_read: int = 0
    telemetry_frames: int = 0
    crc_errors: int = 0  #: candidate frames with a bad CRC
    frame_errors: int = 0  #: bad header / contents, command frames echoed back, wrong n
    last_telemetry: th.Telemetry | None = None
    last_telemetry_time: float | None = None  #: [s] simulated time of the update that got it
    measured_pwm: tuple[int, ...] | None = None  #: [µs] output PWM of the last telemetry
    command: tuple[float, ...] | None = None  #: last command handed to the sender
    frames_sent: int = 0
    neutral_frames: int = 0
    stale_events: int = 0
    link: LinkCounters = LinkCounters()


class _CommandSender:
    """Background (daemon) thread writing the latest command at ``rate_hz`` [Hz] of wall time,
    or neutral frames when no command was handed over for ``stale_timeout`` [s] of wall time.
    Everything shared with the Drake thread is guarded by ``_lock``; transport calls by
    ``io_lock``."""

    def __init__(self, thrusters, transport, io_lock, rate_hz: float, stale_timeout: float):
        self.thrusters = list(thrusters)
        self.transport, self.io_lock = transport, io_lock
        self.interval = 1.0 / rate_hz
        self.stale_timeout = stale_timeout
        self._force_mask = _force_mask(self.thrusters)
        self._lock = threading.Lock()
        self._command: np.ndarray | None = None
        self._handover_time = 0.0
        self._stale = False
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.seq = 0
        self.frames_sent = 0
        self.neutral_frames = 0
        self.stale_events = 0

    def hand_over(self, command: np.ndarray) -> None:
        cmd = np.where(np.isfinite(command), command, 0.0)  # NaN / inf → neutral entries
        with self._lock:
            self._command = cmd
            self._handover_time = time.monotonic()

    def start(self) -> None:
        with self._lock:
            if self._thread is not None or self._stop.is_set():
                return
            self._thread = threading.Thread(
                target=self._run, name="ThrusterSerialSink-sender", daemon=True
            )
            self._thread.start()

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def counters(self) -> tuple[int, int, int]:
        with self._lock:
            return self.frames_sent, self.neutral_frames, self.stale_events

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)

    def _run(self) -> None:
        next_time = time.monotonic()
        while not self._stop.is_set():
            self.send_once()
            next_time += self.interval
            now = time.monotonic()
            if next_time < now - self.interval:  # fell behind (host stalled): no burst
                next_time = now
            self._stop.wait(max(next_time - now, 0.0))

    def send_once(self) -> None:
        with self._lock:
            if self._command is None:
                return
            cmd = self._command
            stale = time.monotonic() - self._handover_time > self.stale_timeout
            if stale and not self._stale:
                self.stale_events += 1
            self._stale = stale
            seq = self.seq
            self.seq = (seq + 1) & 0xFFFF
        if stale:
            cmd = np.where(self._force_mask, 0.0, cmd)  # zero force, angles held
        frame = th.encode_command(seq, *tc.command_to_channels(self.thrusters, cmd))
        with self.io_lock:
            self.transport.write(frame)
        with self._lock:
            self.frames_sent += 1
            self.neutral_frames += int(stale)

    def send_neutral(self) -> None:
        """One neutral frame now (used by ``close``)."""
        with self._lock:
            if self._command is None:
                return
            cmd = np.where(self._force_mask, 0.0, self._command)
            seq = self.seq
            self.seq = (seq + 1) & 0xFFFF
        frame = th.encode_command(seq, *tc.command_to_channels(self.thrusters, cmd))
        with self.io_lock:
            self.transport.write(frame)
        with self._lock:
            self.frames_sent += 1
            self.neutral_frames += 1


def _force_mask(thrusters) -> np.ndarray:
    """True at the force entries of the ``thruster_command`` layout ([f] / [f, α])."""
    mask = []
    for t in thrusters:
        mask += [True, False] if t.azimuth else [True]
    return np.array(mask, dtype=bool)


class ThrusterSerialSink(LeafSystem):
    """Thruster commands to the thruster MCU on ``port``, measured thrust back.

    .. pydrake_system::

        name: ThrusterSerialSink
        input_ports:
        - thruster_command
        output_ports:
        - thrust_measured
        - thruster_link
        - diagnostics

    Ports (``k = command_size(thrusters)``: [f] per fixed thruster, [f, α] per azimuth, force
    [N], angle [rad], see ``usvdrake.systems.vessel.thrusters``):

    * ``thruster_command`` (input, k): forces are converted to PWM with the T200 16 V curve
      (:func:`hardware_io.thrust_curve.command_to_channels`); non-finite entries are sent as 0.
    * ``thrust_measured`` (output, k): forces [N] of the PWM the MCU reports it outputs (last
      telemetry, through :func:`~hardware_io.thrust_curve.pwm_to_force`) and, for azimuths,
      the angle of the last command handed to the sender (the telemetry carries no angle);
      zeros before the first telemetry.
    * ``thruster_link`` (output, 5): :data:`LINK_FIELDS` = [telemetry frames received, command
      frames sent, telemetry age [s] (simulated time since the update that received the last
      telemetry; :data:`NO_TELEMETRY_AGE` = 1e9 before any), status byte of the last telemetry,
      corrupted frames + telemetry frames with the wrong channel count].
    * ``diagnostics`` (output, abstract): a dict of the link counters ``telemetry_frames``,
      ``crc_errors``, ``frame_errors`` (from the link status) and ``frames_sent``,
      ``neutral_frames``, ``stale_events`` (the sender thread's live counters, read at each
      evaluation: the port is not cached), and the port's link at the last update:
      ``connected``, ``disconnects``, ``reconnects``
      (:class:`~hardware_io.transport.LinkCounters`). An unplugged MCU is reopened by the
      transport while the sender keeps writing; the frames meanwhile are dropped.

    The outputs depend on the state (and time) only, never directly on the input, so the
    system can sit in a feedback loop.

    Timing (PROTOCOL.md "Sequence numbers and the watchdog"): a periodic unrestricted update
    every ``period`` [s] (first at t = 0) reads the telemetry bytes available (non-blocking),
    updates the :class:`ThrusterLinkStatus` and hands the current ``thruster_command`` to the
    sender. The sender is a daemon thread on the wall clock, started by the first update (not
    by the constructor): every ``1 / send_rate_hz`` [s] it encodes and writes the latest
    command with an incrementing ``seq``, so the frame rate (50 Hz keep-alive) does not depend
    on the diagram's rate or on the simulation's real-time factor. If no command was handed
    over for more than ``stale_timeout`` [s] of wall time (the diagram or its controller went
    silent: stalled, paused, crashed), it sends neutral frames (zero force, azimuth angles
    held) instead and counts one stale event, until the next handover. Keep ``period`` well
    below ``stale_timeout`` in simulated time run at real time.

    The link status is abstract state in the Context. The transport, the frame parser's
    partial-frame buffer and the sender thread are I/O and live on the system object, not in
    the Context (as for :class:`~hardware_io.systems.GpsSerialSource`): contexts of this system
    are not independent (all share the one port and the one sender), and the system cannot be
    cloned or pickled across processes. Call :meth:`close` to stop the sender (it writes one
    last neutral frame) and release the port. A missing port raises
    :class:`hardware_io.transport.PortNotFoundError`.
    """

    def __init__(
        self,
        thrusters,
        port: str,
        baudrate: int = 115200,
        send_rate_hz: float = 50.0,
        stale_timeout: float = 0.3,
        period: float = 0.02,
        transport: SerialTransport | None = None,
    ):
        super().__init__()
        if send_rate_hz <= 0.0 or stale_timeout <= 0.0 or period <= 0.0:
            raise ValueError("send_rate_hz, stale_timeout and period must be positive")
        self.thrusters = list(thrusters)
        if not 1 <= len(self.thrusters) <= th.MAX_CHANNELS:
            raise ValueError(f"{len(self.thrusters)} thrusters, need 1 … {th.MAX_CHANNELS}")
        self.size = command_size(self.thrusters)
        self.transport = transport if transport is not None else SerialTransport(port, baudrate)
        self._io_lock = threading.Lock()
        self._closed = False
        self._parser = th.FrameParser()
        self._sender = _CommandSender(
            self.thrusters, self.transport, self._io_lock, send_rate_hz, stale_timeout
        )
        self._status = self.DeclareAbstractState(AbstractValue.Make(ThrusterLinkStatus()))
        self.DeclareVectorInputPort("thruster_command", self.size)
        deps = {self.all_state_ticket(), self.time_ticket()}
        self.DeclareVectorOutputPort(
            "thrust_measured", BasicVector(self.size), self._calc_thrust, deps
        )
        self.DeclareVectorOutputPort(
            "thruster_link", BasicVector(len(LINK_FIELDS)), self._calc_link, deps
        )
        diagnostics = self.DeclareAbstractOutputPort(
            "diagnostics",
            lambda: AbstractValue.Make({}),
            self._calc_diagnostics,
            {self.abstract_state_ticket(self._status)},
        )
        diagnostics.disable_caching_by_default()  # the sender thread's counters are live
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)

    # ------------------------------------------------------------------ public helpers

    def status(self, context) -> ThrusterLinkStatus:
        return context.get_abstract_state(self._status).get_value()

    @property
    def sender_running(self) -> bool:
        return self._sender.running

    @property
    def frames_sent(self) -> int:
        """Command frames written so far (live counter of the sender thread)."""
        return self._sender.counters()[0]

    @property
    def neutral_frames(self) -> int:
        return self._sender.counters()[1]

    @property
    def stale_events(self) -> int:
        """Times the sender switched to neutral frames because no command was handed over for
        ``stale_timeout`` [s] (live counter)."""
        return self._sender.counters()[2]

    def close(self) -> None:
        """Stops the sender (writing one neutral frame if it ever ran) and closes the port.
        Idempotent; later updates read nothing and the port is not reopened."""
        if self._closed:
            return
        self._closed = True
        was_running = self._sender._thread is not None
        self._sender.stop()
        if was_running:
            self._sender.send_neutral()
        with self._io_lock:
            self.transport.close()

    # ------------------------------------------------------------------ Drake callbacks

    def _update(self, context, state):
        t = context.get_time()
        st = context.get_abstract_state(self._status).get_value()
        data, link = b"", st.link
        if not self._closed:
            with self._io_lock:
                data, _host_time = self.transport.read()
                link = self.transport.link
        crc0, fe0 = self._parser.crc_errors, self._parser.frame_errors
        msgs = self._parser.feed(data) if data else []
        wrong = 0
        tlm, tlm_count = st.last_telemetry, 0
        for m in msgs:
            if not isinstance(m, th.Telemetry) or (
                m.pwm_us is not None and len(m.pwm_us) != len(self.thrusters)
            ):
                wrong += 1
                continue
            tlm, tlm_count = m, tlm_count + 1
        command = np.array(self.get_input_port(0).Eval(context), dtype=float)
        self._sender.hand_over(command)
        self._sender.start()
        sent, neutral, stale = self._sender.counters()
        st = replace(
            st,
            bytes_read=st.bytes_read + len(data),
            telemetry_frames=st.telemetry_frames + tlm_count,
            crc_errors=st.crc_errors + self._parser.crc_errors - crc0,
            frame_errors=st.frame_errors + self._parser.frame_errors - fe0 + wrong,
            last_telemetry=tlm,
            last_telemetry_time=t if tlm_count else st.last_telemetry_time,
            measured_pwm=(tlm.pwm_us if tlm_count and tlm.pwm_us is not None else st.measured_pwm),
            command=tuple(float(c) for c in command),
            frames_sent=sent,
            neutral_frames=neutral,
            stale_events=stale,
            link=link,
        )
        state.get_mutable_abstract_state(self._status).set_value(st)

    def _calc_thrust(self, context, output):
        st = self.status(context)
        out = np.zeros(self.size)
        if st.measured_pwm is not None:
            f = np.atleast_1d(tc.pwm_to_force(np.array(st.measured_pwm, dtype=float)))
            k = 0
            for i, t in enumerate(self.thrusters):
                out[k] = f[i]
                if t.azimuth:
                    out[k + 1] = st.command[k + 1] if st.command is not None else 0.0
                    k += 2
                else:
                    k += 1
        output.SetFromVector(out)

    def _calc_diagnostics(self, context, output):
        st = self.status(context)
        sent, neutral, stale = self._sender.counters()
        output.set_value(
            {
                "telemetry_frames": st.telemetry_frames,
                "crc_errors": st.crc_errors,
                "frame_errors": st.frame_errors,
                "frames_sent": sent,
                "neutral_frames": neutral,
                "stale_events": stale,
                "connected": st.link.connected,
                "disconnects": st.link.disconnects,
                "reconnects": st.link.reconnects,
            }
        )

    def _calc_link(self, context, output):
        st = self.status(context)
        age = (
            NO_TELEMETRY_AGE
            if st.last_telemetry_time is None
            else context.get_time() - st.last_telemetry_time
        )
        status = int(st.last_telemetry.status) if st.last_telemetry is not None else 0
        output.SetFromVector(
            [st.telemetry_frames, st.frames_sent, age, status, st.crc_errors + st.frame_errors]
        )
