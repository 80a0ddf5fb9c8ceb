"""Lidar systems: exact before noise through the LeafSystems, motion, noise, determinism."""

import dataclasses

import numpy as np
import pytest
from _worlds import ROOM
from pydrake.systems.analysis import Simulator

from usvdrake.sensors.lidar2d import Lidar2D
from usvdrake.sensors.lidar3d import Lidar3D
from usvdrake.sensors.lidar_model import LIDAR_PRESETS, LidarConfig, body_motion, preset_by_name


def sample(system, port, state, t=None):
    sim = Simulator(system)
    system.GetInputPort("state").FixValue(sim.get_mutable_context(), state)
    sim.AdvanceTo(t if t is not None else 1.5 * system.period)  # the first sweep ends at one period
    return system.GetOutputPort(port).Eval(sim.get_context())


def expected_room_ranges(o, az):
    c, s = np.cos(az), np.sin(az)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (10 - o[0]) / c, np.where(c < 0, (-10 - o[0]) / c, np.inf))
        ty = np.where(s > 0, (5 - o[1]) / s, np.where(s < 0, (-5 - o[1]) / s, np.inf))
    f = o - np.array([4.0, 2.0])
    b = c * f[0] + s * f[1]
    disc = b**2 - (f @ f - 0.3**2)
    tc = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    tc = np.where(tc > 0, tc, np.inf)
    return np.minimum(np.minimum(tx, ty), tc)


@pytest.mark.parametrize("preset", ["rplidar_a1", "hokuyo_utm30lx"])
def test_lidar2d_exact_without_noise(preset):
    cfg = LidarConfig(preset=preset, mount=[0.2, 0.0, 0.5, 0.0], motion=False, noise=False)
    lidar = Lidar2D(cfg, ROOM.scene, seed=0)
    q = np.array([-1.0, 1.0, 0.3, 0.0, 0.0, 0.0])
    scan = sample(lidar, "lidar_scan", q)
    o = q[:2] + 0.2 * np.array([np.cos(0.3), np.sin(0.3)])
    expected = expected_room_ranges(o, scan.angles + 0.3)
    expected = np.where(expected <= preset_by_name(preset).range_max, expected, np.inf)
    np.testing.assert_array_equal(scan.valid, np.isfinite(expected))
    np.testing.assert_allclose(scan.ranges[scan.valid], expected[scan.valid], atol=1e-6)
    assert not np.any(scan.ranges == 0)
    assert len(scan.ranges) == (360 if preset == "rplidar_a1" else 1081)


def test_lidar2d_noise_statistics_and_determinism():
    cfg = LidarConfig(preset="hokuyo_utm30lx", motion=False)
    q = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    a = sample(Lidar2D(cfg, ROOM.scene, seed=3), "lidar_scan", q, t=0.5)
    b = sample(Lidar2D(cfg, ROOM.scene, seed=3), "lidar_scan", q, t=0.5)
    c = sample(Lidar2D(cfg, ROOM.scene, seed=4), "lidar_scan", q, t=0.5)
    np.testing.assert_array_equal(a.ranges, b.ranges)
    assert not np.array_equal(a.ranges, c.ranges)
    exact = expected_room_ranges(np.zeros(2), a.angles)
    err = (a.ranges - exact)[a.valid]
    sigma = 0.01 + 0.0013 * exact[a.valid]
    assert np.std(err / sigma) == pytest.approx(1.0, abs=0.1)
    assert abs(np.mean(err / sigma)) < 0.15


def test_lidar2d_motion_moves_the_beam_origins():
    """A vessel at 2 m/s: the first beam of a 5.5 Hz sweep fired ~0.36 m behind the last."""
    cfg = LidarConfig(preset="rplidar_a1", mount=[0.0, 0.0, 0.5, 0.0], noise=False, motion=True)
    q = np.array([0.0, 0.0, 0.0, 2.0, 0.0, 0.0])
    scan = sample(Lidar2D(cfg, ROOM.scene, seed=0), "lidar_scan", q)
    preset = preset_by_name("rplidar_a1")
    dt = np.arange(360) / 360 / preset.rate_hz - 1 / preset.rate_hz
    pos, _ = body_motion(q, dt)
    expected = np.array(
        [expected_room_ranges(p, np.array([a]))[0] for p, a in zip(pos, scan.angles, strict=True)]
    )
    expected = np.where(expected <= preset.range_max, expected, np.inf)
    np.testing.assert_allclose(scan.ranges[scan.valid], expected[scan.valid], atol=1e-6)


def test_body_motion_is_an_exact_arc():
    q = np.array([1.0, 2.0, 0.5, 1.0, 0.0, 0.2])
    pos, psi = body_motion(q, np.array([-np.pi / 0.2]))  # half a turn back
    radius = 1.0 / 0.2
    centre = q[:2] + radius * np.array([-np.sin(0.5), np.cos(0.5)])
    assert np.linalg.norm(pos[0] - centre) == pytest.approx(radius)
    assert psi[0] == pytest.approx(0.5 - np.pi)


def test_lidar3d_range_image_and_points():
    cfg = LidarConfig(preset="vlp16", mount=[0.0, 0.0, 1.0, 0.0], motion=False, noise=False)
    lidar = Lidar3D(cfg, ROOM.scene, seed=0)
    cloud = sample(lidar, "lidar_points", np.zeros(6))
    assert cloud.range_image.shape == (16, 1800)
    # the level-most rings (±1°) see the walls; every point's range matches the image
    assert np.isfinite(cloud.range_image[7]).mean() > 0.9
    r = np.linalg.norm(cloud.points, axis=1)
    np.testing.assert_allclose(r, cloud.range_image[cloud.ring, cloud.column], atol=1e-9)
    # a point on the east wall (x = 10 m) from the +1° ring
    k = np.argmin(np.abs(cloud.azimuths))
    assert cloud.range_image[8, k] == pytest.approx(10.0 / np.cos(np.deg2rad(1.0)), abs=1e-6)
    # steep down rings hit the water within a few metres: no return
    assert not np.isfinite(cloud.range_image[0]).any()
    assert cloud.points.shape[0] == np.isfinite(cloud.range_image).sum()
    assert np.all(cloud.point_time >= 0) and np.all(cloud.point_time < cloud.sweep_time)


def test_presets_match_their_datasheets():
    vlp = LIDAR_PRESETS["vlp16"]
    assert vlp.columns == 1800 and len(vlp.elevations_deg) == 16 and vlp.range_max == 100.0
    assert min(vlp.elevations_deg) == -15.0 and max(vlp.elevations_deg) == 15.0
    hok = LIDAR_PRESETS["hokuyo_utm30lx"]
    assert hok.columns == 1081 and hok.rate_hz == 40.0 and hok.range_max == 30.0
    assert LIDAR_PRESETS["hokuyo_utm30lx_sim60"].range_max == 60.0
    rp = LIDAR_PRESETS["rplidar_a1"]
    assert rp.columns == 360 and rp.rate_hz == 5.5 and rp.range_max == 12.0
    with pytest.raises(KeyError, match="vlp16"):
        preset_by_name("vlp32")


def test_wrong_dimension_preset_is_rejected():
    with pytest.raises(ValueError, match="for Lidar3D"):
        Lidar2D(dataclasses.replace(LidarConfig(), preset="vlp16"), ROOM.scene, 0)
    with pytest.raises(ValueError, match="for Lidar2D"):
        Lidar3D(LidarConfig(preset="rplidar_a1"), ROOM.scene, 0)
