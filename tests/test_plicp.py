"""PLICP (Censi 2008) and its closed-form covariance (Censi 2007) on synthetic scans."""

import numpy as np
from scipy.optimize import least_squares

from usvdrake.systems.slam.censi_covariance import plicp_covariance, plicp_hessians
from usvdrake.systems.slam.plicp import line_normals, plicp, rot, solve_point_to_line
from usvdrake.worlds import box
from usvdrake.worlds.raycast import Scene, cast
from usvdrake.worlds.synthetic import HOKUYO, cluttered_room


def corridor() -> Scene:
    """50 m × 4 m with end walls: along x only the distant ends constrain a match."""
    return Scene.from_solids(
        [
            box("wall", 0, 2, 50, 0.2, 0, -1, 3),
            box("wall", 0, -2, 50, 0.2, 0, -1, 3),
            box("wall", 25, 0, 0.2, 4, 0, -1, 3),
            box("wall", -25, 0, 0.2, 4, 0, -1, 3),
        ]
    )


def ranges(scene: Scene, pose) -> np.ndarray:
    return cast(scene, HOKUYO, [0.0], np.array(pose[:2]), 1.0, pose[2], 30.0)[0]


def to_points(r: np.ndarray) -> np.ndarray:
    ok = np.isfinite(r)
    a = HOKUYO.azimuths[ok]
    return np.column_stack([r[ok] * np.cos(a), r[ok] * np.sin(a)])


def relative(p1, p2):
    """(t, θ) of pose 2 in the frame of pose 1: what PLICP(scan 1, scan 2) should return."""
    return rot(p1[2]).T @ (np.array(p2[:2]) - np.array(p1[:2])), p2[2] - p1[2]


def test_closed_form_matches_least_squares():
    rng = np.random.default_rng(3)
    for k in range(30):
        n_pts = int(rng.integers(5, 50))
        p = rng.normal(size=(n_pts, 2)) * 3
        ang = rng.uniform(0, 2 * np.pi, n_pts)
        n = np.column_stack([np.cos(ang), np.sin(ang)])
        w = rng.uniform(0.1, 2.0, n_pts)
        true_t, true_th = rng.normal(size=2), rng.uniform(-3, 3)
        # Even k: a scan-matching-like problem (small residuals); odd: arbitrary data.
        noise = 1e-3 if k % 2 == 0 else 3.0
        q = p @ rot(true_th).T + true_t + noise * rng.normal(size=(n_pts, 2))
        sw = np.sqrt(w)

        def res(x, p=p, q=q, n=n, sw=sw):
            return sw * np.einsum("ij,ij->i", n, p @ rot(x[2]).T + x[:2] - q)

        starts = [
            least_squares(res, [0, 0, th0], xtol=1e-15, ftol=1e-15, gtol=1e-15)
            for th0 in np.linspace(-np.pi, np.pi, 8, endpoint=False)
        ]
        ref = min(starts, key=lambda r: r.cost)
        t, th = solve_point_to_line(p, q, n, w)
        ours = 0.5 * np.sum(res(np.r_[t, th]) ** 2)
        assert ours <= ref.cost * (1 + 1e-12) + 1e-15
        if k % 2 == 0:
            dth = np.mod(th - ref.x[2] + np.pi, 2 * np.pi) - np.pi
            assert np.max(np.abs(t - ref.x[:2])) < 1e-9 and abs(dth) < 1e-9


def test_noise_free_motion_recovered():
    scene, rng = cluttered_room(), np.random.default_rng(0)
    for _ in range(10):
        p1 = (rng.uniform(-3, 3), rng.uniform(-2, 2), rng.uniform(-np.pi, np.pi))
        d, ang = rng.uniform(0, 0.5), rng.uniform(0, 2 * np.pi)
        p2 = (p1[0] + d * np.cos(ang), p1[1] + d * np.sin(ang), p1[2] + rng.uniform(-0.17, 0.17))
        t, th = relative(p1, p2)
        res = plicp(to_points(ranges(scene, p1)), to_points(ranges(scene, p2)))
        assert res.converged
        assert np.linalg.norm(res.t - t) <= 1e-3
        assert np.rad2deg(abs(res.theta - th)) <= 0.05


def test_rotation_search_rescues_large_start():
    scene = cluttered_room()
    p1, p2 = (0.0, 0.0, 0.2), (0.3, 0.1, 0.3)
    t, th = relative(p1, p2)
    a, b = to_points(ranges(scene, p1)), to_points(ranges(scene, p2))
    res = plicp(a, b, (t[0], t[1], th + np.deg2rad(40)), rotation_search=True)
    assert np.linalg.norm(res.t - t) <= 1e-3 and abs(res.theta - th) <= np.deg2rad(0.05)


def _gradient(x, ref, cur, c):
    i, ja, jb = c.T
    n = line_normals(ref[ja], ref[jb])
    r = np.einsum("ij,ij->i", n, cur[i] @ rot(x[2]).T + x[:2] - ref[ja])
    dr = np.einsum("ij,ij->i", n, cur[i] @ rot(x[2] + np.pi / 2).T)
    return 2 * np.r_[n.T @ r, r @ dr]


def test_hessians_match_finite_differences():
    scene = cluttered_room()
    ref, cur = to_points(ranges(scene, (0, 0, 0.3))), to_points(ranges(scene, (0.3, 0.2, 0.4)))
    res = plicp(ref, cur)
    x = np.r_[res.t, res.theta] + [0.01, -0.02, 0.01]  # off the optimum: r ≠ 0 terms count
    c = res.correspondences
    hess, jxz = plicp_hessians(ref, cur, x[:2], x[2], c)
    eps = 1e-6
    h_fd = np.array(
        [
            (_gradient(x + e, ref, cur, c) - _gradient(x - e, ref, cur, c)) / (2 * eps)
            for e in np.eye(3) * eps
        ]
    ).T
    assert np.allclose(hess, h_fd, rtol=1e-6, atol=1e-3)
    u_ref = ref / np.linalg.norm(ref, axis=1, keepdims=True)
    for k in np.unique(c[:, 1])[::25]:
        up, um = ref.copy(), ref.copy()
        up[k] += eps * u_ref[k]
        um[k] -= eps * u_ref[k]
        col = (_gradient(x, up, cur, c) - _gradient(x, um, cur, c)) / (2 * eps)
        assert np.allclose(jxz[:, len(cur) + k], col, rtol=1e-5, atol=1e-3)


def _monte_carlo(scene, p1, p2, sigma, trials, **plicp_args):
    """Censi's estimate and the sample covariance of matches with noisy ranges, the
    correspondences held at those of the noise-free match (the assumption of Censi 2007)."""
    r1, r2 = ranges(scene, p1), ranges(scene, p2)
    ref, cur = to_points(r1), to_points(r2)
    res = plicp(ref, cur, **plicp_args)
    i, ja, jb = res.correspondences.T
    rng = np.random.default_rng(7)
    out = []
    for _ in range(trials):
        rn = to_points(r1 + sigma * rng.normal(size=r1.shape))
        cn = to_points(r2 + sigma * rng.normal(size=r2.shape))
        t, th = solve_point_to_line(cn[i], rn[ja], line_normals(rn[ja], rn[jb]))
        out.append(np.r_[t, th])
    return plicp_covariance(ref, cur, res, sigma), np.cov(np.array(out).T)


def test_covariance_matches_monte_carlo():
    est, mc = _monte_carlo(cluttered_room(), (0.5, -0.5, 0.3), (0.8, -0.3, 0.4), 1e-3, 200)
    assert np.linalg.norm(est - mc) / np.linalg.norm(mc) < 0.2


def test_covariance_grows_along_corridor():
    """In a 50 m corridor only the far end wall constrains x: the along-axis variance is finite
    but far larger than the across-axis one. The match starts at the true motion and keeps
    every pair (trim=1): trimmed PLICP drops exactly the end-wall pairs as its worst 10 % and
    slides along the corridor, which is PLICP's degeneracy, not the covariance's."""
    truth = (0.3, 0.05, 0.02)
    cov, _ = _monte_carlo(corridor(), (0.0, 0.0, 0.0), truth, 1e-2, 2, initial=truth, trim=1.0)
    # The scan's x axis is (nearly) the corridor axis.
    assert np.all(np.isfinite(cov)) and cov[0, 0] < 1e-4  # σ_x of a few mm: constrained
    assert cov[0, 0] > 20 * cov[1, 1]


def test_plicp_at_a_converged_pose_is_plicps_own_result():
    """plicp_at pairs and scores a given pose as PLICP does: at PLICP's converged pose it
    returns PLICP's residual and number of pairs; 10 cm off it is worse; nothing paired far
    away."""
    from usvdrake.systems.slam.plicp import plicp_at

    scene = cluttered_room()
    p1, p2 = (0.0, 0.0, 0.0), (0.3, 0.1, 0.05)
    ref, cur = to_points(ranges(scene, p1)), to_points(ranges(scene, p2))
    res = plicp(ref, cur)
    assert res.converged
    at = plicp_at(ref, cur, (*res.t, res.theta))
    assert at.iterations == 0 and at.converged
    # PLICP's pairs are those of its last solve, made a step (below its tolerance) earlier
    assert abs(at.n_valid - res.n_valid) <= 0.01 * res.n_valid
    assert abs(at.residual - res.residual) < 1e-4
    off = plicp_at(ref, cur, (res.t[0] + 0.1, res.t[1] + 0.1, res.theta))
    assert off.residual > res.residual + 0.02
    np.testing.assert_array_equal(plicp_at(ref, cur, (1e3, 1e3, 0.0)).correspondences.shape, (0, 3))
