"""The vessel diagram: station + autonomy halves, ports by name, state in the Context."""

import dataclasses

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from usvdrake import build_vessel_diagram, load_scenario, load_vessel, run_mission
from usvdrake.diagrams.station import make_sim_station
from usvdrake.worlds import make_world


def test_station_ports():
    s = load_scenario("canal_demo")
    vessel, world = load_vessel(s.vessel), make_world(s.world)
    station = make_sim_station(s, vessel, world)
    assert station.get_name() == "station"
    inputs = [station.get_input_port(i).get_name() for i in range(station.num_input_ports())]
    assert inputs == ["thruster_command"]
    outs = {station.get_output_port(i).get_name() for i in range(station.num_output_ports())}
    assert outs == {"thrust_measured", "thrust_applied", "ground_truth_state"}
    sensors = dataclasses.replace(s.sensors, enabled=["lidar2d", "lidar3d", "imu", "gps"])
    full = make_sim_station(dataclasses.replace(s, sensors=sensors), vessel, world)
    outs = {full.get_output_port(i).get_name() for i in range(full.num_output_ports())}
    expected = {"thrust_measured", "thrust_applied", "ground_truth_state"}
    assert outs == expected | {"lidar_scan", "lidar_points", "imu", "gps"}
    # each sensor's system is named by its one name
    assert {"lidar2d", "lidar3d", "imu", "gps"} <= {x.get_name() for x in full.GetSystems()}


def test_devices_share_the_sensor_names_and_ports():
    from usvdrake.diagrams import DEVICES
    from usvdrake.diagrams.hardware_station import port_devices, station_ports_for
    from usvdrake.diagrams.sensors import SENSORS
    from usvdrake.scenario import HardwareConfig, SerialDeviceConfig

    assert DEVICES.names() == ["gps", "imu", "lidar2d", "lidar3d"]
    assert all(DEVICES.get(n).port == SENSORS.get(n).port for n in DEVICES)
    assert port_devices() == {
        "gps": ("gps",),
        "imu": ("imu",),
        "lidar_scan": ("lidar2d",),
        "lidar_points": ("lidar3d",),
        "pose_measurement": ("gps", "imu"),
    }
    hw = HardwareConfig(gps=SerialDeviceConfig("/dev/gps"), imu=SerialDeviceConfig("/dev/imu"))
    assert [n for n in DEVICES if DEVICES.get(n).fitted(hw)] == ["gps", "imu"]
    assert station_ports_for(hw) == ["gps", "imu", "pose_measurement"]


def test_vessel_diagram_structure_reads_like_the_picture():
    d = build_vessel_diagram(load_scenario("canal_demo"))
    names = {s.get_name() for s in d.GetSystems()}
    assert names == {"station", "autonomy"}
    station, autonomy = d.GetSubsystemByName("station"), d.GetSubsystemByName("autonomy")
    assert {s.get_name() for s in station.GetSystems()} == {
        "thrust_mixer",
        "plant",
        "environment",
        "thrust_sensor",
    }
    assert {s.get_name() for s in autonomy.GetSystems()} == {
        "oracle_estimator",
        "los_guidance",
        "heading_speed_controller",
        "thrust_allocation",
    }
    dot = d.GetGraphvizString(max_depth=2)
    for word in (
        "station",
        "autonomy",
        "thruster_command",
        "ground_truth_state",
        "thrust_allocation",
    ):
        assert word in dot
    for port in ("ground_truth_state", "thrust_measured", "thruster_command", "mission_complete"):
        assert d.HasOutputPort(port)


def test_hardware_station_has_the_sim_station_ports_and_the_same_autonomy():
    from hardware_io.emulators.pty_link import PtyDevice
    from hardware_io.systems.gps_serial_source import GpsSerialStatus
    from hardware_io.systems.imu_serial_source import ImuSerialStatus
    from usvdrake.diagrams.hardware_station import close_hardware, hardware_metrics

    s = load_scenario("river_tracking")
    devices = {name: PtyDevice() for name in ("thrusters", "gps", "imu")}
    hw = dataclasses.replace(
        s.hardware,
        **{
            name: dataclasses.replace(getattr(s.hardware, name), port=dev.path)
            for name, dev in devices.items()
        },
    )
    hard = build_vessel_diagram(s, hardware=hw)
    sim = build_vessel_diagram(s)
    try:

        def outputs(d):
            return {d.get_output_port(i).get_name() for i in range(d.num_output_ports())}

        assert outputs(sim) - outputs(hard) == {"ground_truth_state", "thrust_applied"}
        # river_tracking simulates its IMU too (the NMHE reads it); the GPS only on the boat
        assert outputs(hard) - outputs(sim) == {
            "gps",
            "watchdog_status",
            "thruster_link",
            "gps_diagnostics",
            "imu_diagnostics",
            "thruster_diagnostics",
        }

        def autonomy(d):
            a = d.GetSubsystemByName("autonomy")
            return sorted((x.get_name(), type(x).__name__) for x in a.GetSystems())

        assert autonomy(hard) == autonomy(sim)
        station = hard.GetSubsystemByName("station")
        # the devices are named by their sensor names, as in the simulated station
        assert {x.get_name() for x in station.GetSystems()} == {
            "thruster_serial_sink",
            "gps",
            "imu",
            "gnss_imu_pose",
            "watchdog",
        }
        assert "imu" in {x.get_name() for x in sim.GetSubsystemByName("station").GetSystems()}

        # the devices' counters, read off the diagnostics ports (nothing received yet)
        metrics = hardware_metrics(hard, hard.CreateDefaultContext())
        link = ["connected", "disconnects", "reconnects"]
        gps_keys = [f"gps_{f.name}" for f in dataclasses.fields(GpsSerialStatus)]
        imu_keys = [f"imu_{f.name}" for f in dataclasses.fields(ImuSerialStatus)]
        thruster_keys = [
            f"thruster_{k}"
            for k in (
                "telemetry_frames",
                "crc_errors",
                "frame_errors",
                "frames_sent",
                "neutral_frames",
                "stale_events",
            )
        ]
        assert list(metrics) == [
            *gps_keys,
            *(f"gps_{k}" for k in link),
            *imu_keys,
            *(f"imu_{k}" for k in link),
            *thruster_keys,
            *(f"thruster_{k}" for k in link),
            "device_disconnects",
            "device_reconnects",
            "devices_disconnected",
            "watchdog_trips",
            "watchdog_tripped",
        ]
        assert metrics["gps_bytes_read"] == metrics["thruster_frames_sent"] == 0
        assert metrics["device_disconnects"] == metrics["watchdog_trips"] == 0
        assert metrics["devices_disconnected"] == []
    finally:
        close_hardware(hard)
        for dev in devices.values():
            dev.close()


def test_hardware_station_errors_name_what_is_missing():
    with pytest.raises(ValueError, match="hardware.thrusters.port"):
        build_vessel_diagram(load_scenario("canal_demo"), hardware=True)
    s = load_scenario("river_tracking")
    no_imu = dataclasses.replace(s.hardware, imu=dataclasses.replace(s.hardware.imu, port=""))
    with pytest.raises(ValueError, match="pose_measurement .fit hardware.gps and hardware.imu"):
        build_vessel_diagram(s, hardware=no_imu)


def test_state_lives_in_the_context():
    """Two simulations of one diagram from fresh contexts give identical trajectories."""
    s = dataclasses.replace(load_scenario("canal_demo"), duration=5.0)
    d = build_vessel_diagram(s)
    finals = []
    for _ in range(2):
        sim = Simulator(d)
        sim.AdvanceTo(5.0)
        finals.append(d.GetOutputPort("ground_truth_state").Eval(sim.get_context()).copy())
    np.testing.assert_array_equal(finals[0], finals[1])
    assert finals[0][0] > -4.0 + 1.0  # it moved forward


def test_same_seed_same_metrics_bit_for_bit():
    s = dataclasses.replace(load_scenario("usv2000_open_water"), duration=20.0)
    a = run_mission(s).metrics
    b = run_mission(s).metrics
    for k in ("wall_time_s", "realtime_factor"):
        a.pop(k), b.pop(k)
    assert a == b
    c = run_mission(dataclasses.replace(s, seed=s.seed + 1)).metrics
    assert c["path_length_m"] != a["path_length_m"]
