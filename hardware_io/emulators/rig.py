"""The hardware-in-the-loop rig: the simulated boat behind real device protocols.

``python -m hardware_io.emulators.rig SCENARIO [--corrupt P] [--report FILE] [--link-dir DIR]``
builds the scenario's *simulated* station (plant, environment, simulated sensors), puts a thruster
microcontroller, a GNSS receiver, an IMU and, when the scenario has a 2D lidar, an RPLIDAR A1 on
pseudo-terminals in front of it (:mod:`hardware_io.emulators.device_systems`) and simulates it in
real time. It prints one JSON line ``{"ready": true, "ports": {"thrusters": "/dev/pts/N", ...}}``
on stdout; the host (``usvdrake hil``) opens those ports exactly as it would open the boat's USB
serial adapters. With ``--link-dir`` the ports are stable names in that folder (symlinks to the
pseudo-terminals, as ``/dev/serial/by-id`` names are), so a device can be unplugged and come
back under the same name.

The boat is moored (held at the scenario's initial state) until the microcontroller receives
its first valid command frame, so the host's start-up time does not let it drift. Control
lines on stdin: ``cut thrusters`` cuts the thruster wire (no byte crosses any more: the
firmware watchdog must bring the propellers to neutral), ``unplug NAME`` / ``replug NAME``
take a device away (the host reads EIO and its port name is gone) and bring it back (needs
``--link-dir``), ``stop`` (or end of stdin: the host died) ends the run and writes the report:
the truth on the wall clock, the cut and watchdog times, the unplugs and every wire's byte
counters.
"""

from __future__ import annotations

import argparse
import json
import os
import select
import sys
import time
from pathlib import Path

import numpy as np
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator
from pydrake.systems.framework import DiagramBuilder

from hardware_io.emulators.device_systems import (
    GpsEmulator,
    ImuEmulator,
    McuEmulator,
    RplidarEmulator,
    TruthRecorder,
)
from hardware_io.emulators.firmware import McuFirmware
from hardware_io.emulators.pty_link import PtyDevice, WireFaults
from usvdrake.diagrams import load_scenario
from usvdrake.diagrams.station import make_sim_station
from usvdrake.scenario import Scenario
from usvdrake.sensors.lidar_model import sample_rate
from usvdrake.sensors.pose_sensor import PoseSensorConfig
from usvdrake.vessel import load_vessel
from usvdrake.worlds import make_world

__all__ = ["Rig", "main"]

WIRES = ("thrusters", "gps", "imu")


class Rig:
    """The emulator diagram of ``scenario`` with its devices on new pseudo-terminals."""

    def __init__(
        self,
        scenario: Scenario,
        corruption: float = 0.0,
        gps_rate_hz: float = 20.0,
        imu_rate_hz: float = 100.0,
        link_dir: Path | None = None,
    ):
        self.scenario = scenario
        vessel = load_vessel(scenario.vessel)
        world = make_world(scenario.world, scenario.seed)
        wires = WIRES + (("lidar2d",) if "lidar2d" in scenario.sensors.enabled else ())
        self.faults = {
            name: WireFaults(corruption, seed=scenario.seed * 10 + i)
            for i, name in enumerate(wires)
        }
        self.ptys = {
            name: PtyDevice(self.faults[name], None if link_dir is None else Path(link_dir) / name)
            for name in wires
        }
        self.plug_events: list[tuple[float, str, str]] = []  # (monotonic, device, action)
        azimuth = any(t.azimuth for t in vessel.thrusters)
        self.firmware = McuFirmware(len(vessel.thrusters), azimuth=azimuth)

        builder = DiagramBuilder()
        station = builder.AddNamedSystem("station", make_sim_station(scenario, vessel, world))
        self._plant = station.GetSubsystemByName("plant")
        mcu = builder.AddNamedSystem(
            "thruster_mcu", McuEmulator(vessel.thrusters, self.ptys["thrusters"], self.firmware)
        )
        builder.Connect(
            mcu.GetOutputPort("thruster_command"), station.GetInputPort("thruster_command")
        )
        truth = station.GetOutputPort("ground_truth_state")
        pose = scenario.sensors.pose if "pose" in scenario.sensors.enabled else PoseSensorConfig()
        simulated = set(scenario.sensors.enabled)
        gps = builder.AddNamedSystem(
            "gps_receiver",
            GpsEmulator(
                self.ptys["gps"],
                world.datum,
                gps_rate_hz,
                position_std=float(np.hypot(pose.x_std, pose.y_std) / np.sqrt(2.0)),
                simulated_gps="gps" in simulated,
                seed=scenario.seed,
            ),
        )
        imu = builder.AddNamedSystem(
            "imu",
            ImuEmulator(
                self.ptys["imu"],
                imu_rate_hz,
                yaw_std=pose.psi_std,
                rate_std=pose.r_std,
                simulated_imu="imu" in simulated,
                seed=scenario.seed,
            ),
        )
        for device, port in ((gps, "gps"), (imu, "imu")):
            builder.Connect(truth, device.GetInputPort("state"))
            if device.HasInputPort(port):
                builder.Connect(station.GetOutputPort(port), device.GetInputPort(port))
        if "lidar2d" in self.ptys:
            lidar_cfg = scenario.sensors.lidar2d
            rate = sample_rate(lidar_cfg)
            lidar = builder.AddNamedSystem(
                "rplidar", RplidarEmulator(self.ptys["lidar2d"], 1.0 / rate)
            )
            builder.Connect(station.GetOutputPort("lidar_scan"), lidar.GetInputPort("lidar_scan"))
        self.truth = builder.AddNamedSystem("truth_recorder", TruthRecorder())
        builder.Connect(truth, self.truth.GetInputPort("state"))
        self.diagram = builder.Build()
        self.diagram.set_name("hil_rig")

        self.simulator = Simulator(self.diagram)
        ResetIntegratorFromFlags(
            self.simulator, scenario.simulation.integrator, scenario.simulation.max_step
        )
        self.simulator.get_mutable_integrator().set_target_accuracy(scenario.simulation.accuracy)
        self.simulator.set_target_realtime_rate(1.0)
        self._initial = np.asarray(scenario.initial_state, float)
        self.first_command_time: float | None = None
        self.last_command_before_cut: float | None = None
        self.simulator.Initialize()

    def ports(self) -> dict[str, str]:
        return {name: pty.path for name, pty in self.ptys.items()}

    @property
    def moored(self) -> bool:
        return self.first_command_time is None

    def step(self, dt: float = 0.01) -> None:
        """Advance the world by ``dt`` (paced to the wall clock); while moored, hold the boat."""
        context = self.simulator.get_mutable_context()
        self.simulator.AdvanceTo(context.get_time() + dt)
        if self.moored:
            if self.firmware.frames_ok > 0:
                self.first_command_time = time.monotonic()
            else:
                self._plant.GetMyMutableContextFromRoot(context).SetContinuousState(self._initial)

    def cut_thrusters(self) -> None:
        """Cut the thruster wire now (remembering when the last valid command had arrived)."""
        self.faults["thrusters"].cut()
        self.last_command_before_cut = self.firmware.last_command_time

    def plug(self, device: str, action: str) -> None:
        """``action`` = ``unplug`` / ``replug`` the wire named ``device``; an unknown device or
        a replug without a link dir is refused with ValueError."""
        if device not in self.ptys:
            raise ValueError(f"no device {device!r} (the rig has {', '.join(self.ptys)})")
        pty = self.ptys[device]
        if action == "unplug":
            pty.unplug()
        else:
            pty.replug()
        self.plug_events.append((time.monotonic(), device, action))

    def report(self) -> dict:
        fw = self.firmware
        return {
            "sim_time_s": self.simulator.get_context().get_time(),
            "first_command_time": self.first_command_time,
            "cut_time": self.faults["thrusters"].cut_time,
            "last_command_before_cut": self.last_command_before_cut,
            "watchdog_trips": list(fw.trip_times),
            "plug_events": [list(e) for e in self.plug_events],
            "mcu": {
                "frames_ok": fw.frames_ok,
                "frames_rejected": fw.frames_rejected,
                "pwm_us": list(fw.pwm_us),
            },
            "wires": {
                name: {
                    "bytes_in": pty.bytes_in,
                    "bytes_out": pty.bytes_out,
                    "bytes_corrupted": self.faults[name].bytes_corrupted,
                }
                for name, pty in self.ptys.items()
            },
            "truth_columns": ["wall_time", "sim_time", "x", "y", "psi", "u", "v", "r"],
            "truth": self.truth.rows,
        }

    def close(self) -> None:
        for pty in self.ptys.values():
            pty.close()


class _ControlLines:
    """Non-blocking line reader on a file descriptor; ``eof`` once the writer has gone."""

    def __init__(self, fd: int):
        self.fd, self.eof, self._buf = fd, False, b""

    def poll(self) -> list[str]:
        lines = []
        while not self.eof and select.select([self.fd], [], [], 0)[0]:
            chunk = os.read(self.fd, 4096)
            if not chunk:
                self.eof = True
                break
            self._buf += chunk
        while b"\n" in self._buf:
            line, self._buf = self._buf.split(b"\n", 1)
            lines.append(line.decode(errors="replace").strip())
        return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m hardware_io.emulators.rig", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("scenario", help="scenario name or YAML path")
    parser.add_argument("--corrupt", type=float, default=0.0, help="fraction of bytes corrupted")
    parser.add_argument("--report", type=Path, help="write the JSON report here on stop")
    parser.add_argument("--gps-rate", type=float, default=20.0, help="[Hz] GGA rate")
    parser.add_argument("--imu-rate", type=float, default=100.0, help="[Hz] MTData2 rate")
    parser.add_argument("--link-dir", type=Path, help="put the ports here as stable names")
    args = parser.parse_args(argv)

    rig = Rig(
        load_scenario(args.scenario), args.corrupt, args.gps_rate, args.imu_rate, args.link_dir
    )
    print(json.dumps({"ready": True, "ports": rig.ports()}), flush=True)
    control = _ControlLines(sys.stdin.fileno())
    try:
        while True:
            lines = control.poll()
            if "stop" in lines or control.eof:
                break
            if "cut thrusters" in lines:
                rig.cut_thrusters()
            for line in lines:
                action, _, device = line.partition(" ")
                if action in ("unplug", "replug"):
                    try:
                        rig.plug(device, action)
                    except ValueError as e:  # a bad control line must not end the run
                        print(f"rig: {line}: {e}", file=sys.stderr, flush=True)
            rig.step()
    finally:
        if args.report is not None:
            args.report.write_text(json.dumps(rig.report()))
        rig.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
