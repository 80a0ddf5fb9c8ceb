"""Thruster MCU link: McuFirmware (pure model), ThrusterSerialSink against the firmware on a
pseudo-terminal, and the sensor Watchdog (hardware_io/PROTOCOL.md)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from pydrake.common.value import AbstractValue
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource

from hardware_io import thrust_curve as tc
from hardware_io.codecs import thrust as th
from hardware_io.emulators.firmware import TICK_PERIOD_S, McuFirmware
from hardware_io.emulators.pty_link import PtyDevice, WireFaults
from hardware_io.systems.thruster_serial_sink import NO_TELEMETRY_AGE, ThrusterSerialSink
from hardware_io.systems.watchdog import Watchdog
from hardware_io.transport import PortNotFoundError
from usvdrake.sensors.messages import GpsFix, ImuSample
from usvdrake.systems.vessel.thrusters import command_size
from usvdrake.vessel import load_vessel

ROBOAT = load_vessel("roboat2").thrusters  # 4 fixed
ROUND = load_vessel("ntnu_round").thrusters  # 3 azimuths
TIMEOUT = th.WATCHDOG_TIMEOUT_S


def _quantisation(force) -> np.ndarray:
    """[N] force error of ±0.5 µs of PWM rounding around each force (local curve slope)."""
    p = tc.force_to_pwm(np.asarray(force, float))
    return np.abs(tc.pwm_to_force(p + 0.5) - tc.pwm_to_force(p - 0.5)) / 2 + 1e-9


# ------------------------------------------------------------------------------------------
# McuFirmware (pure, simulated time)


def test_power_up_is_neutral_and_tripped():
    fw = McuFirmware(4)
    assert fw.pwm_us == (1500,) * 4 and fw.watchdog_tripped
    assert fw.watchdog_trip_time is None and fw.last_command_time is None
    np.testing.assert_array_equal(fw.forces(), np.zeros(4))
    tlm = th.decode_telemetry(fw.telemetry(0.0))
    assert tlm.seq == 0 and tlm.status == th.Status.WATCHDOG_TRIPPED
    assert tlm.battery_mv == 16000 and tlm.pwm_us == (1500,) * 4 and tlm.rpm is None


def test_valid_frame_sets_clamped_outputs_and_command_vector():
    fw = McuFirmware(4)
    fw.feed(th.encode_command(41, [1000, 1600, 1400, 2500]), now=1.0)
    assert fw.pwm_us == (1100, 1600, 1400, 1900)  # clamped to 1100 … 1900 µs
    assert fw.seq == 41 and fw.last_command_time == 1.0 and fw.frames_ok == 1
    assert not fw.watchdog_tripped
    f = fw.forces()
    np.testing.assert_allclose(f, tc.pwm_to_force([1100, 1600, 1400, 1900]))
    np.testing.assert_allclose(fw.command_vector(ROBOAT), f)
    tlm = th.decode_telemetry(fw.telemetry(1.01))
    assert tlm.seq == 41 and tlm.status == th.Status(0) and tlm.pwm_us == fw.pwm_us
    fw.battery_mv = 13500
    assert th.decode_telemetry(fw.telemetry(1.02)).status == th.Status.UNDERVOLTAGE


def test_corrupted_and_split_frames():
    fw = McuFirmware(4)
    good = th.encode_command(1, [1600] * 4)
    bad = bytearray(th.encode_command(2, [1700] * 4))
    bad[9] ^= 0x40  # a PWM byte: CRC mismatch
    fw.feed(b"\x00\xaa" + bytes(bad) + good[:5], now=0.0)
    assert fw.parser_errors == 1 and fw.frames_ok == 0 and fw.pwm_us == (1500,) * 4
    fw.feed(good[5:], now=0.01)  # rest of the split frame
    assert fw.frames_ok == 1 and fw.pwm_us == (1600,) * 4 and fw.seq == 1
    fw.feed(th.encode_command(5, [1550] * 4), now=0.02)
    assert fw.seq_gaps == 1  # 1 → 5


def test_wrong_channel_count_is_rejected():
    fw = McuFirmware(4)
    fw.feed(th.encode_command(1, [1600] * 4), now=0.0)
    fw.feed(th.encode_command(2, [1900] * 3), now=0.01)
    assert fw.frames_rejected == 1 and fw.frames_ok == 1
    assert fw.pwm_us == (1600,) * 4 and fw.seq == 1 and fw.last_command_time == 0.0


def test_azimuth_firmware_round_trip():
    cmd = np.array([1.0, 0.5, 2.0, -1.0, 0.0, 3.0])
    fw = McuFirmware(3, azimuth=True)
    fw.feed(th.encode_command(3, *tc.command_to_channels(ROUND, cmd)), now=0.0)
    out = fw.command_vector(ROUND)
    forces, angles = cmd[0::2], cmd[1::2]
    assert np.all(np.abs(out[0::2] - forces) <= _quantisation(forces))
    np.testing.assert_allclose(out[1::2], angles, atol=np.deg2rad(0.005) + 1e-12)
    # the watchdog zeroes the ESCs and holds the servos
    fw.tick(0.2)
    assert fw.watchdog_tripped and fw.pwm_us == (1500,) * 3
    np.testing.assert_allclose(fw.command_vector(ROUND)[1::2], angles, atol=1e-4)
    np.testing.assert_array_equal(fw.command_vector(ROUND)[0::2], 0.0)


def test_watchdog_trips_after_timeout_not_before():
    fw = McuFirmware(4)
    t0 = 0.0  # so that t0 + TIMEOUT - t0 == TIMEOUT exactly
    fw.feed(th.encode_command(1, [1700] * 4), now=t0)
    fw.tick(t0 + TIMEOUT - 1e-6)
    fw.tick(t0 + TIMEOUT)  # "more than" the timeout
    assert not fw.watchdog_tripped and fw.pwm_us == (1700,) * 4
    fw.tick(t0 + TIMEOUT + 1e-6)
    assert fw.watchdog_tripped and fw.pwm_us == (1500,) * 4
    assert fw.watchdog_trip_time == t0 + TIMEOUT + 1e-6 and fw.watchdog_trips == 1
    fw.tick(t0 + 1.0)  # later ticks keep the first trip time
    assert fw.watchdog_trip_time == t0 + TIMEOUT + 1e-6
    assert th.decode_telemetry(fw.telemetry(t0 + 1.0)).status & th.Status.WATCHDOG_TRIPPED
    fw.feed(th.encode_command(2, [1600] * 4), now=t0 + 1.1)  # a new command clears the trip
    assert not fw.watchdog_tripped and fw.watchdog_trip_time is None
    assert fw.pwm_us == (1600,) * 4


@pytest.mark.parametrize("phase", [0.0, 0.0031, 0.0099])
def test_watchdog_latency_after_last_frame(phase):
    """Firmware ticking every 10 ms, frames at 50 Hz, then the link is cut: the outputs are
    neutral within timeout + one tick of the last frame (PROTOCOL.md)."""
    fw = McuFirmware(4)
    tick = np.arange(0.0, 2.0, TICK_PERIOD_S)
    frames = np.arange(phase, 1.0, 0.02)
    k = 0
    for now in tick:
        while k < len(frames) and frames[k] <= now:
            fw.feed(th.encode_command(k & 0xFFFF, [1800] * 4), now=frames[k])
            k += 1
        fw.tick(now)
        if frames[0] <= now < frames[-1]:
            assert not fw.watchdog_tripped
    latency = fw.watchdog_trip_time - fw.last_command_time
    assert TIMEOUT < latency <= TIMEOUT + TICK_PERIOD_S + 1e-9
    assert fw.watchdog_trips == 1 and fw.frames_ok == len(frames)


# ------------------------------------------------------------------------------------------
# ThrusterSerialSink against the firmware on a pty


class _Device:
    """McuFirmware on the device end of a pty, run by a thread: reads and ticks every
    ``tick`` s of wall time, sends telemetry at ``telemetry_hz``."""

    def __init__(self, n, azimuth=False, faults=None, telemetry_hz=20.0, tick=0.005):
        self.pty = PtyDevice(faults)
        self.path = self.pty.path
        self.fw = McuFirmware(n, azimuth)
        self.lock = threading.Lock()
        self.arrivals: list[float] = []  # time.monotonic() of each applied command frame
        self.max_tick_gap = 0.0
        self._tick, self._tlm_period = tick, 1.0 / telemetry_hz
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        last = next_tlm = time.monotonic()
        while not self._stop.wait(self._tick):
            now = time.monotonic()
            data = self.pty.read()
            with self.lock:
                self.max_tick_gap = max(self.max_tick_gap, now - last)
                last = now
                n0 = self.fw.frames_ok
                self.fw.feed(data, now)
                self.arrivals += [now] * (self.fw.frames_ok - n0)
                self.fw.tick(now)
                if now >= next_tlm:
                    self.pty.write(self.fw.telemetry(now))
                    next_tlm = max(next_tlm + self._tlm_period, now)

    def frames_between(self, a: float, b: float) -> int:
        with self.lock:
            return sum(a <= t < b for t in self.arrivals)

    def close(self):
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.pty.close()


class _Rig:
    """ConstantVectorSource → ThrusterSerialSink, simulated at real time, and a _Device."""

    def __init__(self, thrusters, command, faults=None, realtime=True, **sink_kwargs):
        self.thrusters = thrusters
        self.dev = _Device(len(thrusters), any(t.azimuth for t in thrusters), faults)
        b = DiagramBuilder()
        self.source = b.AddSystem(ConstantVectorSource(np.asarray(command, float)))
        self.sink = b.AddSystem(ThrusterSerialSink(thrusters, self.dev.path, **sink_kwargs))
        b.Connect(self.source.get_output_port(), self.sink.get_input_port())
        self.diagram = b.Build()
        self.sim = Simulator(self.diagram)
        if realtime:
            self.sim.set_target_realtime_rate(1.0)
        self.sim.Initialize()
        self.ctx = self.sim.get_context()
        self.sink_ctx = self.sink.GetMyContextFromRoot(self.ctx)

    def set_command(self, command):
        src_ctx = self.source.GetMyMutableContextFromRoot(self.sim.get_mutable_context())
        self.source.get_mutable_source_value(src_ctx).SetFromVector(command)

    def advance(self, dt: float):
        self.sim.AdvanceTo(self.ctx.get_time() + dt)

    def advance_until(self, cond, timeout: float = 3.0, dt: float = 0.05):
        deadline = time.monotonic() + timeout
        while not cond():
            assert time.monotonic() < deadline, "condition not reached"
            self.advance(dt)

    def measured(self) -> np.ndarray:
        return self.sink.GetOutputPort("thrust_measured").Eval(self.sink_ctx)

    def link(self) -> np.ndarray:
        return self.sink.GetOutputPort("thruster_link").Eval(self.sink_ctx)

    def close(self):
        self.sink.close()
        self.dev.close()


@pytest.mark.parametrize(
    "thrusters, command",
    [(ROBOAT, [10.0, -5.0, 0.0, 30.0]), (ROUND, [1.0, 0.5, 2.0, -1.0, 0.0, 3.0])],
    ids=["roboat2", "ntnu_round"],
)
def test_round_trip_through_pty(thrusters, command):
    command = np.array(command)
    rig = _Rig(thrusters, command)
    try:
        sink = rig.sink
        assert not sink.sender_running  # nothing started by construction / Initialize
        assert not any(sink.HasDirectFeedthrough(0, k) for k in range(3))
        assert sink.get_input_port().size() == command_size(thrusters) == len(command)
        assert sink.GetOutputPort("thrust_measured").size() == len(command)
        assert sink.GetOutputPort("thruster_link").size() == 5
        np.testing.assert_array_equal(rig.measured(), np.zeros(len(command)))
        assert rig.link()[2] == NO_TELEMETRY_AGE

        target = tuple(tc.command_to_channels(thrusters, command)[0])
        rig.advance_until(
            lambda: (
                sink.status(rig.sink_ctx).measured_pwm == target
                and sink.status(rig.sink_ctx).telemetry_frames >= 2
            )
        )
        assert sink.sender_running
        fmask = np.array(sum(([True, False] if t.azimuth else [True] for t in thrusters), []))
        with rig.dev.lock:
            fw_out = rig.dev.fw.command_vector(thrusters)
            assert not rig.dev.fw.watchdog_tripped
        forces = command[fmask]
        assert np.all(np.abs(fw_out[fmask] - forces) <= _quantisation(forces))
        np.testing.assert_allclose(fw_out[~fmask], command[~fmask], atol=np.deg2rad(0.005))
        measured = rig.measured()
        np.testing.assert_allclose(measured[fmask], fw_out[fmask])  # same PWM, same curve
        np.testing.assert_array_equal(measured[~fmask], command[~fmask])
        n_tlm, n_sent, age, status, errors = rig.link()
        assert n_tlm >= 2 and n_sent >= 2 and 0.0 <= age < 0.5
        assert status == 0 and errors == 0
        diagnostics = sink.GetOutputPort("diagnostics").Eval(rig.sink_ctx)
        assert list(diagnostics) == [
            "telemetry_frames", "crc_errors", "frame_errors",
            "frames_sent", "neutral_frames", "stale_events",
            "connected", "disconnects", "reconnects",
        ]  # fmt: skip
        assert diagnostics["telemetry_frames"] >= 2 and diagnostics["crc_errors"] == 0
        assert diagnostics["neutral_frames"] == diagnostics["stale_events"] == 0
        time.sleep(0.1)  # the sender keeps writing; the port reads its live counter (no cache)
        sent = sink.GetOutputPort("diagnostics").Eval(rig.sink_ctx)["frames_sent"]
        assert diagnostics["frames_sent"] < sent <= sink.frames_sent

        # thrust_measured follows the telemetry when the command changes
        new = command.copy()
        new[fmask] = -np.abs(new[fmask]) - 1.0
        rig.set_command(new)
        target = tuple(tc.command_to_channels(thrusters, new)[0])
        rig.advance_until(lambda: sink.status(rig.sink_ctx).measured_pwm == target)
        m = rig.measured()[fmask]
        assert np.all(np.abs(m - new[fmask]) <= _quantisation(new[fmask]))
    finally:
        rig.close()
    assert not rig.sink.sender_running and rig.sink.neutral_frames == 1  # close() sent neutral
    rig.sink.close()  # idempotent: no second frame, the port stays closed
    assert rig.sink.neutral_frames == 1 and not rig.sink.transport.connected


@pytest.mark.parametrize("period, realtime", [(0.1, True), (0.002, False)])
def test_frame_rate_does_not_depend_on_diagram_rate(period, realtime):
    rig = _Rig(ROBOAT, [5.0] * 4, realtime=realtime, period=period, stale_timeout=0.3)
    try:
        rig.advance_until(lambda: rig.dev.fw.frames_ok > 0, dt=period if realtime else 0.05)
        t_a = time.monotonic()
        sent_a = rig.sink.frames_sent
        while time.monotonic() < t_a + 1.0:  # a diagram at 10 Hz, or far faster than real time
            rig.advance(period if realtime else 0.05)
            if not realtime:
                time.sleep(0.005)
        t_b = time.monotonic()
        time.sleep(0.03)  # let the device read what was sent before t_b
        rate_rx = rig.dev.frames_between(t_a, t_b) / (t_b - t_a)
        rate_tx = (rig.sink.frames_sent - sent_a) / (t_b - t_a)
        assert 40.0 <= rate_tx <= 60.0, rate_tx
        assert 40.0 <= rate_rx <= 60.0, rate_rx
        assert rig.sink.stale_events == 0 and not rig.dev.fw.watchdog_tripped
    finally:
        rig.close()


def test_stale_controller_gets_neutral_frames():
    stale = 0.2
    command = np.array([20.0, 20.0, -20.0, 0.0])
    rig = _Rig(ROBOAT, command, stale_timeout=stale)
    target = tuple(tc.command_to_channels(ROBOAT, command)[0])
    fw = rig.dev.fw
    try:
        rig.advance_until(lambda: fw.pwm_us == target)
        rig.advance(0.1)
        t_stop = time.monotonic()  # the diagram stalls: no more handovers
        deadline = t_stop + 1.0
        while fw.pwm_us != (1500,) * 4:
            assert time.monotonic() < deadline, "no neutral frames"
            time.sleep(0.005)
        elapsed = time.monotonic() - t_stop
        assert stale - 0.02 - 0.03 <= elapsed <= stale + 0.15, elapsed  # 0.02: period
        with rig.dev.lock:
            ok0 = fw.frames_ok
        time.sleep(0.1)
        with rig.dev.lock:  # neutral frames keep the MCU watchdog quiet
            assert fw.frames_ok >= ok0 + 3 and not fw.watchdog_tripped
            assert fw.pwm_us == (1500,) * 4
        assert rig.sink.stale_events == 1 and rig.sink.neutral_frames >= 3
        diagnostics = rig.sink.GetOutputPort("diagnostics").Eval(rig.sink_ctx)
        assert diagnostics["stale_events"] == 1 and diagnostics["neutral_frames"] >= 3
        rig.advance_until(lambda: fw.pwm_us == target)  # the controller is back
        assert rig.sink.stale_events == 1 and fw.watchdog_trips == 0
    finally:
        rig.close()


def test_one_percent_corruption_still_delivers_commands():
    command = np.array([12.0, -8.0, 3.0, 25.0])
    target = tuple(tc.command_to_channels(ROBOAT, command)[0])
    rig = _Rig(ROBOAT, command, faults=WireFaults(0.01, seed=3))
    fw = rig.dev.fw
    try:
        rig.advance_until(lambda: fw.frames_ok > 0)
        sent0, ok0 = rig.sink.frames_sent, fw.frames_ok
        rig.advance(1.5)
        time.sleep(0.03)
        sent, ok = rig.sink.frames_sent - sent0, fw.frames_ok - ok0
        with rig.dev.lock:
            assert fw.pwm_us == target and fw.watchdog_trips == 0
            fw_errors = fw.parser_errors
        assert ok >= 0.6 * sent, (ok, sent)  # 0.99^19 = 83 % of 19-byte frames intact
        st = rig.sink.status(rig.sink_ctx)
        assert st.measured_pwm == target
        assert fw_errors + st.crc_errors + st.frame_errors > 0
        assert rig.dev.pty.faults.bytes_corrupted > 0
    finally:
        rig.close()


def test_cut_link_trips_mcu_watchdog_within_timeout_plus_tick():
    faults = WireFaults()
    rig = _Rig(ROBOAT, [15.0] * 4, faults=faults)
    fw = rig.dev.fw
    try:
        rig.advance_until(lambda: rig.sink.status(rig.sink_ctx).telemetry_frames > 0)
        faults.cut()
        rig.advance_until(lambda: fw.watchdog_tripped, timeout=2.0)
        with rig.dev.lock:
            latency = fw.watchdog_trip_time - fw.last_command_time
            tick_gap = rig.dev.max_tick_gap
            assert fw.pwm_us == (1500,) * 4
        assert TIMEOUT < latency <= TIMEOUT + tick_gap + 1e-6, (latency, tick_gap)
        assert fw.last_command_time <= faults.cut_time + 0.01
        rig.advance(0.3)
        assert rig.link()[2] >= 0.25  # no telemetry across a cut wire either
    finally:
        rig.close()


def test_missing_port_raises_generic_error():
    with pytest.raises(PortNotFoundError, match="ttyUSB9.*not plugged in"):
        ThrusterSerialSink(ROBOAT, "/dev/ttyUSB9-does-not-exist")


# ------------------------------------------------------------------------------------------
# Watchdog


class _WatchdogRig:
    def __init__(self, required, size=4, force_mask=None, period=0.02):
        self.wd = Watchdog(size, required, period=period, force_mask=force_mask)
        self.sim = Simulator(self.wd)
        self.ctx = self.sim.get_mutable_context()
        self.period = period
        self.wd.get_input_port(0).FixValue(self.ctx, np.arange(1.0, size + 1.0))

    def feed(self, name, msg):
        self.wd.GetInputPort(name).FixValue(self.ctx, AbstractValue.Make(msg))

    def advance_to(self, t):
        # stop between two updates so the update at a multiple of period has run
        self.sim.AdvanceTo(t)

    def command(self):
        return self.wd.GetOutputPort("thruster_command").Eval(self.ctx)

    def status(self):
        return self.wd.GetOutputPort("watchdog_status").Eval(self.ctx)


def test_watchdog_grace_period_and_status_bits():
    rig = _WatchdogRig({"gps": 0.5, "imu": 0.2, "lidar_scan": 0.3})
    assert [rig.wd.get_output_port(i).get_name() for i in range(rig.wd.num_output_ports())] == [
        "thruster_command",
        "watchdog_status",
    ]
    rig.advance_to(0.19)
    np.testing.assert_array_equal(rig.status(), [0, 0, 0])  # grace: silent but not yet due
    np.testing.assert_array_equal(rig.command(), [1, 2, 3, 4])
    rig.advance_to(0.23)  # update at 0.22: imu (bit 1) overdue
    np.testing.assert_array_equal(rig.status(), [1, 0b010, 1])
    np.testing.assert_array_equal(rig.command(), [0, 0, 0, 0])
    rig.advance_to(0.33)  # lidar_scan (bit 2) too
    np.testing.assert_array_equal(rig.status(), [1, 0b110, 1])
    rig.advance_to(0.53)
    np.testing.assert_array_equal(rig.status(), [1, 0b111, 1])
    assert rig.wd.silent_sensors(rig.ctx) == ["gps", "imu", "lidar_scan"]


def test_watchdog_trip_untrip_and_trip_count():
    rig = _WatchdogRig({"gps": 0.3, "imu": 0.1})
    t = 0.01
    while t < 1.0:  # both sensors alive: gps at 5 Hz, imu at 50 Hz
        if round(t / 0.02) % 10 == 0:
            rig.feed("gps", GpsFix(time=t, valid=True))
        rig.feed("imu", ImuSample(time=t))
        t += 0.02
        rig.advance_to(t)
        np.testing.assert_array_equal(rig.status(), [0, 0, 0])
    last_imu = t - 0.02
    while t < last_imu + 0.1 + 0.02:  # imu stops; gps keeps coming
        rig.feed("gps", GpsFix(time=t, valid=True))
        t += 0.02
        rig.advance_to(t)
    np.testing.assert_array_equal(rig.status(), [1, 0b10, 1])
    np.testing.assert_array_equal(rig.command(), [0, 0, 0, 0])
    rig.feed("imu", ImuSample(time=t))
    t += 0.02
    rig.advance_to(t)
    np.testing.assert_array_equal(rig.status(), [0, 0, 1])  # untripped, count kept
    np.testing.assert_array_equal(rig.command(), [1, 2, 3, 4])
    # an invalid fix does not count as a fix: gps goes silent after its timeout
    t_valid = t
    while t < t_valid + 0.3 + 0.04:
        rig.feed("gps", GpsFix(time=t, valid=False))
        rig.feed("imu", ImuSample(time=t))
        t += 0.02
        rig.advance_to(t)
    np.testing.assert_array_equal(rig.status(), [1, 0b01, 2])


def test_watchdog_keeps_azimuth_angles():
    mask = np.array([True, False] * 3)
    rig = _WatchdogRig({"imu": 0.1}, size=6, force_mask=mask)
    rig.advance_to(0.05)
    np.testing.assert_array_equal(rig.command(), [1, 2, 3, 4, 5, 6])
    rig.advance_to(0.13)
    np.testing.assert_array_equal(rig.command(), [0, 2, 0, 4, 0, 6])
    with pytest.raises(ValueError):
        Watchdog(6, {"imu": 0.1}, force_mask=[True] * 4)


def test_watchdog_hears_a_lidar_even_when_it_sees_nothing():
    from usvdrake.sensors.messages import LaserScan

    rig = _WatchdogRig({"lidar_scan": 0.25})
    t = 0.0
    while t < 0.5:  # 10 Hz scans, open water: no return at all
        rig.feed("lidar_scan", LaserScan(time=t, ranges=np.ones(3), valid=np.zeros(3, bool)))
        t += 0.1
        rig.advance_to(t)
        np.testing.assert_array_equal(rig.status(), [0, 0, 0])
    rig.advance_to(t + 0.3)  # then the scans stop
    np.testing.assert_array_equal(rig.status(), [1, 1, 1])
