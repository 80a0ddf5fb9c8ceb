"""The hardware station: the boat's real devices behind the station's ports (DESIGN.md).

Same port names as :func:`usvdrake.diagrams.station.make_sim_station` minus
``ground_truth_state`` (there is none on the water), plus ``watchdog_status``,
``thruster_link`` and the devices' counters (``<device>_diagnostics``)::

    thruster_command ─► Watchdog ─► ThrusterSerialSink ─► thrust_measured, thruster_link
                           ▲ gps, imu, lidar (required ones)
    gps (GpsSerialSource) ─► gps ─┐
    imu (ImuSerialSource) ─► imu ─┴► GnssImuPose ─► pose_measurement
    lidar2d (LidarSerialSource) ─► lidar_scan     lidar3d (VelodyneUdpSource) ─► lidar_points

The sensor devices come from the device table :data:`~usvdrake.diagrams.devices.DEVICES`: every
row that the scenario's ``hardware`` section (:class:`~usvdrake.scenario.HardwareConfig`) fits
is built and named by its row's name, the sensor's one name (``gps``, ``imu``, ``lidar2d``,
``lidar3d``, as the simulated station names its sensors). The thruster MCU and the watchdog are
fixed parts. The ``Watchdog`` zeroes the thrust while a sensor the autonomy needs is silent for
``hardware.sensor_timeout``; the sink's keep-alive thread sends neutral when the diagram itself
stops handing it commands; the microcontroller's own watchdog covers a cut wire
(``hardware_io/PROTOCOL.md``).
"""

from __future__ import annotations

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder

from hardware_io.systems.gnss_imu_pose import GnssImuPose
from hardware_io.systems.thruster_serial_sink import ThrusterSerialSink
from hardware_io.systems.watchdog import Watchdog
from usvdrake.diagrams.devices import DEVICES
from usvdrake.scenario import HardwareConfig, Scenario
from usvdrake.systems.vessel.thrusters import command_size
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World

__all__ = [
    "close_hardware",
    "hardware_metrics",
    "linked_devices",
    "make_hardware_station",
    "port_devices",
    "station_ports_for",
]

#: Station output ports fused from several devices → those devices.
FUSED_PORTS = {"pose_measurement": ("gps", "imu")}

#: :func:`hardware_metrics`' key prefix per device (the 2D lidar's metrics have always been
#: ``lidar_*``).
METRIC_PREFIXES = {"gps": "gps", "imu": "imu", "lidar2d": "lidar"}


def port_devices() -> dict[str, tuple[str, ...]]:
    """Station output port → the hardware devices that make it (from :data:`DEVICES`, plus
    the fused :data:`FUSED_PORTS`)."""
    out: dict[str, tuple[str, ...]] = {}
    for name in DEVICES:
        out.setdefault(DEVICES.get(name).port, (name,))
    out.update(FUSED_PORTS)
    return out


def _fitted(hw: HardwareConfig, device: str) -> bool:
    return device in DEVICES and DEVICES.get(device).fitted(hw)


def station_ports_for(hw: HardwareConfig) -> list[str]:
    """The sensor ports a hardware station with these devices exports."""
    return [p for p, devs in port_devices().items() if all(_fitted(hw, d) for d in devs)]


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
    """The named Diagram ``station`` of the thruster MCU, the watchdog and every device of
    :data:`~usvdrake.diagrams.devices.DEVICES` that ``hardware`` fits (each system named by its
    device's name); ``needs`` are the station outputs the autonomy reads (each must be made by
    fitted devices; those sensors are also the watchdog's required ones). A port that does not
    exist raises :class:`~hardware_io.transport.PortNotFoundError` with one line naming it; the
    ports opened before it are closed again."""
    hw = hardware
    if not hw.thrusters.port:
        raise ValueError("hardware.thrusters.port: the hardware station needs the thruster MCU")
    makers = port_devices()
    missing = [
        f"{port} (fit hardware.{' and hardware.'.join(makers[port])})"
        for port in needs
        if port in makers and port not in station_ports_for(hw)
    ]
    if missing:
        raise ValueError("the autonomy needs station output " + ", ".join(missing))

    opened = []  # systems holding ports or sockets, closed again if the build fails
    try:
        station = _build(scenario, vessel, world, hw, needs, makers, opened)
    except BaseException:
        for system in opened:
            if callable(getattr(system, "close", None)):
                system.close()
        raise
    station.set_name("station")
    return station


def _build(scenario, vessel, world, hw, needs, makers, opened) -> Diagram:
    builder = DiagramBuilder()

    def add(name, system):
        opened.append(system)
        return builder.AddNamedSystem(name, system)

    sink = add(
        "thruster_serial_sink",
        ThrusterSerialSink(
            vessel.thrusters,
            hw.thrusters.port,
            hw.thrusters.baudrate,
            send_rate_hz=hw.command_rate_hz,
            stale_timeout=hw.stale_timeout,
        ),
    )
    sources = {}  # device name → its system, named after it
    for name in DEVICES:
        device = DEVICES.get(name)
        if device.fitted(hw):
            sources[name] = add(name, device.make(hw, scenario, world))
    for name, system in sources.items():
        port = DEVICES.get(name).port
        builder.ExportOutput(system.GetOutputPort(port), port)
    if "gps" in sources and "imu" in sources:
        pose = builder.AddNamedSystem(
            "gnss_imu_pose", GnssImuPose(world.datum, scenario.initial_state[:3])
        )
        for name in ("gps", "imu"):  # GnssImuPose's inputs are named after the ports
            port = DEVICES.get(name).port
            builder.Connect(sources[name].GetOutputPort(port), pose.GetInputPort(port))
        builder.ExportOutput(pose.GetOutputPort("pose_measurement"), "pose_measurement")

    required = sorted({d for p in needs if p in makers for d in makers[p]})
    required_ports = {DEVICES.get(d).port: hw.sensor_timeout for d in required}
    watchdog = builder.AddNamedSystem(
        "watchdog",
        Watchdog(
            command_size(vessel.thrusters),
            required_ports,
            force_mask=_force_mask(vessel.thrusters),
        ),
    )
    for d in required:
        port = DEVICES.get(d).port
        builder.Connect(sources[d].GetOutputPort(port), watchdog.GetInputPort(port))
    builder.Connect(
        watchdog.GetOutputPort("thruster_command"), sink.GetInputPort("thruster_command")
    )
    builder.ExportInput(watchdog.GetInputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(watchdog.GetOutputPort("watchdog_status"), "watchdog_status")
    builder.ExportOutput(sink.GetOutputPort("thrust_measured"), "thrust_measured")
    builder.ExportOutput(sink.GetOutputPort("thruster_link"), "thruster_link")
    for name, system in sources.items():
        if system.HasOutputPort("diagnostics"):
            builder.ExportOutput(system.GetOutputPort("diagnostics"), f"{name}_diagnostics")
    builder.ExportOutput(sink.GetOutputPort("diagnostics"), "thruster_diagnostics")
    return builder.Build()


def close_hardware(diagram: Diagram) -> None:
    """Release every port and thread the hardware systems inside ``diagram`` hold."""
    for system in diagram.GetSystems():
        if isinstance(system, Diagram):
            close_hardware(system)
        elif callable(getattr(system, "close", None)):
            system.close()


def linked_devices(vessel_diagram: Diagram) -> list[str]:
    """The serial devices whose ``<device>_diagnostics`` port ``vessel_diagram`` exports, each
    with its link (``connected``, ``disconnects``, ``reconnects``): those of
    :data:`METRIC_PREFIXES` that are fitted, then ``thruster``."""
    names = (*METRIC_PREFIXES, "thruster")
    return [d for d in names if vessel_diagram.HasOutputPort(f"{d}_diagnostics")]


def hardware_metrics(vessel_diagram: Diagram, context) -> dict:
    """The hardware devices' counters, read off the ``<device>_diagnostics`` output ports of
    ``vessel_diagram`` (a vessel diagram with a hardware station, or the station itself) in
    ``context`` (the root context of the diagram it is part of): ``gps_<counter>``,
    ``imu_<counter>``, ``lidar_<counter>`` (the 2D lidar) for each fitted device, then
    ``thruster_telemetry_frames``, ``thruster_crc_errors``, ``thruster_frame_errors``,
    ``thruster_frames_sent``, ``thruster_neutral_frames``, ``thruster_stale_events``, each
    device's link (``<prefix>_connected``, ``<prefix>_disconnects``, ``<prefix>_reconnects``)
    and over all of them ``device_disconnects``, ``device_reconnects`` and
    ``devices_disconnected`` (the devices still gone at the end); off ``watchdog_status``,
    ``watchdog_trips`` (times the host watchdog zeroed the thrust) and ``watchdog_tripped``
    (it still was at the end). Empty for a diagram without them (a simulated station)."""
    ctx = vessel_diagram.GetMyContextFromRoot(context)
    out: dict = {}
    links = {}
    for device in linked_devices(vessel_diagram):
        counters = vessel_diagram.GetOutputPort(f"{device}_diagnostics").Eval(ctx)
        prefix = METRIC_PREFIXES.get(device, device)
        out.update({f"{prefix}_{key}": value for key, value in counters.items()})
        links[device] = counters
    if links:
        out["device_disconnects"] = sum(c["disconnects"] for c in links.values())
        out["device_reconnects"] = sum(c["reconnects"] for c in links.values())
        out["devices_disconnected"] = [d for d, c in links.items() if not c["connected"]]
    if vessel_diagram.HasOutputPort("watchdog_status"):
        tripped, _silent, trips = vessel_diagram.GetOutputPort("watchdog_status").Eval(ctx)
        out["watchdog_trips"] = int(trips)
        out["watchdog_tripped"] = bool(tripped)
    return out
