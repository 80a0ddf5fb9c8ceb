"""The 2D SLAM on insane scans: refused or cleaned and counted, never an exception, never a map
that grows with a 1e300 m ray (issue "Bad input gets a clear error", item 8)."""

import dataclasses
import tracemalloc

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.slam.graph_slam import GraphSlamConfig
from usvdrake.systems.slam.hector import HectorConfig
from usvdrake.systems.slam.lidar_slam2d import HectorSlam, LidarSlam2D
from usvdrake.systems.slam.scan_checks import usable_scan

GOOD = LaserScan(
    time=0.1,
    angle_min=-np.pi / 2,
    angle_increment=np.pi / 179,
    range_max=30.0,
    ranges=np.full(180, 5.0),
    valid=np.ones(180, bool),
)
INSANE = {
    "nan angle step": dataclasses.replace(GOOD, angle_increment=np.nan),
    "zero angle step": dataclasses.replace(GOOD, angle_increment=0.0),
    "inf start angle": dataclasses.replace(GOOD, angle_min=np.inf),
    "nan range_max": dataclasses.replace(GOOD, range_max=np.nan),
}
CLEANED = {
    "1e300 ranges flagged valid": dataclasses.replace(
        GOOD, range_max=1e301, ranges=np.full(180, 1e300)
    ),
    "300-1000 m ranges flagged valid": dataclasses.replace(
        GOOD, range_max=2000.0, ranges=np.linspace(300.0, 1000.0, 180)
    ),
    "nan ranges flagged valid": dataclasses.replace(GOOD, ranges=np.full(180, np.nan)),
}


def test_a_sane_scan_passes_untouched():
    assert usable_scan(GOOD) is GOOD


@pytest.mark.parametrize("name", sorted(INSANE))
def test_insane_scans_are_refused(name):
    assert usable_scan(INSANE[name]) is None


@pytest.mark.parametrize("name", sorted(CLEANED))
def test_absurd_ranges_are_no_returns(name):
    scan = usable_scan(CLEANED[name])
    assert scan is not None and not scan.valid.any() and scan.range_max <= 200.0


@pytest.mark.parametrize("slam_kind", ["graph", "hector"])
def test_the_slam_systems_survive_insane_scans_and_count_them(slam_kind):
    period = 0.1
    if slam_kind == "graph":
        slam = LidarSlam2D(GraphSlamConfig(), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], period)
    else:
        slam = HectorSlam(HectorConfig(), [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], period)
    simulator = Simulator(slam)
    context = simulator.get_mutable_context()
    port = slam.GetInputPort("lidar_scan")
    scans = [*INSANE.values(), *CLEANED.values()]
    tracemalloc.start()
    for k, scan in enumerate(scans):
        t = (k + 1) * period
        port.FixValue(context, dataclasses.replace(scan, time=t - 0.05))
        simulator.AdvanceTo(t)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 200e6, f"{peak / 1e6:.0f} MB"
    summary = slam.GetOutputPort("slam_summary").Eval(context)
    assert summary.rejected_scans == len(INSANE)
    pose = slam.GetOutputPort("slam_pose").Eval(context)
    assert np.isfinite(pose).all()
