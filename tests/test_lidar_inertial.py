"""The lidar-IMU front end of the 3D SLAM (Roboat II §V): IMU propagation, gravity compensation,
de-skewing, sun glare, and the ``FactorGraphSlam`` system on the canal survey."""

import numpy as np
import pytest

from usvdrake.sensors.imu_model import STANDARD_GRAVITY, specific_force, yaw_quaternion
from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, body_motion, preset_by_name
from usvdrake.sensors.messages import ImuSample
from usvdrake.systems.slam.lidar_inertial import (
    ImuPropagator,
    level_rotation,
    planar_pose,
    pose_matrix,
)
from usvdrake.systems.slam.scan_registration3d import deskew, so3_exp
from usvdrake.worlds import make_world


def turning_samples(q0, seconds: float, rate: float):
    """Ideal IMU samples of a vessel on a steady turn (constant u, v, r), with the poses."""
    n = int(round(seconds * rate))
    t = np.arange(1, n + 1) / rate
    xy, psi = body_motion(np.asarray(q0, float), t)
    samples = []
    for tk, p in zip(t, psi, strict=True):
        q = np.r_[0.0, 0.0, p, q0[3:]]
        f = specific_force(q, np.zeros(3), STANDARD_GRAVITY)
        samples.append(
            ImuSample(
                time=tk,
                angular_velocity=np.array([0.0, 0.0, q0[5]]),
                linear_acceleration=f,
                orientation=yaw_quaternion(p),
            )
        )
    return samples, xy, psi


def test_imu_propagation_follows_a_steady_turn():
    q0 = np.array([3.0, -2.0, 0.4, 1.5, 0.1, 0.2])  # 1.5 m/s, turning at 0.2 rad/s
    samples, xy, psi = turning_samples(q0, 1.0, 200.0)
    imu = ImuPropagator()
    imu.reset(pose_matrix(3.0, -2.0, 0.0, 0.4), [1.5, 0.1, 0.0], 0.0)
    for s in samples:
        imu.add(s)
    end = planar_pose(imu.T)
    # exact arc: 1.5 m of travel; zero-order-hold integration at 200 Hz is within a few mm
    assert np.hypot(*(end[:2] - xy[-1])) < 5e-3
    assert abs(end[2] - psi[-1]) < 1e-9
    np.testing.assert_allclose(imu.v_body[:2], [1.5, 0.1], atol=5e-3)
    assert imu.T[2, 3] == 0.0 and imu.v[2] == 0.0  # a surface vessel does not heave
    # an older sample changes nothing
    before = imu.T.copy()
    imu.add(samples[10])
    np.testing.assert_array_equal(imu.T, before)
    # prediction beyond the last sample: constant rates
    ahead = planar_pose(imu.predict(1.1))
    assert np.hypot(*(ahead[:2] - end[:2])) == pytest.approx(0.1 * np.hypot(1.5, 0.1), rel=0.02)


def test_gravity_compensation_uses_the_ahrs_tilt_not_the_estimate():
    """A 2° roll error of the estimate must not become 0.34 m/s² of horizontal acceleration."""
    R_est = pose_matrix(0, 0, 0, 0.7)[:3, :3] @ so3_exp(np.array([np.deg2rad(2.0), 0.0, 0.0]))
    f = np.array([0.0, 0.0, STANDARD_GRAVITY])  # at rest, level
    a = level_rotation(R_est, yaw_quaternion(0.3)) @ f - [0, 0, STANDARD_GRAVITY]
    assert np.abs(a).max() < 1e-12
    naive = R_est @ f - [0, 0, STANDARD_GRAVITY]
    assert np.hypot(naive[0], naive[1]) > 0.3
    # and the estimate's yaw, not the AHRS's, turns a forward acceleration into the world
    a = level_rotation(R_est, yaw_quaternion(0.3)) @ np.array([1.0, 0.0, STANDARD_GRAVITY])
    assert np.arctan2(a[1], a[0]) == pytest.approx(0.7, abs=1e-9)


def test_deskew_moves_points_to_the_sweep_end():
    rng = np.random.default_rng(3)
    world_pts = rng.uniform(-20, 20, (200, 3))
    omega = np.array([0.0, 0.0, 0.3])  # [rad/s] sensor frame
    v = np.array([1.5, 0.2, 0.0])  # [m/s]
    age = rng.uniform(0.0, 0.1, 200)  # measured up to one 10 Hz sweep before the end
    T_end = pose_matrix(5.0, 1.0, 0.0, 0.2)
    measured, truth = [], []
    for P, a in zip(world_pts, age, strict=True):
        # sensor pose at the firing time: T_end · Exp(−a ξ) (constant body twist)
        T = np.eye(4)
        T[:3, :3] = so3_exp(-a * omega)
        T[:3, 3] = -a * v  # first order (the model deskew assumes; exact for ω ∥ v = 0)
        T_i = T_end @ T
        measured.append(np.linalg.solve(T_i, np.r_[P, 1.0])[:3])
        truth.append(np.linalg.solve(T_end, np.r_[P, 1.0])[:3])
    out = deskew(np.array(measured), age, omega, v)
    assert np.abs(out - np.array(truth)).max() < 2e-3
    raw_err = np.abs(np.array(measured) - np.array(truth)).max()
    assert raw_err > 0.1  # what de-skewing removed (up to 15 cm of travel + 1.7° of turn)


def test_sun_glare_false_returns_only_towards_the_sun():
    world = make_world("amsterdam_canals", 0)
    base = LidarConfig(preset="vlp16", mount=[0, 0, 1, 0], motion=False, noise=False)
    glare = LidarConfig(**{**base.__dict__, "glare_fraction": 1.0, "glare_azimuth_deg": 90.0})
    q = np.array([-216.5, -125.0, 0.0, 0.0, 0.0, 0.0])
    clear = LidarModel(preset_by_name("vlp16"), base, world.scene, 0, 30).sweep(q, 5)
    glared = LidarModel(preset_by_name("vlp16"), glare, world.scene, 0, 30).sweep(q, 5)
    changed = np.any(clear.ranges != glared.ranges, axis=0)
    az = LidarModel(preset_by_name("vlp16"), base, world.scene, 0, 30).layout.azimuths
    off = np.abs(np.angle(np.exp(1j * (az[changed] - np.pi / 2))))  # heading 0: sensor = world
    assert changed.sum() > 20 and np.all(off <= np.deg2rad(6.0) + 1e-9)
    false = glared.ranges[:, changed][clear.ranges[:, changed] != glared.ranges[:, changed]]
    assert np.all((false >= 0.5) & (false <= 30.0))
    # about 30 % of the sector's beams
    sector = np.abs(np.angle(np.exp(1j * (az - np.pi / 2)))) <= np.deg2rad(6.0)
    frac = np.mean(clear.ranges[:, sector] != glared.ranges[:, sector])
    assert 0.2 < frac < 0.4
    # glare_fraction 0.5: some sweeps clear, some not; the same k always the same
    half = LidarConfig(**{**glare.__dict__, "glare_fraction": 0.5})
    m = LidarModel(preset_by_name("vlp16"), half, world.scene, 0, 30)
    hit = [np.any(m.sweep(q, k).ranges != clear.ranges) for k in range(20)]
    assert 3 < sum(hit) < 17
    np.testing.assert_array_equal(m.sweep(q, 7).ranges, m.sweep(q, 7).ranges)


@pytest.fixture(scope="module")
def short_survey(tmp_path_factory):
    from usvdrake.diagrams import load_scenario, with_overrides
    from usvdrake.run.mission import run_mission

    scenario = with_overrides(load_scenario("canal_survey"), duration=25.0)
    return run_mission(scenario, out_dir=tmp_path_factory.mktemp("survey"), record=False)


def test_factor_graph_slam_tracks_the_start_of_the_canal_survey(short_survey):
    m = short_survey.metrics
    assert m["slam_keyframes"] >= 10  # ~1 m apart at 1.5 m/s after the start
    assert m["slam_sweeps"] == pytest.approx(250, abs=2)  # 10 Hz
    assert m["ate_m"] < 0.5 and m["ate_final_m"] < 0.5
    assert m["gps_factors"] >= 1
    assert 0 < m["keyframe_ms_median"] < 1000
    for key in ("loop_return_error_m", "vertical_error_max_m", "degenerate_segments"):
        assert key in m


def test_slam_outputs_are_logged(short_survey):
    from usvdrake.logs.mission_log import read_log_vectors

    t, pose, _ = read_log_vectors(short_survey.files["log"], "/slam_pose")
    truth_t, truth, _ = read_log_vectors(short_survey.files["log"], "/ground_truth")
    assert len(t) > 100
    i = np.searchsorted(truth_t, t[-1])
    assert np.hypot(pose[-1, 0] - truth[i, 0], pose[-1, 1] - truth[i, 1]) < 1.0


def test_controllers_fly_on_the_slam_estimate(short_survey):
    """canal_survey's estimator is the SLAM (Roboat II §V): the logged state estimate is its pose,
    not ground truth, and the boat still follows the canal."""
    from usvdrake.logs.mission_log import read_log_vectors

    log = short_survey.files["log"]
    t_e, est, _ = read_log_vectors(log, "/state_estimate")
    t_s, slam, _ = read_log_vectors(log, "/slam_pose")
    t_g, truth, _ = read_log_vectors(log, "/ground_truth")
    i = np.searchsorted(t_e, t_s[len(t_s) // 2 :])
    ok = i < len(t_e)
    common = np.isclose(t_e[np.minimum(i, len(t_e) - 1)], t_s[len(t_s) // 2 :]) & ok
    assert common.sum() > 50
    np.testing.assert_allclose(est[i[common], :2], slam[len(t_s) // 2 :][common, :2], atol=1e-9)
    j = np.minimum(np.searchsorted(t_g, t_e[i[common]]), len(t_g) - 1)
    assert np.abs(est[i[common], :2] - truth[j, :2]).max() > 1e-4  # not the oracle
    assert short_survey.metrics["cross_track_rmse_m"] < 1.0
