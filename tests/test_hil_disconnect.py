"""A device that goes away mid-run: reported on the diagnostics ports and in the metrics, the
thrust zeroed by the host watchdog, the port reopened when the device is back, and a hardware-in-
the-loop run that still ends with its metrics (``usvdrake hil``, issue 40 item 4).

Faults are placed on the simulated clock and the verdicts are events seen by the end of a run
(or within a bound of simulated time), so a loaded machine changes no outcome."""

import json

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder, LeafSystem
from pydrake.systems.primitives import ConstantVectorSource

from hardware_io.codecs.nmea import GGA, encode_gga
from hardware_io.emulators.pty_link import PtyDevice
from hardware_io.systems import GpsSerialSource
from hardware_io.systems.watchdog import Watchdog
from hardware_io.transport import SerialTransport
from usvdrake.cli import main as cli_main
from usvdrake.diagrams import load_scenario
from usvdrake.logs.mission_log import read_log_vectors
from usvdrake.run.hil import parse_rig_event, run_hil

GGA_FIX = encode_gga(GGA(43200.0, 52.37, 4.89, 1, 12, 0.7, 1.0, 46.0))
FIX_PERIOD = 0.02  # [s] a 50 Hz receiver
TIMEOUT = 0.5  # [s] the watchdog's, as hardware.sensor_timeout


class _Receiver(LeafSystem):
    """A GNSS receiver on ``device``: one GGA every ``FIX_PERIOD`` of simulated time."""

    def __init__(self, device: PtyDevice):
        super().__init__()
        self.device = device
        self.DeclarePeriodicPublishEvent(FIX_PERIOD, 0.0, self._send)

    def _send(self, context):
        self.device.write(GGA_FIX)


def _gps_loop(tmp_path):
    device = PtyDevice(link=tmp_path / "gps")
    builder = DiagramBuilder()
    builder.AddNamedSystem("receiver", _Receiver(device))
    # reconnect_period 0: the port is tried at every poll, so the reconnection is an event of
    # the simulated clock
    transport = SerialTransport(device.path, 9600, reconnect_period=0.0)
    gps = builder.AddNamedSystem("gps", GpsSerialSource("", 9600, "amsterdam", 0.01, transport))
    watchdog = builder.AddNamedSystem("watchdog", Watchdog(2, {"gps": TIMEOUT}))
    command = builder.AddSystem(ConstantVectorSource([10.0, -10.0]))
    builder.Connect(command.get_output_port(), watchdog.GetInputPort("thruster_command"))
    builder.Connect(gps.GetOutputPort("gps"), watchdog.GetInputPort("gps"))
    diagram = builder.Build()
    simulator = Simulator(diagram)
    simulator.set_target_realtime_rate(1.0)  # the receiver's bytes cross the pty in real time
    context = simulator.get_mutable_context()

    def read():
        link = gps.GetOutputPort("diagnostics").Eval(gps.GetMyContextFromRoot(context))
        wd = watchdog.GetMyContextFromRoot(context)
        status = watchdog.GetOutputPort("watchdog_status").Eval(wd)
        thrust = watchdog.GetOutputPort("thruster_command").Eval(wd)
        return link, status, thrust

    return device, gps, simulator, read


def test_unplugged_gps_trips_the_watchdog_and_is_reopened_when_back(tmp_path, capfd):
    device, gps, simulator, read = _gps_loop(tmp_path)
    try:
        simulator.AdvanceTo(1.0)
        device.unplug()
        simulator.AdvanceTo(1.0 + 3 * TIMEOUT)  # nothing can arrive: the port is gone
        link, status, thrust = read()
        assert not link["connected"] and link["disconnects"] == 1 and link["reconnects"] == 0
        assert status[0] == 1.0 and status[2] >= 1  # tripped, counted
        np.testing.assert_array_equal(thrust, [0.0, 0.0])
        err = capfd.readouterr().err
        assert err.count("lost") == 1 and str(device.path) in err  # one warning line

        device.replug()
        t = simulator.get_context().get_time()
        while t < 12.0:  # until the fixes flow again, bounded in simulated time
            t += 0.1
            simulator.AdvanceTo(t)
            link, status, thrust = read()
            if link["connected"] and status[0] == 0.0:
                break
        assert link["connected"] and link["disconnects"] == 1 and link["reconnects"] == 1
        assert status[0] == 0.0 and status[2] >= 1
        np.testing.assert_array_equal(thrust, [10.0, -10.0])
        assert "back" in capfd.readouterr().err
    finally:
        gps.close()
        device.close()
    assert not (tmp_path / "gps").exists()  # the device's name left with it


def test_rig_events_are_parsed_or_refused_with_one_line():
    assert parse_rig_event("3:unplug gps") == (3.0, "unplug gps")
    assert parse_rig_event("4.5: replug  imu") == (4.5, "replug imu")
    assert parse_rig_event("0:kill") == (0.0, "kill")
    for bad in ("unplug gps", "x:kill", "-1:kill", "nan:kill", "3:unplug radar", "3:reboot"):
        with pytest.raises(ValueError, match="rig event") as e:
            parse_rig_event(bad)
        assert "\n" not in str(e.value)


def test_hil_cli_refuses_a_bad_rig_event_with_one_line(tmp_path, capsys):
    code = cli_main(["hil", "river_tracking", "--rig-event", "3:reboot", "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "rig event" in err


@pytest.mark.slow
def test_hil_run_whose_rig_dies_ends_with_its_metrics(tmp_path, capfd):
    # the rig (every emulated device) is killed 3 s in: the ports fail at the host's next read
    code = cli_main(
        ["hil", "river_tracking", "--duration", "6", "--rig-event", "3:kill"]
        + ["--no-compare", "--quiet", "--out", str(tmp_path)]
    )
    err = capfd.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and "killed by signal 9" in err
    m = json.loads((tmp_path / "metrics.json").read_text())
    assert m["tracked_until_s"] == pytest.approx(6.0)
    assert m["device_disconnects"] >= 1 and m["gps_disconnects"] == 1
    assert set(m["devices_disconnected"]) == {"gps", "imu", "thruster"}
    assert m["watchdog_trips"] >= 1 and m["watchdog_tripped"]
    assert m["rig_events"] == [[3.0, "kill"]] and "signal 9" in m["rig_error"]
    assert "position_rmse_m" not in m  # no truth from a dead rig
    # the log says when the link went down, and that the watchdog tripped (silent GPS: bit 0)
    log = tmp_path / "log.mcap"
    times, link, _ = read_log_vectors(log, "/hil/link/gps")
    down = times[link[:, 1] >= 1]
    assert len(down) and down[0] >= 3.0 and not link[-1, 0]
    _, wd, _ = read_log_vectors(log, "/watchdog_status")
    assert wd[-1, 0] == 1.0 and wd[-1, 2] >= 1 and int(wd[-1, 1]) & 1


@pytest.mark.slow
def test_hil_run_reconnects_a_gps_unplugged_and_plugged_back(tmp_path, capfd):
    # 3 s without a GPS (the watchdog's timeout is 0.5 s), then 4 s to come back: the rig
    # replugs on a new pseudo-terminal under the same name, the host's port reopens
    scenario = load_scenario("river_tracking")
    events = [(2.0, "unplug gps"), (5.0, "replug gps")]
    result = run_hil(scenario, tmp_path, duration=9.0, compare_sim=False, rig_events=events)
    m = result.metrics
    assert m["gps_disconnects"] == 1 and m["gps_reconnects"] == 1 and m["gps_connected"]
    assert m["device_disconnects"] == 1 and m["device_reconnects"] == 1
    assert m["devices_disconnected"] == [] and "rig_error" not in m
    assert m["watchdog_trips"] >= 1
    assert m["imu_disconnects"] == m["thruster_disconnects"] == 0
    assert m["position_rmse_m"] is not None  # the rig lived: truth metrics as usual
    err = capfd.readouterr().err
    assert "Traceback" not in err
    assert err.count("gps lost") == 1 and err.count("gps back") == 1
    assert err.count(" lost (") == 1  # no other port, not even when the run ends
    report = json.loads((tmp_path / "rig_report.json").read_text())
    assert [e[1:] for e in report["plug_events"]] == [["gps", "unplug"], ["gps", "replug"]]
