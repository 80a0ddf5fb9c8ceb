"""The compiled PLICP (plicp_kernel) against its numpy reference (plicp_reference): the same poses
and the same correspondences on real CARMEN scans and noisy simulated ones, the exact
nearest-neighbour grid against cKDTree, the solve against solve_point_to_line, edge cases."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from usvdrake.logs.carmen import read_carmen
from usvdrake.systems.slam import plicp_kernel as kernel
from usvdrake.systems.slam.graph_slam.poses import between
from usvdrake.systems.slam.plicp import (
    line_normals,
    plicp,
    plicp_at,
    plicp_at_reference,
    plicp_reference,
    rot,
    solve_point_to_line,
)
from usvdrake.worlds.synthetic import noisy_scan_pairs

DATA = Path(__file__).parent / "data" / "carmen"


def assert_same(a, b):
    """Same correspondences and bookkeeping, and then the very same pose and residual (plicp
    repeats its last solve in numpy), which is more than |Δt| ≤ 1e-9 m, |Δθ| ≤ 1e-10 rad."""
    assert a.iterations == b.iterations and a.converged == b.converged
    assert a.n_valid == b.n_valid
    np.testing.assert_array_equal(a.correspondences, b.correspondences)
    np.testing.assert_array_equal(a.t, b.t)
    assert a.theta == b.theta and a.residual == b.residual


@pytest.fixture(scope="module")
def intel():
    """(points, odometry pose) of the 56 scans where the Intel robot moves."""
    scans = list(read_carmen(DATA / "intel-first200.clf.bz2"))[144:]
    return [(s.scan.points(), s.odometry_pose) for s in scans]


def noisy_scans(count, seed):
    """Pairs of 1081-beam scans of the cluttered room, ranges with 1 cm noise, poses 0-0.5 m /
    0-10° apart: (reference points, current points, true relative pose)."""
    return [(a, b, between(p1, p2)) for a, b, p1, p2 in noisy_scan_pairs(count, seed)]


@pytest.mark.parametrize("gap", [1, 2, 5])
def test_intel_pairs_match_reference(intel, gap):
    for k in range(0, len(intel) - gap, 2 if gap == 1 else 3):
        (ref, pa), (cur, pb) = intel[k], intel[k + gap]
        guess = tuple(between(pa, pb))
        assert_same(plicp(ref, cur, guess), plicp_reference(ref, cur, guess))


def test_intel_variants_match_reference(intel):
    """Other options the callers use: a tighter pairing distance, no trimming, no coarse stage,
    the rotation search from a 20° error, and a cap on the iterations."""
    (ref, pa), (cur, pb) = intel[20], intel[24]
    guess = between(pa, pb)
    variants = [
        dict(max_distance=0.3, trim=0.8),
        dict(trim=1.0, coarse_stride=1),
        dict(rotation_search=True, initial=tuple(guess + [0, 0, np.deg2rad(20)])),
        dict(max_iterations=3),
    ]
    for kw in variants:
        kw.setdefault("initial", tuple(guess))
        assert_same(plicp(ref, cur, **kw), plicp_reference(ref, cur, **kw))


def test_mit_corridor_matches_reference():
    (a, b) = [s.scan.points() for s in read_carmen(DATA / "mit-csail-117.clf")]
    for guess in [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.1, 0.05, 0.02)]:
        assert_same(plicp(a, b, guess), plicp_reference(a, b, guess))
        assert_same(plicp(b, a, guess), plicp_reference(b, a, guess))


def test_noisy_simulated_pairs_match_reference():
    for ref, cur, truth in noisy_scans(12, seed=5):
        for guess in [(0.0, 0.0, 0.0), tuple(truth)]:
            ours, theirs = plicp(ref, cur, guess), plicp_reference(ref, cur, guess)
            assert_same(ours, theirs)
        assert np.linalg.norm(ours.t - truth[:2]) < 0.02  # and the match is right


def test_plicp_at_matches_reference(intel):
    (ref, pa), (cur, pb) = intel[10], intel[13]
    pose = plicp(ref, cur, tuple(between(pa, pb))).pose
    for p in (pose, pose + [0.05, -0.03, 0.01], pose + [50.0, 0.0, 0.0]):
        assert_same(plicp_at(ref, cur, p), plicp_at_reference(ref, cur, p))


def test_grid_nearest_is_cKDTree_nearest():
    rng = np.random.default_rng(2)
    for cell in (0.05, 0.3, 2.0):  # (the grid is exact for any cell size)
        pts = rng.normal(size=(400, 2)) * [5.0, 2.0]
        grid, tree = kernel.build_grid(pts, cell), cKDTree(pts)
        q = rng.normal(size=(500, 2)) * [6.0, 3.0]
        for bound in (0.1, 0.5, 3.0):
            d, j = tree.query(q, distance_upper_bound=bound)
            for k in range(len(q)):
                hint = int(rng.integers(-1, len(pts)))
                got, d2 = kernel.nearest(grid, q[k, 0], q[k, 1], bound * bound, hint)
                if np.isfinite(d[k]):
                    assert got == j[k] and np.sqrt(d2) == d[k]
                else:
                    assert got == -1


def test_grid_ties_and_bound():
    """Exact ties go to the lower index; a point exactly at the bound is excluded (strict, as
    cKDTree's distance_upper_bound)."""
    pts = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0], [3.0, 3.0]])
    order = [4, 1, 0, 3, 2]  # the far point first: the tie is then won by index 1
    for cell in (0.3, 1.0, 4.0):
        grid = kernel.build_grid(pts, cell)
        assert kernel.nearest(grid, 0.0, 0.0, 1.0 + 1e-9)[0] == 0
        assert kernel.nearest(grid, 0.0, 0.0, 1.0)[0] == -1
        assert kernel.nearest(grid, 0.0, 0.0, 4.0, hint=2)[0] == 0
        assert kernel.nearest(kernel.build_grid(pts[order], cell), 0.0, 0.0, 4.0)[0] == 1
        # a non-finite point is never the nearest
        holed = np.vstack([[np.nan, 0.0], pts[:3]])
        assert kernel.nearest(kernel.build_grid(holed, cell), 0.0, 0.0, 4.0, hint=0)[0] == 1


def test_search_skips_do_not_change_the_pairs(intel):
    """Pairs found with the last search's memo (hints, clearances: searches skipped) equal pairs
    found afresh, along a walk of small and large steps."""
    (ref, _), (cur, _) = intel[30], intel[31]
    grid, rng = kernel.build_grid(ref, 0.25), np.random.default_rng(4)
    active = np.arange(len(cur))
    hint, memo = np.full(len(cur), -1), np.full((len(cur), 3), -1.0)
    pose = np.zeros(3)
    skipped = 0
    for _ in range(60):
        pose = pose + rng.normal(size=3) * 10.0 ** -rng.integers(1, 9)
        before = memo.copy()
        args = (grid, ref, cur, active, np.cos(pose[2]), np.sin(pose[2]), pose[0], pose[1])
        kept = kernel.pairs(*args, 1.0, 1.0, 0.9, hint, memo)
        fresh = kernel.pairs(*args, 1.0, 1.0, 0.9, np.full(len(cur), -1), np.full_like(memo, -1))
        for a, b in zip(kept, fresh, strict=True):
            np.testing.assert_array_equal(a, b)
        skipped += np.sum(np.all(memo == before, axis=1))
    assert skipped > 10 * len(cur)  # the memo did skip searches


def test_trim_ties_keep_the_lowest_indices():
    """A straight wall matched exactly: every error is 0, so trimming keeps the first points."""
    ref = np.column_stack([np.arange(40) * 0.1, np.full(40, 2.0)])
    cur = ref[:20].copy()
    grid = kernel.build_grid(ref, 0.25)
    active = np.arange(len(cur))
    hint, memo = np.full(len(cur), -1), np.full((len(cur), 3), -1.0)
    i, j1, j2, n = kernel.pairs(
        grid, ref, cur, active, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.5, hint, memo
    )
    np.testing.assert_array_equal(i, np.arange(10))
    np.testing.assert_array_equal(j1, np.arange(10))


def test_solve_matches_solve_point_to_line():
    rng = np.random.default_rng(3)
    for k in range(200):
        m = int(rng.integers(5, 60))  # (3 pairs can have several exact fits)
        p = rng.normal(size=(m, 2)) * 4
        ang = rng.uniform(0, 2 * np.pi, m)
        n = np.column_stack([np.cos(ang), np.sin(ang)])
        w = rng.uniform(0.1, 2.0, m) if k % 3 else np.ones(m)
        t, th = rng.normal(size=2), rng.uniform(-3, 3)
        q = p @ rot(th).T + t + (1e-3 if k % 2 else 2.0) * rng.normal(size=(m, 2))
        ok, tx, ty, theta = kernel.solve(p, q, n, w)
        t_ref, th_ref = solve_point_to_line(p, q, n, w)
        assert ok
        assert np.max(np.abs([tx, ty] - t_ref)) <= 1e-9 * max(1.0, np.abs(t_ref).max())
        assert abs(np.mod(theta - th_ref + np.pi, 2 * np.pi) - np.pi) <= 1e-10


def test_solve_exact_fit():
    """Noise-free pairs (the near-double root of the quartic) give the motion exactly."""
    p = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 3.0]])
    t, th = np.array([0.3, -0.2]), 0.4
    q = p @ rot(th).T + t
    n = line_normals(q, q + [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [1.0, -2.0]])
    ok, tx, ty, theta = kernel.solve(p, q, n, np.ones(4))
    assert ok and np.allclose([tx, ty, theta], [0.3, -0.2, 0.4], atol=1e-12)


def test_degenerate_geometry_as_reference():
    """A wall only (A singular, or singular up to rounding: the kernel leaves the match to numpy,
    whose rounding decides it), no overlap at all (fewer than 3 pairs), one or two reference
    points: the same results as the reference."""
    wall = np.column_stack([np.linspace(0, 10, 101), np.zeros(101)])
    assert not kernel.solve(wall, wall, np.tile([0.0, 1.0], (101, 1)), np.ones(101))[0]
    with pytest.raises(np.linalg.LinAlgError):
        solve_point_to_line(wall, wall, np.tile([0.0, 1.0], (101, 1)))
    slanted = wall @ rot(0.5).T  # a corridor off the axes: A singular up to rounding only
    cases = [
        (wall, wall + [0.2, 0.0], (0.0, 0.0, 0.0)),
        (slanted, slanted + [0.2 * np.cos(0.5), 0.2 * np.sin(0.5)], (0.0, 0.0, 0.0)),
        (wall, wall, (100.0, 0.0, 0.0)),
        (wall[:1], wall, (0.0, 0.0, 0.0)),
        (wall[:2], wall[:2], (0.0, 0.0, 0.0)),
    ]
    for ref, cur, guess in cases:
        ours, theirs = plicp(ref, cur, guess), plicp_reference(ref, cur, guess)
        assert_same(ours, theirs)
    assert ours.n_valid == 0 and ours.iterations == 0 and ours.residual == np.inf
