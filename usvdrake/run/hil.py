"""``run_hil``: the hardware diagram against emulated devices, in real time (``usvdrake hil``).

Two processes, as on the boat: the *rig* (:mod:`hardware_io.emulators.rig`) simulates the vessel
and world behind a thruster microcontroller, a GNSS receiver and an IMU on pseudo-terminals; this
process builds ``build_vessel_diagram(scenario, hardware=...)`` with those ports — the hardware
station of serial systems plus the *same* autonomy objects as in simulation — and runs it paced
to the wall clock (Simulator target real-time rate 1).

Ground truth exists only in the rig. Both processes stamp samples with ``time.monotonic()``
(one system-wide clock on Linux), so afterwards the truth is put on this process's simulation
clock and scored against the reference exactly as ``usvdrake run`` scores a simulation.

After ``duration`` the thruster wire is cut (``cut_link``): the metric ``watchdog_latency_ms``
is the time from the cut until the emulated microcontroller outputs neutral PWM.

A device that goes away mid-run (unplugged, or the whole rig dead) does not end the run: its
transport reports it and keeps reopening the port, the host watchdog zeroes the thrust while a
sensor is silent, and the metrics count the disconnects, reconnects and watchdog trips (also in
the log: ``/hil/link/<device>``, ``/watchdog_status``). ``rig_events`` injects such faults at
given simulated times (:func:`parse_rig_event`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import select
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import DiagramBuilder, EventStatus, LeafSystem
from pydrake.systems.primitives import LogVectorOutput

from usvdrake.analysis.metrics import control_estimation_metrics, vessel_clearance
from usvdrake.diagrams.hardware_station import (
    close_hardware,
    hardware_metrics,
    linked_devices,
)
from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.jsonable import jsonable
from usvdrake.logs.mission_log import MissionLogWriter, RecordedPort, add_mission_recorder
from usvdrake.run.measure import final_values, interruption
from usvdrake.run.mission import run_mission
from usvdrake.run.simulate import simulate
from usvdrake.scenario import Scenario, scenario_yaml
from usvdrake.vessel import load_vessel
from usvdrake.worlds import make_world

__all__ = ["HilResult", "parse_rig_event", "run_hil"]

READY_TIMEOUT_S = 120.0  # the rig imports Drake and builds the world before it is ready
CUT_OBSERVATION_S = 1.0  # [s] kept running after the cut so the watchdog is seen
RIG_DEVICES = ("thrusters", "gps", "imu", "lidar2d")  # the rig's wires, by name
LINK_FIELDS = ("connected", "disconnects", "reconnects")  # of each device, in the log
WATCHDOG_FIELDS = ("tripped", "silent_mask", "trips")


def parse_rig_event(text: str) -> tuple[float, str]:
    """``"T:COMMAND"`` → (T [s of simulated time], COMMAND): ``unplug DEVICE``, ``replug
    DEVICE`` (DEVICE one of :data:`RIG_DEVICES`), ``cut thrusters`` or ``kill`` (the rig
    process killed, as a power loss would). ValueError with one line otherwise."""
    when, sep, command = text.partition(":")
    try:
        t = float(when)
    except ValueError:
        t = math.nan
    if not sep or not math.isfinite(t) or t < 0.0:
        raise ValueError(f"rig event {text!r}: expected T:COMMAND with T >= 0 seconds")
    command = " ".join(command.split())
    action, _, device = command.partition(" ")
    if command in ("kill", "cut thrusters") or (
        action in ("unplug", "replug") and device in RIG_DEVICES
    ):
        return t, command
    raise ValueError(
        f"rig event {text!r}: COMMAND is kill, cut thrusters, or unplug/replug one of "
        + ", ".join(RIG_DEVICES)
    )


class ClockRecorder(LeafSystem):
    """(simulation time, ``time.monotonic()``) pairs at ``rate_hz`` in :attr:`rows`; with a
    mission log ``writer`` also the topic ``/hil/clock`` (``unix_time``, ``monotonic`` [s]) so a
    log says which wall-clock moment each simulation time was."""

    def __init__(self, rate_hz: float = 20.0, writer=None):
        super().__init__()
        self.rows: list[tuple[float, float]] = []
        self._writer = writer
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._record)

    def _record(self, context):
        t, mono = context.get_time(), time.monotonic()
        self.rows.append((t, mono))
        if self._writer is not None:
            self._writer.write_vector(
                "/hil/clock", t, [time.time(), mono], names=("unix_time", "monotonic")
            )


class LinkRecorder(LeafSystem):
    """Each device's link (``connected``, ``disconnects``, ``reconnects`` of its
    ``<device>_diagnostics`` input, one abstract input per name of ``devices``) on the mission
    log topic ``/hil/link/<device>`` at ``rate_hz``: when a device went away and came back."""

    def __init__(self, devices: Sequence[str], writer, rate_hz: float = 10.0):
        super().__init__()
        self._writer = writer
        self._inputs = {
            d: self.DeclareAbstractInputPort(f"{d}_diagnostics", AbstractValue.Make({}))
            for d in devices
        }
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._record)

    def _record(self, context):
        t = context.get_time()
        for device, port in self._inputs.items():
            counters = port.Eval(context)
            values = [float(counters[k]) for k in LINK_FIELDS]
            self._writer.write_vector(f"/hil/link/{device}", t, values, names=LINK_FIELDS)


class RigEvents(LeafSystem):
    """Sends the rig each ``(t, command)`` of ``events`` once simulated time reaches ``t``
    (checked every ``period``; ``kill`` kills the rig process instead), and logs it on
    ``/hil/rig_events/<command>`` ([t_requested]) with a ``writer``: faults on the simulated
    clock, so a test's verdict does not depend on how fast the machine is."""

    def __init__(self, rig, events: Sequence[tuple[float, str]], writer=None, period=0.05):
        super().__init__()
        self._rig, self._writer = rig, writer
        self._pending = sorted(events)
        self.DeclarePeriodicPublishEvent(period, 0.0, self._send)

    def _send(self, context):
        t = context.get_time()
        while self._pending and self._pending[0][0] <= t + 1e-9:
            when, command = self._pending.pop(0)
            if command == "kill":
                self._rig.kill()
            else:
                self._rig.send(command)
            if self._writer is not None:
                topic = "/hil/rig_events/" + command.replace(" ", "_")
                self._writer.write_vector(topic, t, [when], names=("t_requested",))


@dataclass
class HilResult:
    metrics: dict
    times: np.ndarray  # [s] host simulation time of the samples
    states: np.ndarray  # (n × 6) ground truth from the rig on the host clock
    files: dict = field(default_factory=dict)


class RigProcess:
    """The rig as a child process: ``ports`` once ready (stable names in a folder of its own,
    so a device can come back under the same name), ``send(line) -> bool``, ``kill()``,
    ``stop() -> report or None`` (None, with the reason in :attr:`error`, when the rig died
    or failed: the host's run still ends with its own metrics)."""

    def __init__(self, scenario_yaml: Path, report: Path, corruption: float):
        self.report_path = report
        self.error: str | None = None
        report.unlink(missing_ok=True)  # a report left by an earlier run is not this one's
        self._links = tempfile.TemporaryDirectory(prefix="usvdrake-rig-")
        cmd = [sys.executable, "-m", "hardware_io.emulators.rig", str(scenario_yaml)]
        cmd += ["--corrupt", repr(corruption), "--report", str(report)]
        cmd += ["--link-dir", self._links.name]
        self.proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        try:
            self.ports = self._wait_ready()
        except BaseException:
            self.kill()
            raise

    def _wait_ready(self) -> dict[str, str]:
        deadline = time.monotonic() + READY_TIMEOUT_S
        while time.monotonic() < deadline:
            ready, _, _ = select.select([self.proc.stdout], [], [], 0.2)
            if ready:
                chunk = self.proc.stdout.readline()
                if chunk.strip():
                    return json.loads(chunk)["ports"]
            if self.proc.poll() is not None:
                err = self.proc.stderr.read().decode(errors="replace").strip().splitlines()
                raise RuntimeError(
                    "HIL rig exited before it was ready: " + (err[-1] if err else "no output")
                )
        raise RuntimeError(f"HIL rig not ready after {READY_TIMEOUT_S:.0f} s")

    @property
    def alive(self) -> bool:
        return self.proc.poll() is None

    def send(self, line: str) -> bool:
        """Writes a control line; False if the rig has gone (its stdin is a broken pipe)."""
        try:
            self.proc.stdin.write(line.encode() + b"\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError, ValueError):  # ValueError: stdin already closed
            return False
        return True

    def stop(self, timeout: float = 30.0) -> dict | None:
        if self.alive:
            self.send("stop")
            try:
                self.proc.stdin.close()
            except (BrokenPipeError, OSError):
                pass  # the rig died between the two calls
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._links.cleanup()
        code = self.proc.returncode
        if code != 0:
            err = self.proc.stderr.read().decode(errors="replace").strip().splitlines()
            how = f"killed by signal {-code}" if code < 0 else f"exit {code}"
            self.error = f"HIL rig failed ({how})" + (f": {err[-1]}" if err else "")
        try:
            return json.loads(self.report_path.read_text())
        except (OSError, ValueError):  # killed before it could write one
            return None

    def kill(self) -> None:
        if self.alive:
            self.proc.kill()
            self.proc.wait()
        self._links.cleanup()


def truth_on_host_clock(report: dict, clock: np.ndarray, times: np.ndarray) -> np.ndarray:
    """The rig's truth (rows ``[wall, sim, x, y, ψ, u, v, r]``) at host simulation ``times``,
    through the host's (simulation time, wall time) pairs ``clock``: linear interpolation in
    wall time, ψ unwrapped first and wrapped back."""
    truth = np.asarray(report["truth"], float)
    wall_of = np.interp(times, clock[:, 0], clock[:, 1])
    q = truth[:, 2:].copy()
    q[:, 2] = np.unwrap(q[:, 2])
    out = np.column_stack([np.interp(wall_of, truth[:, 0], q[:, k]) for k in range(6)])
    out[:, 2] = np.angle(np.exp(1j * out[:, 2]))
    return out


def watchdog_latency_ms(report: dict) -> float | None:
    """Milliseconds from the wire cut to the first watchdog trip after it (None: no cut, or
    the microcontroller never went to neutral — a failure the caller reports)."""
    cut = report.get("cut_time")
    if cut is None:
        return None
    trips = [t for t in report.get("watchdog_trips", []) if t >= cut]
    return 1000.0 * (min(trips) - cut) if trips else None


def run_hil(
    scenario: Scenario,
    out_dir: str | Path,
    duration: float | None = None,
    corruption: float = 0.0,
    cut_link: bool = True,
    compare_sim: bool = True,
    progress: bool = False,
    meshcat=None,
    emulated: bool = True,
    rig_events: Sequence[tuple[float, str]] = (),
) -> HilResult:
    """Run ``scenario``'s hardware diagram against the rig for ``duration`` s of wall time.

    ``emulated=False`` runs it against the real devices on the ports of the scenario's
    ``hardware`` section instead (no rig: no truth, so only the host's own metrics); a port
    that does not exist stops it with one line before anything moves.

    Writes ``metrics.json``, ``log.mcap`` (the host's inputs, outputs and estimates),
    ``rig_report.json`` and ``scenario.yaml`` to ``out_dir``. With ``compare_sim`` the same
    scenario is also simulated (no hardware, as fast as possible) over the same duration and
    ``position_rmse_ratio_vs_sim`` compares the two.

    ``rig_events``: (simulated time [s], rig command) pairs, see :func:`parse_rig_event`.
    Devices lost mid-run are counted (``device_disconnects``, ``device_reconnects``, per
    device ``<device>_disconnects`` ...), ``devices_disconnected`` lists those still gone at
    the end, ``watchdog_trips`` counts the host watchdog's trips; a rig that died leaves
    ``rig_error`` and no truth metrics. The run ends with its metrics either way.
    """
    if rig_events and not emulated:
        raise ValueError("rig events need the emulated rig (not --devices)")

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    duration = float(duration if duration is not None else scenario.duration)
    scenario = dataclasses.replace(scenario, duration=duration)
    (out / "scenario.yaml").write_text(scenario_yaml(scenario))
    # the world and the nominal vessel, resolved once for the diagram and the metrics
    nominal, world = load_vessel(scenario.vessel), make_world(scenario.world, scenario.seed)
    hw = scenario.hardware
    rig = None
    if emulated:
        rig = RigProcess(out / "scenario.yaml", out / "rig_report.json", corruption)
        hw = dataclasses.replace(
            hw,
            thrusters=dataclasses.replace(hw.thrusters, port=rig.ports["thrusters"]),
            gps=dataclasses.replace(hw.gps, port=rig.ports["gps"]),
            imu=dataclasses.replace(hw.imu, port=rig.ports["imu"]),
        )
        if "lidar2d" in rig.ports:  # the rig plays an RPLIDAR A1
            hw = dataclasses.replace(
                hw,
                lidar2d=dataclasses.replace(
                    hw.lidar2d, port=rig.ports["lidar2d"], protocol="rplidar"
                ),
            )
    log_writer = None
    try:
        builder = DiagramBuilder()
        vessel = builder.AddNamedSystem(
            "vessel",
            build_vessel_diagram(
                scenario, meshcat=meshcat, hardware=hw, vessel=nominal, world=world
            ),
        )
        log_writer = _add_log(builder, vessel, out / "log.mcap", scenario)
        clock = builder.AddNamedSystem("clock_recorder", ClockRecorder(writer=log_writer))
        _add_link_recorder(builder, vessel, log_writer, scenario.visualization.rate_hz)
        if rig_events:
            builder.AddNamedSystem("rig_events", RigEvents(rig, rig_events, log_writer))
        period = 1.0 / scenario.visualization.rate_hz
        logged = [
            p
            for p in (
                "reference",
                "state_estimate",
                "thruster_command",
                "thrust_measured",
                "pose_measurement",
                "nmhe_solve_ms",
                "estimate_time",
                "watchdog_status",
                "thruster_link",
            )
            if vessel.HasOutputPort(p)
        ]
        loggers = {p: LogVectorOutput(vessel.GetOutputPort(p), builder, period) for p in logged}
        diagram = builder.Build()
        diagram.set_name("hil_mission")

        # the host runs on the wall clock: the devices (or the rig) set the pace
        outcome = simulate(
            diagram, duration, vessel, realtime_rate=1.0, progress=progress, step=0.5, unit="s"
        )
        simulator, t = outcome.simulator, outcome.sim_time
        context = simulator.get_mutable_context()
        tracked_until = t
        lag_s = outcome.wall_time - t
        cut0 = time.perf_counter()
        if cut_link and rig is not None and rig.send("cut thrusters"):
            simulator.set_monitor(lambda root: EventStatus.Succeeded())
            simulator.AdvanceTo(t + CUT_OBSERVATION_S)
        wall = outcome.wall_time + (time.perf_counter() - cut0)
        host_status = hardware_metrics(vessel, context)
        # the host lets go of its ports first: a rig that stops under an open port is an unplug
        close_hardware(diagram)
        report = rig.stop() if rig is not None else None
        log_writer.close()
    except BaseException:
        if rig is not None:
            rig.kill()
        if log_writer is not None:
            log_writer.close()
        raise

    logs = {p: lg.FindLog(context) for p, lg in loggers.items()}
    metrics = {
        "scenario": scenario.name,
        "mode": "hil" if rig is not None else "devices",
        "duration_s": duration,
        "tracked_until_s": float(tracked_until),
        "wall_time_s": float(wall),
        "realtime_lag_s": float(lag_s),
        **interruption(outcome.interrupted),  # SIGINT / SIGTERM ended it early
        "byte_corruption": corruption if rig is not None else None,
    }
    if rig_events:
        metrics["rig_events"] = [[float(t), c] for t, c in sorted(rig_events)]
    if rig is not None and rig.error is not None:
        metrics["rig_error"] = rig.error
    metrics.update(host_status)
    if "thruster_command" in logs:
        metrics["thrust_abs_max_n"] = float(np.max(np.abs(logs["thruster_command"].data())))
    times = logs["state_estimate"].sample_times()
    keep = times <= tracked_until + 1e-9
    times, states = times[keep], None
    if report is not None:
        states = truth_on_host_clock(report, np.asarray(clock.rows, float), times)
        metrics.update(
            _truth_metrics(
                scenario, vessel, context, logs, keep, times, states, report, nominal, world
            )
        )
        if compare_sim:
            sim = run_mission(dataclasses.replace(scenario, duration=tracked_until), record=False)
            metrics["sim_position_rmse_m"] = sim.metrics.get("position_rmse_m")
            metrics["sim_heading_rmse_rad"] = sim.metrics.get("heading_rmse_rad")
            if metrics.get("position_rmse_m") is not None and metrics["sim_position_rmse_m"]:
                metrics["position_rmse_ratio_vs_sim"] = (
                    metrics["position_rmse_m"] / metrics["sim_position_rmse_m"]
                )

    (out / "metrics.json").write_text(json.dumps(jsonable(metrics), indent=2) + "\n")
    files = {"metrics": out / "metrics.json", "log": out / "log.mcap"}
    if report is not None:
        files["rig_report"] = out / "rig_report.json"
    files["scenario"] = out / "scenario.yaml"
    return HilResult(metrics, times, states, files)


def _truth_metrics(
    scenario, vessel, context, logs, keep, times, states, report, nominal, world
) -> dict:
    """Tracking and estimation against the rig's truth, clearance to the world, the watchdog
    and the wires."""

    def logged(name):
        return logs[name].data().T[keep] if name in logs else None

    nmhe_ms = logged("nmhe_solve_ms")
    est_time = logged("estimate_time")
    out = control_estimation_metrics(
        times,
        states,
        logged("state_estimate"),
        final_values(vessel, context),
        logged("pose_measurement"),
        None if nmhe_ms is None else nmhe_ms.ravel(),
        None if est_time is None else est_time.ravel(),
    )
    clearance = vessel_clearance(world, states, nominal)
    finite = clearance[np.isfinite(clearance)]
    out["min_clearance_m"] = float(finite.min()) if len(finite) else None
    out["collision_samples"] = int(np.sum(clearance < 0.0))
    out["path_length_m"] = float(np.sum(np.hypot(*np.diff(states[:, :2], axis=0).T)))
    cut = report["cut_time"]
    out["watchdog_latency_ms"] = watchdog_latency_ms(report)
    last = report.get("last_command_before_cut")
    trips = [t for t in report["watchdog_trips"] if cut is not None and t >= cut]
    if last is not None and trips:  # the firmware rule itself: ≤ 150 ms + one tick
        out["watchdog_after_last_frame_ms"] = 1000.0 * (min(trips) - last)
    out["watchdog_trips_before_cut"] = sum(
        1 for tr in report["watchdog_trips"] if cut is None or tr < cut
    )
    for name, wire in report["wires"].items():
        out[f"wire_{name}_bytes_corrupted"] = wire["bytes_corrupted"]
        out[f"wire_{name}_bytes_to_host"] = wire["bytes_out"]
    out["mcu_frames_ok"] = report["mcu"]["frames_ok"]
    out["mcu_frames_rejected"] = report["mcu"]["frames_rejected"]
    return out


def _add_log(builder, vessel, path: Path, scenario):
    """The mission log (``log.mcap``) of the host diagram: its writer, recorder attached (with
    the host watchdog's status on ``/watchdog_status``)."""
    writer = MissionLogWriter(path)
    extra = [RecordedPort("watchdog_status", "/watchdog_status", names=WATCHDOG_FIELDS)]
    extra = [p for p in extra if vessel.HasOutputPort(p.port)]
    add_mission_recorder(builder, vessel, writer, scenario.visualization.rate_hz, extra)
    return writer


def _add_link_recorder(builder, vessel, writer, rate_hz: float) -> None:
    """A :class:`LinkRecorder` of every serial device of ``vessel`` (:func:`linked_devices`)."""
    names = linked_devices(vessel)
    if not names:
        return
    recorder = builder.AddNamedSystem("link_recorder", LinkRecorder(names, writer, rate_hz))
    for name in names:
        port = f"{name}_diagnostics"
        builder.Connect(vessel.GetOutputPort(port), recorder.GetInputPort(port))
