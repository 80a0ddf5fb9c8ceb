"""The incremental voxel map (voxel_map) against independent implementations: PCL-style voxel
centroids (scan_registration3d.voxel_downsample) for its contents, scipy's k-d tree for its
k-nearest-neighbour search."""

import numba
import numpy as np
import pytest
from scipy.spatial import cKDTree

from usvdrake.systems.slam.scan_registration3d import voxel_downsample
from usvdrake.systems.slam.voxel_map import VoxelMap, voxel_filter


def sorted_rows(a):
    return a[np.lexsort(a.T)]


def clouds(rng, n=6, m=2500, half=6.0):
    """Keyframes of points on a few planes and random scatter (surfaces are what maps hold)."""
    out = []
    for _ in range(n):
        u = rng.uniform(-half, half, (m, 2))
        plane = np.column_stack([u[:, 0], u[:, 1], 0.3 * u[:, 0] + rng.normal(0, 0.02, m)])
        out.append(np.vstack([plane, rng.uniform(-half, half, (m // 5, 3))]))
    return out


@pytest.mark.parametrize("voxel", [0.3, 0.0])
def test_map_is_the_voxel_filter_of_the_keyframes_it_holds(voxel):
    """Adding, dropping and re-adding (a moved pose) keyframes: the map holds exactly the
    voxel centroids of the union of the keyframes present (every point, voxel = 0), through
    several growths of the tables (the initial capacity is 4096 entries)."""
    rng = np.random.default_rng(0)
    kf = clouds(rng)
    fmap = VoxelMap(edge_voxel=voxel, planar_voxel=voxel, search_cell=0.7)
    for i, c in enumerate(kf):
        fmap.add(i, c[:50], c)
    fmap.remove(1)
    fmap.remove(4)
    moved = kf[2] + [0.05, -0.02, 0.01]
    fmap.add(2, moved[:50], moved)  # replaces keyframe 2
    present = [kf[0], moved, kf[3], kf[5]]
    expected = voxel_downsample(np.vstack(present), voxel)
    got = fmap.planar_points
    assert len(got) == len(expected)
    np.testing.assert_allclose(sorted_rows(got), sorted_rows(expected), atol=1e-9)
    assert sorted(fmap.keys()) == [0, 2, 3, 5]
    np.testing.assert_allclose(
        sorted_rows(fmap.edge_points),
        sorted_rows(voxel_downsample(np.vstack([c[:50] for c in present]), voxel)),
        atol=1e-9,
    )
    for key in (0, 2, 3, 5):
        fmap.remove(key)
    assert len(fmap.planar_points) == 0 and len(fmap.edge_points) == 0


@pytest.mark.parametrize("voxel,radius", [(0.3, 1.0), (0.3, 0.4), (0.0, 0.5), (0.0, 2.0)])
def test_knn_is_the_k_d_tree_answer(voxel, radius):
    """The k nearest map points within the radius (or none), as a k-d tree with the same
    distance bound gives them; queries on and off the surfaces, and far outside the map."""
    rng = np.random.default_rng(1)
    fmap = VoxelMap(voxel, voxel, search_cell=0.7)
    for i, c in enumerate(clouds(rng, n=3)):
        fmap.add(i, c[:40], c)
    pts = fmap.planar_points
    q = np.vstack([rng.uniform(-7, 7, (3000, 3)), [[50.0, 50.0, 50.0]]])
    table, idx, ok = fmap.knn(False, q, 5, radius)
    d, i_ref = cKDTree(pts).query(q, k=5, distance_upper_bound=radius)
    ok_ref = np.isfinite(d[:, -1])
    np.testing.assert_array_equal(ok, ok_ref)
    assert 30 < ok.sum() < len(q)  # both kinds of answer occur
    np.testing.assert_allclose(table[idx[ok]], pts[i_ref[ok_ref]], atol=1e-12)


def test_knn_does_not_depend_on_the_number_of_threads():
    """The query rows run on numba's threads: one thread and all of them, the same answer and
    tolerances to the bit."""
    rng = np.random.default_rng(2)
    fmap = VoxelMap(0.3, 0.3, search_cell=0.7)
    for i, c in enumerate(clouds(rng, n=3)):
        fmap.add(i, c[:40], c)
    q = rng.uniform(-7, 7, (4000, 3))
    answers = []
    for threads in (1, numba.config.NUMBA_NUM_THREADS):
        idx, ok, tau = np.zeros((len(q), 5), np.int64), np.zeros(len(q), bool), np.zeros(len(q))
        previous = numba.get_num_threads()
        numba.set_num_threads(threads)
        try:
            fmap.knn_update(False, q, np.arange(0, len(q), 3), 5, 1.0, 0.1, idx, ok, tau)
        finally:
            numba.set_num_threads(previous)
        answers.append((idx, ok, tau))
    for a, b in zip(*answers, strict=True):
        assert np.array_equal(a, b)
    assert answers[0][1].sum() > 100 and not answers[0][1][1::3].any()  # only the rows asked


def test_tolerance_certifies_the_answer_for_moved_queries():
    """A query moved by less than its tolerance tau has the same neighbour set (and the same
    found / not found) as a fresh search from where it is now."""
    rng = np.random.default_rng(2)
    fmap = VoxelMap(0.3, 0.3, search_cell=0.7)
    for i, c in enumerate(clouds(rng, n=3)):
        fmap.add(i, c[:40], c)
    q = rng.uniform(-7, 7, (3000, 3))
    k, radius = 5, 0.8
    idx = np.zeros((len(q), k), dtype=np.int64)
    ok = np.zeros(len(q), dtype=bool)
    tau = np.zeros(len(q))
    fmap.knn_update(False, q, np.arange(len(q)), k, radius, 0.1, idx, ok, tau)
    assert np.all(tau[~ok] <= 0.1 + 1e-12) and np.median(tau) > 1e-3  # extra caps a miss
    step = rng.normal(size=q.shape)
    step *= (0.999 * tau / np.linalg.norm(step, axis=1))[:, None]  # just inside tau
    _, idx2, ok2 = fmap.knn(False, q + step, k, radius)
    np.testing.assert_array_equal(ok2, ok)
    np.testing.assert_array_equal(np.sort(idx2[ok], axis=1), np.sort(idx[ok], axis=1))
    # and well beyond tau the answer does change for some queries (tau is not vacuous)
    far = q + step / 0.999 * 3.0
    _, idx3, ok3 = fmap.knn(False, far, k, radius)
    same = (ok3 == ok) & np.all(np.sort(idx3, axis=1) == np.sort(idx, axis=1), axis=1)
    assert not np.all(same)


def test_only_listed_rows_are_searched():
    fmap = VoxelMap(0.0, 0.0)
    fmap.add("a", np.zeros((0, 3)), np.array([[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]]))
    q = np.array([[0.0, 0, 0], [0.2, 0, 0]])
    idx = np.full((2, 2), -7, dtype=np.int64)
    ok = np.zeros(2, dtype=bool)
    tau = np.full(2, -1.0)
    fmap.knn_update(False, q, np.array([1]), 2, 1.0, 0.0, idx, ok, tau)
    assert idx[0, 0] == -7 and tau[0] == -1.0  # row 0 untouched
    table = fmap.table(False)
    np.testing.assert_allclose(table[idx[1]], [[0.2, 0, 0], [0.1, 0, 0]])  # nearest first
    assert ok[1] and tau[1] == pytest.approx(0.05)  # half the gap from the 2nd to the 3rd


def test_voxel_filter_is_the_sorted_voxel_grid_in_another_order():
    rng = np.random.default_rng(3)
    pts = np.vstack(clouds(rng, n=2))
    for voxel in (0.05, 0.4, 3.0, 5e-6):  # the last beyond the packed keys: the general path
        got, want = voxel_filter(pts, voxel), voxel_downsample(pts, voxel)
        assert len(got) == len(want)
        np.testing.assert_allclose(sorted_rows(got), sorted_rows(want), atol=1e-12)
    np.testing.assert_array_equal(voxel_filter(pts, 0.0), pts)


def test_moving_a_keyframe_equals_dropping_and_adding_it():
    """Small pose corrections (most points stay in their voxel) and a large one (all move)."""
    rng = np.random.default_rng(7)
    kf = clouds(rng, n=3)
    moved = VoxelMap(0.3, 0.3, search_cell=0.7)
    for i, c in enumerate(kf):
        moved.add(i, c[:40], c)
    for shift in ([0.004, -0.002, 0.001], [0.2, 0.1, -0.3], [0.0, 0.0, 0.0]):
        c = kf[1] + shift
        moved.move(1, c[:40], c)
        fresh = VoxelMap(0.3, 0.3, search_cell=0.7)
        for i, d in enumerate([kf[0], c, kf[2]]):
            fresh.add(i, d[:40], d)
        for layer in ("planar_points", "edge_points"):
            a, b = getattr(moved, layer), getattr(fresh, layer)
            assert len(a) == len(b)
            np.testing.assert_allclose(sorted_rows(a), sorted_rows(b), atol=1e-9)
        q = rng.uniform(-7, 7, (500, 3))
        ta, ia, oka = moved.knn(False, q, 5, 0.8)
        tb, ib, okb = fresh.knn(False, q, 5, 0.8)
        np.testing.assert_array_equal(oka, okb)
        np.testing.assert_allclose(ta[ia[oka]], tb[ib[okb]], atol=1e-9)


def test_sliding_the_window_equals_rebuilding_it():
    """slide(): keyframes that left are dropped, new ones added, and those whose pose changed
    shifted in the compiled transform-and-compare pass; the map is the one built afresh."""
    rng = np.random.default_rng(11)
    local = clouds(rng, n=5, m=800)
    poses = np.repeat(np.eye(4)[None], 5, axis=0)
    for i in range(5):
        poses[i, :3, 3] = [2.0 * i, 0.5 * i, 0.0]
    fmap = VoxelMap(0.3, 0.3, search_cell=0.7)
    fmap.slide(range(0, 3), poses, [c[:40] for c in local], local)
    later = poses.copy()
    c, s = np.cos(0.02), np.sin(0.02)
    later[1, :3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    later[2, :3, 3] += [0.03, -0.02, 0.01]
    fmap.slide(range(1, 5), later, [c[:40] for c in local], local)
    assert sorted(fmap.keys()) == [1, 2, 3, 4]
    fresh = VoxelMap(0.3, 0.3, search_cell=0.7)
    for i in range(1, 5):
        R, t = later[i, :3, :3], later[i, :3, 3]
        fresh.add(i, local[i][:40] @ R.T + t, local[i] @ R.T + t)
    for layer in ("planar_points", "edge_points"):
        a, b = getattr(fmap, layer), getattr(fresh, layer)
        assert len(a) == len(b)
        np.testing.assert_allclose(sorted_rows(a), sorted_rows(b), atol=1e-9)
