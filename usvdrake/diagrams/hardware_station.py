"""The hardware station: the boat's real devices behind the station's ports (DESIGN.md).

Same port names as :func:`usvdrake.diagrams.station.make_sim_station` minus
``ground_truth_state`` (there is none on the water), plus ``watchdog_status`` and
``thruster_link``::

    thruster_command ─► Watchdog ─► ThrusterSerialSink ─► thrust_measured, thruster_link
                           ▲ gps, imu, lidar (required ones)
    GpsSerialSource ─► gps ─┐
    ImuSerialSource ─► imu ─┴► GnssImuPose ─► pose_measurement
    LidarSerialSource ─► lidar_scan        VelodyneUdpSource ─► lidar_points

Devices come from the scenario's ``hardware`` section (:class:`~usvdrake.scenario.HardwareConfig`);
a device with no port is not fitted. The ``Watchdog`` zeroes the thrust while a sensor the
autonomy needs is silent for ``hardware.sensor_timeout``; the sink's keep-alive thread sends
neutral when the diagram itself stops handing it commands; the microcontroller's own watchdog
covers a cut wire (``hardware_io/PROTOCOL.md``).
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder

from usvdrake.scenario import HardwareConfig, Scenario
from usvdrake.systems.vessel.thrusters import command_size
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World

__all__ = ["close_hardware", "make_hardware_station", "station_ports_for"]

#: Station output port → the hardware devices that make it.
PORT_DEVICES = {
    "gps": ("gps",),
    "imu": ("imu",),
    "pose_measurement": ("gps", "imu"),
    "lidar_scan": ("lidar2d",),
    "lidar_points": ("lidar3d",),
}


def _fitted(hw: HardwareConfig, device: str) -> bool:
    cfg = getattr(hw, device)
    return bool(cfg.address if device == "lidar3d" else cfg.port)


def station_ports_for(hw: HardwareConfig) -> list[str]:
    """The sensor ports a hardware station with these devices exports."""
    return [p for p, devs in PORT_DEVICES.items() if all(_fitted(hw, d) for d in devs)]


def _force_mask(thrusters) -> np.ndarray:
    mask = []
    for t in thrusters:
        mask += [True, False] if t.azimuth else [True]
    return np.array(mask, bool)


def make_hardware_station(
    scenario: Scenario,
    vessel: VesselParams,
    world: World,
    hardware: HardwareConfig,
    needs: list[str],
) -> Diagram:
    """The named Diagram ``station`` of the devices in ``hardware``; ``needs`` are the station
    outputs the autonomy reads (each must be made by fitted devices; those sensors are also the
    watchdog's required ones). A port that does not exist raises
    :class:`~hardware_io.transport.PortNotFoundError` with one line naming it."""
    from hardware_io.systems.gnss_imu_pose import GnssImuPose
    from hardware_io.systems.gps_serial_source import GpsSerialSource
    from hardware_io.systems.thruster_serial_sink import ThrusterSerialSink
    from hardware_io.systems.watchdog import Watchdog

    hw = hardware
    if not hw.thrusters.port:
        raise ValueError("hardware.thrusters.port: the hardware station needs the thruster MCU")
    missing = [
        f"{port} (fit hardware.{' and hardware.'.join(PORT_DEVICES[port])})"
        for port in needs
        if port in PORT_DEVICES and port not in station_ports_for(hw)
    ]
    if missing:
        raise ValueError("the autonomy needs station output " + ", ".join(missing))

    builder = DiagramBuilder()
    opened = []  # systems holding ports, closed again if a later one fails

    def add(name, factory):
        try:
            system = factory()
        except Exception:
            for s in opened:
                s.close()
            raise
        opened.append(system)
        return builder.AddNamedSystem(name, system)

    sink = add(
        "thruster_serial_sink",
        lambda: ThrusterSerialSink(
            vessel.thrusters,
            hw.thrusters.port,
            hw.thrusters.baudrate,
            send_rate_hz=hw.command_rate_hz,
            stale_timeout=hw.stale_timeout,
        ),
    )
    sources = {}
    if _fitted(hw, "gps"):
        sources["gps"] = add(
            "gps_serial_source",
            lambda: GpsSerialSource(
                hw.gps.port, hw.gps.baudrate, world.datum, period=hw.poll_period
            ),
        )
    if _fitted(hw, "imu"):
        from hardware_io.systems.imu_serial_source import ImuSerialSource

        sources["imu"] = add(
            "imu_serial_source",
            lambda: ImuSerialSource(hw.imu.port, hw.imu.baudrate, period=hw.poll_period),
        )
    if _fitted(hw, "lidar2d"):
        from hardware_io.systems.lidar_serial_source import LidarSerialSource

        sources["lidar_scan"] = add(
            "lidar_serial_source",
            lambda: LidarSerialSource(
                hw.lidar2d.port, hw.lidar2d.baudrate, hw.lidar2d.protocol, period=hw.poll_period
            ),
        )
    if _fitted(hw, "lidar3d"):
        from hardware_io.systems.velodyne_udp_source import VelodyneUdpSource

        sources["lidar_points"] = add(
            "velodyne_udp_source",
            lambda: VelodyneUdpSource(hw.lidar3d.address, hw.lidar3d.port, period=hw.poll_period),
        )
    for port, system in sources.items():
        builder.ExportOutput(system.GetOutputPort(port), port)
    if "gps" in sources and "imu" in sources:
        pose = builder.AddNamedSystem(
            "gnss_imu_pose", GnssImuPose(world.datum, scenario.initial_state[:3])
        )
        builder.Connect(sources["gps"].GetOutputPort("gps"), pose.GetInputPort("gps"))
        builder.Connect(sources["imu"].GetOutputPort("imu"), pose.GetInputPort("imu"))
        builder.ExportOutput(pose.GetOutputPort("pose_measurement"), "pose_measurement")

    required = sorted({d for p in needs if p in PORT_DEVICES for d in PORT_DEVICES[p]})
    required_ports = {
        {"lidar2d": "lidar_scan", "lidar3d": "lidar_points"}.get(d, d): hw.sensor_timeout
        for d in required
    }
    watchdog = builder.AddNamedSystem(
        "watchdog",
        Watchdog(
            command_size(vessel.thrusters),
            required_ports,
            force_mask=_force_mask(vessel.thrusters),
        ),
    )
    for port in required_ports:
        builder.Connect(sources[port].GetOutputPort(port), watchdog.GetInputPort(port))
    builder.Connect(
        watchdog.GetOutputPort("thruster_command"), sink.GetInputPort("thruster_command")
    )
    builder.ExportInput(watchdog.GetInputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(watchdog.GetOutputPort("watchdog_status"), "watchdog_status")
    builder.ExportOutput(sink.GetOutputPort("thrust_measured"), "thrust_measured")
    builder.ExportOutput(sink.GetOutputPort("thruster_link"), "thruster_link")
    station = builder.Build()
    station.set_name("station")
    return station


def close_hardware(diagram: Diagram) -> None:
    """Release every port and thread the hardware systems inside ``diagram`` hold."""
    for system in diagram.GetSystems():
        if isinstance(system, Diagram):
            close_hardware(system)
        elif callable(getattr(system, "close", None)):
            system.close()
