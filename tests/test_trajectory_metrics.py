"""ATE / RPE / relation error against closed forms and, when installed, against evo."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from usvdrake.analysis import trajectory_metrics as tm


def _random_trajectory(rng: np.random.Generator, n: int = 200) -> tm.Trajectory:
    """A smooth-ish 3D trajectory: random-walk positions and orientations, 10 Hz."""
    xyz = np.cumsum(rng.normal(0.0, 0.5, (n, 3)), axis=0)
    rotvec = np.cumsum(rng.normal(0.0, 0.05, (n, 3)), axis=0)
    quat = Rotation.from_rotvec(rotvec).as_quat()
    return tm.trajectory_from_tum(np.arange(n) * 0.1, xyz, quat)


def _planar(rng: np.random.Generator, n: int = 200) -> np.ndarray:
    """Random-walk planar poses (n × 3: x, y, ψ)."""
    return np.column_stack(
        [np.cumsum(rng.normal(0.0, 0.5, (n, 2)), axis=0), np.cumsum(rng.normal(0.0, 0.1, n))]
    )


def _move(traj: tm.Trajectory, T: np.ndarray) -> tm.Trajectory:
    """Every pose premultiplied by the rigid transform T (the whole trajectory moved)."""
    return tm.Trajectory(traj.t, T @ traj.poses)


def _noisy(rng: np.random.Generator, traj: tm.Trajectory, sigma: float) -> tm.Trajectory:
    """Poses perturbed by Gaussian position [m] and rotation-vector [rad] noise."""
    poses = traj.poses.copy()
    dR = Rotation.from_rotvec(rng.normal(0.0, sigma, (len(poses), 3))).as_matrix()
    poses[:, :3, :3] = poses[:, :3, :3] @ dR
    poses[:, :3, 3] += rng.normal(0.0, sigma, (len(poses), 3))
    return tm.Trajectory(traj.t, poses)


@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("with_scale", [False, True])
def test_umeyama_recovers_random_similarity(d, with_scale):
    rng = np.random.default_rng(1)
    R = Rotation.random(random_state=2).as_matrix()
    if d == 2:
        a = 0.7
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
    t = rng.normal(0.0, 10.0, d)
    s = 1.3 if with_scale else 1.0
    a_pts = rng.normal(0.0, 5.0, (50, d))
    b_pts = s * a_pts @ R.T + t
    R_hat, t_hat, s_hat = tm.umeyama(a_pts, b_pts, with_scale)
    np.testing.assert_allclose(R_hat, R, atol=1e-12)
    np.testing.assert_allclose(t_hat, t, atol=1e-12)
    assert s_hat == pytest.approx(s, abs=1e-12)
    assert np.linalg.det(R_hat) == pytest.approx(1.0, abs=1e-12)


def test_umeyama_never_returns_a_reflection():
    rng = np.random.default_rng(3)
    a = rng.normal(size=(30, 3))
    b = a * np.array([1.0, 1.0, -1.0])  # mirrored: best proper rotation is not the mirror
    R, _, _ = tm.umeyama(a, b)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_ate_of_a_moved_copy_is_zero_after_alignment_and_the_offset_without():
    rng = np.random.default_rng(4)
    ref = _random_trajectory(rng)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 1.0]).as_matrix()
    T[:3, 3] = [5.0, -3.0, 2.0]
    assert tm.ate(_move(ref, T), ref, align="se3")["ate_max_m"] < 1e-9
    offset = np.eye(4)
    offset[:3, 3] = [3.0, 4.0, 12.0]  # |d| = 13 m
    r = tm.ate(_move(ref, offset), ref, align="none")
    for key in ("ate_rmse_m", "ate_mean_m", "ate_median_m", "ate_max_m"):
        assert r[key] == pytest.approx(13.0, abs=1e-9)
    assert r["ate_std_m"] == pytest.approx(0.0, abs=1e-9)
    assert r["ate_pairs"] == len(ref.t)


def test_planar_ate_with_se2_alignment():
    rng = np.random.default_rng(5)
    p = _planar(rng)
    t = np.arange(len(p)) * 0.1
    moved = tm.se3_to_planar(tm.planar_to_se3([[10.0, -4.0, 2.0]]) @ tm.planar_to_se3(p))
    assert tm.ate((t, moved), (t, p), align="se2")["ate_rmse_m"] < 1e-9
    # scaled: only Sim(2) alignment removes it, and reports the scale
    r = tm.ate((t, moved * [2.0, 2.0, 1.0]), (t, p), align="se2", with_scale=True)
    assert r["ate_rmse_m"] < 1e-9
    assert r["ate_scale"] == pytest.approx(0.5)


def test_ate_errors_locate_a_bent_stretch_and_plot_it(tmp_path):
    """Pose by pose: a moved copy whose poses 50-59 are pushed 1 m sideways shows its error
    there and nowhere else much (the alignment shares it out), the RMSE is ``ate``'s; the
    plot is a PNG and refuses errors that do not fit the poses."""
    rng = np.random.default_rng(7)
    p = _planar(rng)
    t = np.arange(len(p)) * 0.1
    moved = tm.se3_to_planar(tm.planar_to_se3([[3.0, 1.0, 0.5]]) @ tm.planar_to_se3(p))
    moved[50:60, 1] += 1.0
    aligned, ref, e, s = tm.ate_errors((t, moved), (t, p), align="se2")
    assert s == 1.0 and len(e) == len(p) == len(aligned.t) == len(ref.t)
    assert e[50:60].min() > 0.8 and np.delete(e, range(50, 60)).max() < 0.2
    assert np.sqrt(np.mean(e**2)) == pytest.approx(tm.ate((t, moved), (t, p))["ate_rmse_m"])
    png = tm.plot_ate(aligned, ref, e, tmp_path / "ate.png", title="bent")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(ValueError, match="200 estimated and 200 reference poses, 3 errors"):
        tm.plot_ate(aligned, ref, e[:3], tmp_path / "bad.png")


def test_rpe_of_a_rigidly_moved_copy_is_zero():
    rng = np.random.default_rng(6)
    ref = _random_trajectory(rng)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([1.0, 0.5, -2.0]).as_matrix()
    T[:3, 3] = [100.0, 20.0, -5.0]
    for delta, unit in [(1, "frames"), (7, "frames"), (2.0, "seconds"), (5.0, "meters")]:
        r = tm.rpe(_move(ref, T), ref, delta, unit)
        assert r["rpe_trans_max_m"] < 1e-9
        assert r["rpe_rot_max_rad"] < 1e-7
        assert r["rpe_pairs"] > 0


def test_one_percent_scale_drift_gives_one_centimetre_per_metre():
    x = np.arange(101.0)  # 1 m apart along x
    ref = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    est = ref * [1.01, 1.0, 1.0]
    r = tm.rpe(est, ref, 10.0, unit="meters", rel_tol=0.01)
    assert r["rpe_pairs"] == 91  # i = 0 … 90
    assert r["rpe_trans_rmse_m"] / 10.0 == pytest.approx(0.01, abs=1e-12)
    assert r["rpe_trans_max_m"] == pytest.approx(0.1, abs=1e-12)
    assert r["rpe_rot_rmse_rad"] == 0.0
    assert tm.rpe(est, ref, 10, unit="frames")["rpe_trans_mean_m"] == pytest.approx(0.1)
    # the default 10 % tolerance (evo's) also pairs i = 91 with the end, 9 m on
    assert tm.rpe(est, ref, 10.0, unit="meters")["rpe_pairs"] == 92


def test_scale_drift_on_a_circle_gives_one_percent_of_the_chord():
    # a uniform scale error leaves headings alone, so E_i is a pure translation of 1 % of the
    # chord 2 r sin(kθ/2) between poses k steps apart
    r_c, theta, k = 20.0, 0.05, 9
    a = np.arange(300) * theta
    ref = np.column_stack([r_c * np.sin(a), r_c * (1 - np.cos(a)), a])
    est = ref * [1.01, 1.01, 1.0]
    out = tm.rpe(est, ref, k, unit="frames")
    chord = 2 * r_c * np.sin(k * theta / 2)
    assert out["rpe_trans_rmse_m"] == pytest.approx(0.01 * chord, rel=1e-10)
    assert out["rpe_rot_max_rad"] < 1e-9


def test_rpe_rotation_of_a_constant_yaw_rate_error():
    n = 50
    ref = np.column_stack([np.arange(n, dtype=float), np.zeros(n), np.zeros(n)])
    est = ref.copy()
    est[:, 2] = 0.01 * np.arange(n)  # heading drifts 0.01 rad per frame, positions exact
    r = tm.rpe(est, ref, 5)
    assert r["rpe_rot_rmse_rad"] == pytest.approx(0.05, abs=1e-12)


def test_tum_round_trip(tmp_path):
    rng = np.random.default_rng(7)
    t = 1.3e9 + np.cumsum(rng.uniform(0.01, 0.05, 40))
    xyz = rng.normal(0.0, 100.0, (40, 3))
    quat = Rotation.random(40, random_state=8).as_quat()
    path = tmp_path / "traj.tum"
    tm.write_tum(path, t, xyz, quat)
    assert path.read_text().startswith("# t x y z qx qy qz qw\n")
    t2, xyz2, quat2 = tm.read_tum(path)
    np.testing.assert_allclose(t2, t, rtol=0, atol=1e-6)  # 1e9 s at double precision
    np.testing.assert_allclose(xyz2, xyz, rtol=0, atol=1e-9)
    np.testing.assert_allclose(quat2, quat, rtol=0, atol=1e-9)
    traj = tm.read_trajectory(path)
    xyz3, quat3 = tm.xyz_quat_from_se3(traj.poses)
    np.testing.assert_allclose(xyz3, xyz, atol=1e-9)
    np.testing.assert_allclose(np.abs(np.sum(quat3 * quat, axis=1)), 1.0, atol=1e-9)


def test_read_tum_as_mission_writes_it(tmp_path):
    # mission._write_tum: yaw-only quaternions, "%.6f", a "# t x y z qx qy qz qw" header
    psi = np.array([0.0, 0.5, -2.0])
    rows = np.column_stack(
        [[0.0, 0.1, 0.2], [1.0, 2.0, 3.0], [0.0, -1.0, 4.0], np.zeros((3, 3)), np.sin(psi / 2)]
    )
    rows = np.column_stack([rows, np.cos(psi / 2)])
    path = tmp_path / "ground_truth.tum"
    np.savetxt(path, rows, fmt="%.6f", header="t x y z qx qy qz qw")
    planar = tm.se3_to_planar(tm.read_trajectory(path).poses)
    np.testing.assert_allclose(
        planar, [[1.0, 0.0, 0.0], [2.0, -1.0, 0.5], [3.0, 4.0, -2.0]], atol=2e-6
    )


def test_associate_jittered_timestamps():
    rng = np.random.default_rng(9)
    t_a = np.arange(0.0, 10.0, 0.1)
    keep = np.sort(rng.choice(len(t_a), 80, replace=False))  # b misses 20 stamps
    t_b = t_a[keep] + rng.uniform(-0.005, 0.005, len(keep))
    shuffle = rng.permutation(len(t_b))
    ia, ib = tm.associate(t_a, t_b[shuffle], max_dt=0.02)
    np.testing.assert_array_equal(ia, keep)
    np.testing.assert_array_equal(keep[shuffle[ib]], ia)  # each b back with its own a
    np.testing.assert_allclose(t_b[shuffle][ib], t_a[ia], atol=0.005)


def test_associate_is_one_to_one_and_prefers_the_nearest():
    # two a stamps compete for b = 1.0; the nearer (1.004) wins, the other matches 1.03
    ia, ib = tm.associate([1.0, 1.011], [1.004, 1.03, 5.0], max_dt=0.02)
    np.testing.assert_array_equal(ia, [0, 1])
    np.testing.assert_array_equal(ib, [0, 1])
    ia, ib = tm.associate([1.0, 1.011], [1.004], max_dt=0.02)
    np.testing.assert_array_equal(ia, [0])
    assert len(tm.associate([0.0], [1.0], max_dt=0.5)[0]) == 0


def test_nearest_index_unsorted():
    t = np.array([3.0, 1.0, 2.0, 1.5])  # CARMEN stamps can step back
    np.testing.assert_array_equal(
        tm.nearest_index(t, [0.0, 1.01, 1.6, 1.85, 2.9, 9.0], 0.2), [-1, 1, 3, 2, 0, -1]
    )


def test_relation_error_on_hand_made_relations(tmp_path):
    t = np.array([10.0, 11.0, 12.0, 13.0])
    est = (t, np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0], [3.0, 0.0, 0.0]]))
    path = tmp_path / "log.relations"
    path.write_text(
        "# t1 t2 x y z roll pitch yaw\n"
        "10.0 11.0 1.0 0.0 0.0 0.0 0.0 0.0\n"  # exact: error 0
        "11.0 13.0 2.1 0.0 0.0 0.0 0.0 0.1\n"  # δ*⁻¹δ: translation R(−0.1)(−0.1, 0), |.| = 0.1
        "\n"
        "12.0 99.0 1.0 0.0 0.0 0.0 0.0 0.0\n"  # no estimated pose at 99 s
    )
    rel = tm.read_relations(path)
    assert len(rel.t1) == 3
    r = tm.relation_error(est, rel)
    assert r["rel_relations"] == 2
    assert r["rel_unmatched"] == 1
    assert r["rel_trans_mean_m"] == pytest.approx(0.05, abs=1e-12)
    assert r["rel_trans_std_m"] == pytest.approx(0.05, abs=1e-12)
    assert r["rel_trans_sq_mean_m2"] == pytest.approx(0.005, abs=1e-12)
    assert r["rel_trans_max_m"] == pytest.approx(0.1, abs=1e-12)
    assert r["rel_rot_mean_rad"] == pytest.approx(0.05, abs=1e-12)
    assert r["rel_rot_max_rad"] == pytest.approx(0.1, abs=1e-12)
    assert r["rel_epsilon"] == pytest.approx(0.01, abs=1e-12)


def test_relations_of_the_truth_give_zero_and_rpy_convention():
    rng = np.random.default_rng(10)
    ref = _random_trajectory(rng, 30)
    i, j = np.arange(0, 25), np.arange(5, 30)
    delta = tm.relative_poses(ref.poses[i], ref.poses[j])
    # as a relations file stores them: x y z and roll pitch yaw with R = Rz Ry Rx
    ypr = Rotation.from_matrix(delta[:, :3, :3]).as_euler("ZYX")
    rebuilt = tm.se3_from_xyz_rpy(delta[:, :3, 3], ypr[:, ::-1])
    np.testing.assert_allclose(rebuilt, delta, atol=1e-12)
    r = tm.relation_error(ref, tm.Relations(ref.t[i], ref.t[j], rebuilt))
    assert r["rel_trans_max_m"] < 1e-9
    assert r["rel_rot_max_rad"] < 1e-7


def test_planar_helpers_round_trip():
    p = np.array([[1.0, 2.0, 0.3], [-4.0, 0.5, -3.0], [0.0, 0.0, np.pi - 1e-9]])
    np.testing.assert_allclose(tm.se3_to_planar(tm.planar_to_se3(p)), p, atol=1e-12)
    T = tm.planar_to_se3(p)
    np.testing.assert_allclose(tm.se3_inverse(T) @ T, np.tile(np.eye(4), (3, 1, 1)), atol=1e-12)
    np.testing.assert_allclose(tm.rotation_angle(T[:, :3, :3]), np.abs(p[:, 2]), atol=1e-9)


# --- cross-check against evo (not a dependency: skipped unless installed) --------------------


def _evo(traj: tm.Trajectory):
    from evo.core.trajectory import PoseTrajectory3D

    return PoseTrajectory3D(poses_se3=list(traj.poses), timestamps=traj.t)


@pytest.fixture
def ref_and_est():
    rng = np.random.default_rng(11)
    ref = _random_trajectory(rng, 300)
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.1, -0.2, 0.8]).as_matrix()
    T[:3, 3] = [2.0, -1.0, 0.5]
    return ref, _move(_noisy(rng, ref, 0.05), T)


def test_ate_agrees_with_evo(ref_and_est):
    pytest.importorskip("evo")
    from evo.core import metrics

    ref, est = ref_and_est
    for with_scale in (False, True):
        e = _evo(est)
        e.align(_evo(ref), correct_scale=with_scale)
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data((_evo(ref), e))
        stats = ape.get_all_statistics()
        ours = tm.ate(est, ref, align="se3", with_scale=with_scale)
        for key in ("rmse", "mean", "median", "std", "max"):
            assert ours[f"ate_{key}_m"] == pytest.approx(stats[key], abs=1e-12)


@pytest.mark.parametrize(
    "delta, unit", [(1, "frames"), (10, "frames"), (5.0, "meters"), (20.0, "meters")]
)
def test_rpe_agrees_with_evo(ref_and_est, delta, unit):
    pytest.importorskip("evo")
    from evo.core import metrics

    ref, est = ref_and_est
    ours = tm.rpe(est, ref, delta, unit)
    for relation, key in [
        (metrics.PoseRelation.translation_part, "rpe_trans_{}_m"),
        (metrics.PoseRelation.rotation_angle_rad, "rpe_rot_{}_rad"),
    ]:
        m = metrics.RPE(
            relation,
            delta=delta,
            delta_unit=metrics.Unit.frames if unit == "frames" else metrics.Unit.meters,
            rel_delta_tol=0.1,
            all_pairs=True,
            pairs_from_reference=True,
        )
        m.process_data((_evo(ref), _evo(est)))
        stats = m.get_all_statistics()
        assert len(m.error) == ours["rpe_pairs"]
        for stat in ("rmse", "mean", "max"):
            assert ours[key.format(stat)] == pytest.approx(stats[stat], abs=1e-12)


def test_planar_se2_ate_agrees_with_evo_se3():
    # on planar data a small-error estimate's best 3D alignment is the planar one
    pytest.importorskip("evo")
    from evo.core import metrics

    rng = np.random.default_rng(12)
    p = _planar(rng)
    t = np.arange(len(p)) * 0.1
    noisy = p + rng.normal(0.0, 0.05, p.shape)
    moved = tm.se3_to_planar(tm.planar_to_se3([[10.0, -4.0, 2.0]]) @ tm.planar_to_se3(noisy))
    est, ref = tm.trajectory_from_planar(t, moved), tm.trajectory_from_planar(t, p)
    e = _evo(est)
    e.align(_evo(ref))
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((_evo(ref), e))
    assert tm.ate(est, ref, align="se2")["ate_rmse_m"] == pytest.approx(
        ape.get_all_statistics()["rmse"], abs=1e-6
    )


def test_pairs_by_distance_search_matches_the_direct_minimum():
    # the searchsorted path against the argmin over every later pose, with stationary stretches
    rng = np.random.default_rng(13)
    steps = rng.uniform(0.0, 1.0, 300) * (rng.uniform(size=300) > 0.3)
    along = np.concatenate([[0.0], np.cumsum(np.round(steps, 1))])
    for delta in (0.5, 3.0, 10.0, 500.0):
        direct = [
            i + 1 + int(np.argmin(np.abs(along[i + 1 :] - along[i] - delta)))
            for i in range(len(along) - 1)
        ]
        np.testing.assert_array_equal(tm._nearest_ahead(along, delta), direct)
