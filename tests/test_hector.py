"""Hector SLAM (Kohlbrecher et al. 2011; Ueland 2017) in the NTNU basin with synthetic RPLIDAR
scans: map interpolation against finite differences, the matcher against a known offset, and the
whole SLAM loop against the true path, noise-free and with the RPLIDAR's 1 % range noise."""

import numpy as np
import pytest
import shapely

from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, body_motion, preset_by_name
from usvdrake.systems.slam.hector import HectorMapper, interpolate_map
from usvdrake.worlds import make_world

RES = 0.05  # [m] finest map cell
RATE = 5.5  # [Hz] RPLIDAR A1 scan rate (Ueland 2017)
MAX_RANGE = 12.0  # [m] RPLIDAR A1
# The basin's walls lie on multiples of 0.05 m. With an origin on that lattice they would run
# along cell boundaries, where the map's cell-centred values put them half a cell off (a bias
# test_grid_aligned_walls_bias_is_below_a_cell measures); half a cell more puts them mid-cell.
ORIGIN = (-2.0 - RES / 2, -1.0 - RES / 2)  # [m]
SIZE = (44.0, 8.5)  # [m] the basin with its beach and walls


@pytest.fixture(scope="module")
def world():
    return make_world("ntnu_basin")


def lidar(world, noise: bool, stream: int = 3) -> tuple[LidarModel, np.ndarray]:
    cfg = LidarConfig(preset="rplidar_a1", mount=[0.0, 0.0, 0.25, 0.0], motion=False, noise=noise)
    model = LidarModel(preset_by_name("rplidar_a1"), cfg, world.scene, 0, stream)
    angles = model.layout.az0 + model.layout.daz * np.arange(model.layout.count)
    return model, angles


def s_curve(n: int = 60, u: float = 0.2) -> np.ndarray:
    """n states [x y ψ u v r] 1/RATE apart: 0.2 m/s (0.036 m per scan) from the basin's start
    point with a yaw rate swinging ±0.25 rad/s (up to 2.6° per scan)."""
    dt = 1.0 / RATE
    q = np.array([1.5, 3.2, 0.0, u, 0.0, 0.0])
    states = []
    for k in range(n):
        q[5] = 0.25 * np.sin(2.0 * np.pi * k * dt / 8.0)
        states.append(q.copy())
        xy, psi = body_motion(q, np.array([dt]))
        q[:3] = xy[0, 0], xy[0, 1], psi[0]
    return np.array(states)


def run_slam(world, noise: bool, **kwargs) -> np.ndarray:
    """Errors (n × 3: x [m], y [m], ψ [rad]) of HectorMapper along s_curve()."""
    states = s_curve()
    model, angles = lidar(world, noise)
    slam = HectorMapper(ORIGIN, SIZE, RES, levels=3, initial_pose=states[0, :3], **kwargs)
    errors = []
    for k, q in enumerate(states):
        pose = slam.update(model.sweep(q, k).ranges[0], angles, MAX_RANGE)
        d = pose - q[:3]
        d[2] = (d[2] + np.pi) % (2.0 * np.pi) - np.pi
        errors.append(d)
    cov = slam.covariance
    assert np.allclose(cov, cov.T) and np.all(np.linalg.eigvalsh(cov) > 0.0)
    return np.array(errors)


def test_path_is_in_open_water(world):
    path = shapely.LineString(s_curve()[:, :2])
    walls = shapely.union_all([shapely.Polygon(s.footprint()) for s in world.solids])
    assert path.distance(walls) > 0.5


def test_interpolation_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    prob = rng.uniform(0.1, 0.95, (20, 30))
    origin, res = (-1.3, 0.4), 0.1
    # Cell centres return the cell values exactly (eq. 1 at the interpolation nodes).
    rows, cols = np.array([3, 7, 12]), np.array([5, 2, 20])
    centres = np.column_stack([origin[0] + (cols + 0.5) * res, origin[1] + (rows + 0.5) * res])
    m, _, inside = interpolate_map(prob, origin, res, centres)
    assert inside.all() and np.allclose(m, prob[rows, cols])
    # Gradient (eqs. 2-3) against central differences, away from the interpolant's kinks.
    xy = origin + rng.uniform([0.1, 0.1], [2.8, 1.8], (200, 2))
    frac = ((xy - origin) / res - 0.5) % 1.0
    xy = xy[np.all((frac > 0.01) & (frac < 0.99), axis=1)]
    m, grad, inside = interpolate_map(prob, origin, res, xy)
    assert inside.all()
    h = 1e-6
    for axis in range(2):
        e = np.zeros(2)
        e[axis] = h
        m_plus = interpolate_map(prob, origin, res, xy + e)[0]
        m_minus = interpolate_map(prob, origin, res, xy - e)[0]
        np.testing.assert_allclose(grad[:, axis], (m_plus - m_minus) / (2 * h), atol=1e-6)
    # Outside the grid: unknown, flat.
    m, grad, inside = interpolate_map(prob, origin, res, np.array([[-5.0, 0.0], [1.68, 2.4]]))
    assert not inside.any() and np.all(m == 0.5) and np.all(grad == 0.0)


def test_matcher_recovers_known_offset(world):
    q = s_curve()[0]
    model, angles = lidar(world, noise=False)
    ranges = model.sweep(q, 0).ranges[0]
    slam = HectorMapper(ORIGIN, SIZE, RES, levels=3, initial_pose=q[:3])
    slam.update(ranges, angles, MAX_RANGE)  # the first scan builds the map at the true pose
    hit = np.isfinite(ranges)
    points = np.column_stack([ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])])
    for offset in ([0.1, 0.0, 0.0], [0.07, -0.07, np.deg2rad(3.0)], [-0.05, 0.1, -np.deg2rad(3)]):
        pose, hessian = slam.match(points, q[:3] + offset)
        assert np.hypot(*(pose[:2] - q[:2])) < 0.01  # measured 6 mm (the beach's quantisation)
        assert abs(pose[2] - q[2]) < np.deg2rad(0.3)  # measured < 0.02°
        assert np.all(np.linalg.eigvalsh(hessian) > 0.0)


def test_grid_aligned_walls_bias_is_below_a_cell(world):
    """Walls on cell boundaries shift the map by up to half a cell per axis (cell values sit at
    cell centres); the matcher then follows the map."""
    q = s_curve()[0]
    model, angles = lidar(world, noise=False)
    ranges = model.sweep(q, 0).ranges[0]
    slam = HectorMapper((-2.0, -1.0), SIZE, RES, levels=3, initial_pose=q[:3])
    slam.update(ranges, angles, MAX_RANGE)
    hit = np.isfinite(ranges)
    points = np.column_stack([ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])])
    pose, _ = slam.match(points, q[:3] + [0.05, -0.05, 0.02])
    assert np.all(np.abs(pose[:2] - q[:2]) < 0.6 * RES)  # measured (−0.018, 0.025) m


def test_first_scan_is_inserted_at_the_initial_pose(world):
    q = s_curve()[0]
    model, angles = lidar(world, noise=False)
    slam = HectorMapper(ORIGIN, SIZE, RES, levels=3, initial_pose=q[:3])
    pose = slam.update(model.sweep(q, 0).ranges[0], angles, MAX_RANGE)
    np.testing.assert_array_equal(pose, q[:3])
    assert np.isinf(slam.covariance).all()
    for level, grid in enumerate(slam.grids):
        assert grid.resolution == pytest.approx(RES * 2**level)
        assert (slam.probability(level) > 0.6).sum() > 50  # walls seen on every level


def test_slam_noise_free(world):
    e = run_slam(world, noise=False)
    assert np.hypot(*e[-1, :2]) < 0.03  # measured 0.008 m
    assert abs(e[-1, 2]) < np.deg2rad(0.3)  # measured 0.01°
    assert np.hypot(e[:, 0], e[:, 1]).max() < 0.03  # measured 0.010 m


def test_slam_with_rplidar_noise(world):
    e = run_slam(world, noise=True)
    assert np.hypot(*e[-1, :2]) < 0.10  # measured 0.068 m
    assert abs(e[-1, 2]) < np.deg2rad(2.0)  # measured 1.14°
    assert np.hypot(e[:, 0], e[:, 1]).max() < 0.15  # measured 0.076 m


def test_map_update_thresholds_limit_drift(world):
    """Hector's ROS node inserts a scan only after 0.4 m or 0.9 rad of motion; matching against
    an unchanged map does not accumulate the per-scan errors."""
    e = run_slam(world, noise=True, map_update_distance=0.4, map_update_angle=0.9)
    assert np.hypot(*e[-1, :2]) < 0.05  # measured 0.021 m
    assert abs(e[-1, 2]) < np.deg2rad(0.6)  # measured 0.30°
