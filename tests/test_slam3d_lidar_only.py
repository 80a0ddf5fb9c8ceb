"""3D SLAM without an IMU (issue 38, item 4): the constant-twist prediction (KISS-ICP, Vizzo et
al. 2023) against closed forms, the sensors a run uses detected from the log or dropped by
flags, and lidar-only SLAM on a short recorded canal survey."""

import numpy as np
import pytest
from scipy.linalg import expm

import usvdrake.run.slam3d as slam3d_module
from usvdrake.cli import main
from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.diagrams.slam import settings_from_scenario
from usvdrake.logs.sensor_stream import SensorMessage
from usvdrake.run.mission import run_mission
from usvdrake.run.slam3d import _peek, run_slam3d, sensor_mode, variant_config
from usvdrake.systems.slam.lidar_inertial import (
    ConstantTwistPredictor,
    hold_vertical,
    planar_pose,
    pose_matrix,
    twist_between,
)
from usvdrake.systems.slam.scan_registration3d import so3_exp


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """exp of the se(3) matrix of ξ = (ω, v) by scipy's matrix exponential (independent of
    gtsam's closed form)."""
    w, v = xi[:3], xi[3:]
    A = np.zeros((4, 4))
    A[:3, :3] = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]]
    A[:3, 3] = v
    return expm(A)


def tilted_pose() -> np.ndarray:
    T = pose_matrix(10.0, -4.0, 0.3, 1.1)
    T[:3, :3] = T[:3, :3] @ so3_exp(np.array([0.02, -0.03, 0.0]))
    return T


def test_twist_between_inverts_constant_twist_motion():
    xi = np.array([0.01, -0.02, 0.35, 1.5, 0.1, 0.04])  # a turning, slightly tilting hull
    T0 = tilted_pose()
    for dt in (0.1, 0.7):
        T1 = T0 @ se3_exp(xi * dt)
        np.testing.assert_allclose(twist_between(T0, T1, dt), xi, atol=1e-9)
    assert not np.any(twist_between(T0, T0, 0.0))  # no time: no twist


def test_constant_twist_predictor_extrapolates_along_the_twist():
    xi = np.array([0.01, -0.02, 0.35, 1.5, 0.1, 0.04])
    T0 = tilted_pose()
    p = ConstantTwistPredictor(surface=False)
    p.reset(T0, xi, 2.0)
    np.testing.assert_allclose(p.predict(2.4), T0 @ se3_exp(0.4 * xi), atol=1e-12)
    np.testing.assert_array_equal(p.omega, xi[:3])
    np.testing.assert_array_equal(p.v_body, xi[3:])
    assert p.up is None  # no gravity measured
    p.advance(2.3)
    p.advance(2.1)  # an older time does not go back
    np.testing.assert_allclose(p.T, T0 @ se3_exp(0.3 * xi), atol=1e-12)
    np.testing.assert_allclose(p.v, p.T[:3, :3] @ xi[3:], atol=1e-12)


def test_surface_vessel_twist_neither_climbs_nor_tilts():
    """A hull's twist keeps only the yaw rate and the horizontal velocity (world frame): the
    prediction holds the height and the tilt of the start and still turns and moves."""
    xi = np.array([0.05, -0.04, 0.3, 1.5, 0.2, 0.3])
    T0 = tilted_pose()
    p = ConstantTwistPredictor(surface=True)
    p.reset(T0, xi, 0.0)
    T1 = p.predict(1.0)
    assert T1[2, 3] == pytest.approx(T0[2, 3], abs=1e-12)
    np.testing.assert_allclose(T1[2, :3], T0[2, :3], atol=1e-12)  # the body axes' heights: tilt
    w_world = T0[:3, :3] @ p.omega
    np.testing.assert_allclose(w_world[:2], 0.0, atol=1e-15)
    assert w_world[2] == pytest.approx((T0[:3, :3] @ xi[:3])[2])
    assert np.linalg.norm(T1[:2, 3] - T0[:2, 3]) > 1.0  # it still moves


def test_hold_vertical_takes_plane_motion_and_keeps_height_and_tilt():
    T_ref = tilted_pose()
    T = pose_matrix(12.0, -3.0, 0.9, 1.4)  # moved, turned, and a wrong height, level
    T[:3, :3] = T[:3, :3] @ so3_exp(np.array([-0.05, 0.04, 0.0]))
    H = hold_vertical(T, T_ref)
    np.testing.assert_allclose(planar_pose(H), planar_pose(T), atol=1e-12)
    assert H[2, 3] == T_ref[2, 3]
    np.testing.assert_allclose(H[2, :3], T_ref[2, :3], atol=1e-12)  # same tilt as T_ref
    np.testing.assert_allclose(H[:3, :3] @ H[:3, :3].T, np.eye(3), atol=1e-12)


def test_sensor_mode_names_the_sensors():
    assert sensor_mode(False, False, False) == "lidar only"
    assert sensor_mode(True, False, False) == "lidar + IMU"
    assert sensor_mode(True, True, False) == "lidar + IMU + GPS"
    assert sensor_mode(True, True, True) == "lidar + IMU + GPS + loops"
    assert sensor_mode(False, True, True) == "lidar + GPS + loops"


def test_peek_reads_past_the_first_sweep_and_loses_nothing():
    stream = [SensorMessage(0.1 * i, "gps" if i % 3 else "lidar", i) for i in range(40)]
    head, rest = _peek(iter(stream), horizon=1.0)
    assert head[-1].time > head[0].time + 1.0 and len(head) < len(stream)
    assert [m.msg for m in rest] == list(range(40))


@pytest.fixture(scope="module")
def survey(tmp_path_factory):
    """12 s of the canal survey with its VLP-16, IMU and GPS recorded in log.mcap."""
    scenario = with_overrides(load_scenario("canal_survey"), duration=12.0)
    result = run_mission(scenario, out_dir=tmp_path_factory.mktemp("survey"), record=False)
    config, mount, datum = settings_from_scenario(scenario)
    return result.files["log"], config, mount, datum


@pytest.fixture(scope="module")
def lidar_only(survey):
    log, config, mount, datum = survey
    return run_slam3d(log, variant_config(config, False, False), mount=mount, use_imu=False)


def test_lidar_only_leaves_the_start_and_tracks_the_survey(lidar_only):
    """The issue's failure: without the IMU the SLAM never left its start pose (one keyframe,
    the whole path as error). With the constant twist it follows the boat (~15 m in 12 s)."""
    m = lidar_only.metrics
    assert m["mode"] == "lidar only" and not m["imu_used"]
    assert m["imu_messages"] > 0  # in the log, withheld
    assert m["slam_keyframes"] >= 8
    assert m["ate_m"] < 0.15  # online planar error, unaligned
    assert m["ate_final_m"] < 0.15
    assert m["vertical_error_max_m"] < 0.3  # water level + level hull
    assert lidar_only.slam.lidar_only and len(lidar_only.slam.tracking_ms) == m["slam_sweeps"]


def test_a_log_without_imu_is_detected(survey, monkeypatch):
    log, config, mount, datum = survey
    read = slam3d_module.read_sensor_stream

    def no_imu(*args, **kwargs):
        return (m for m in read(*args, **kwargs) if m.kind != "imu")

    monkeypatch.setattr(slam3d_module, "read_sensor_stream", no_imu)
    r = run_slam3d(log, config, mount=mount, datum=datum)
    assert r.metrics["mode"] == "lidar + GPS + loops" and not r.metrics["imu_used"]
    assert r.metrics["imu_messages"] == 0 and r.metrics["slam_keyframes"] >= 8


def test_imu_and_gps_are_used_when_there(survey):
    log, config, mount, datum = survey
    r = run_slam3d(log, config, mount=mount, datum=datum)
    assert r.metrics["mode"] == "lidar + IMU + GPS + loops" and r.metrics["imu_used"]
    assert not r.slam.lidar_only


def test_cli_summary_says_lidar_only(survey, capsys):
    log = survey[0]
    argv = ["slam3d", str(log), "--scenario", "canal_survey", "--no-imu", "--no-gps", "--quiet"]
    assert main(argv) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert "lidar only + loops" in first and "keyframes" in first
