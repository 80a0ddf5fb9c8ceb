"""Map processing, frontiers and the velocity-setpoint law of Ueland 2017, tested alone."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from usvdrake.systems.guidance.map_processing import (
    VesselOffMapError,
    coarsen,
    cost_weight,
    disc_mask,
    frontier_cells,
    process_map,
)
from usvdrake.systems.guidance.velocity_setpoint import (
    lookahead_distance,
    rediscretise,
    setpoint_on_path,
)
from usvdrake.worlds.world import OccupancyGrid

FREE, OCC, UNK = OccupancyGrid.FREE, OccupancyGrid.OCCUPIED, OccupancyGrid.UNKNOWN


def test_cost_weight_is_eq1():
    # w = 1 + 5 / (0.1 + d): 51 on an obstacle, 11 at 0.4 m, → 1 far away
    np.testing.assert_allclose(cost_weight([0.0, 0.4, 4.9, 1e9]), [51.0, 11.0, 2.0, 1.0])


def test_coarsen_rules_and_bad_ratio():
    fine = np.full((4, 6), FREE, np.int8)
    fine[0, 0] = OCC  # one occupied fine cell makes its 2×2 block occupied
    fine[2:4, 2:4] = UNK  # a fully unknown block stays unknown
    fine[2, 4] = UNK  # 3 of 4 free: free at free_fraction 0.5
    g = coarsen(OccupancyGrid((1.0, 2.0), 0.05, fine), 0.1)
    assert g.resolution == 0.1 and g.origin == (1.0, 2.0)
    np.testing.assert_array_equal(g.data, [[OCC, FREE, FREE], [FREE, UNK, FREE]])
    odd = coarsen(OccupancyGrid((0, 0), 0.05, np.zeros((5, 5), np.int8)), 0.1)
    assert odd.data.shape == (3, 3)  # padded with unknown: the edge blocks are half seen
    assert odd.data[2, 2] == UNK and odd.data[0, 2] == FREE
    with pytest.raises(ValueError, match="whole multiple"):
        coarsen(OccupancyGrid((0, 0), 0.05, fine), 0.12)


def _box_distance(res, occupied, r, c):
    """Exact distance from the centre of (r, c) to the nearest occupied square."""
    cells = np.argwhere(occupied)
    dr = np.maximum(np.abs(cells[:, 0] - r) - 0.5, 0.0)
    dc = np.maximum(np.abs(cells[:, 1] - c) - 0.5, 0.0)
    return res * np.sqrt(dr * dr + dc * dc).min()


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000))
def test_clearance_is_a_tight_lower_bound(seed):
    rng = np.random.default_rng(seed)
    data = np.where(rng.random((15, 17)) < 0.1, OCC, FREE).astype(np.int8)
    data[7, 8] = FREE
    res = 0.2
    pmap = process_map(OccupancyGrid((0, 0), res, data), (8.5 * res, 7.5 * res), 0.0, 0.0, 5.0)
    occ = data == OCC
    if not occ.any():
        return
    for r, c in np.argwhere(~occ)[::7]:
        exact = _box_distance(res, occ, r, c)
        assert pmap.clearance[r, c] <= exact + 1e-12
        # loses at most the half-diagonal minus the half-side of a cell
        assert pmap.clearance[r, c] >= exact - res * (np.sqrt(0.5) - 0.5) - 1e-12


def test_process_map_inflation_reachability_and_near_vessel_rule():
    res = 0.1
    data = np.full((40, 60), FREE, np.int8)
    data[:, 30] = OCC  # a wall splits the map in two
    data[18:22, 8:12] = UNK  # the vessel sits on an unseen patch
    grid = OccupancyGrid((0.0, 0.0), res, data)
    pmap = process_map(grid, (1.0, 2.0), inflation=0.4, near_free_radius=0.2)
    assert pmap.start == (20, 10)
    assert not pmap.unknown[20, 10]  # centre 0.07 m from the vessel: unknown → free
    assert not pmap.unknown[19, 9]  # 0.07 m
    assert pmap.unknown[18, 8]  # centre (0.85, 1.85) is 0.21 m away: stays unknown
    assert pmap.traversable[:, :25].any()
    assert not pmap.traversable[:, 30:].any()  # beyond the wall: unreachable
    # inflation: clearance = edt − res/√2 > 0.4 m needs 5 cells to the wall (0.429 m; 4: 0.329)
    assert not pmap.traversable[:, 26].any() and pmap.traversable[:, 25].all()
    np.testing.assert_allclose(pmap.weights[0, 20], cost_weight(10 * res))
    with pytest.raises(VesselOffMapError, match="outside"):
        process_map(grid, (-1.0, 2.0))
    with pytest.raises(VesselOffMapError, match="no traversable cell"):
        process_map(grid, (3.0, 2.0), inflation=0.4, max_snap=0.1)
    snapped = process_map(grid, (2.8, 2.0), inflation=0.4, max_snap=1.0)
    assert snapped.start == (20, 25)  # pushed out of the inflation towards free water


def test_frontiers_drop_small_clusters_and_track():
    data = np.full((30, 30), FREE, np.int8)
    data[:, 20:] = UNK  # unexplored east part: a long frontier along col 19
    data[5, 5] = UNK  # a single unseen cell: a 1-cell hole, its ring is 8 frontier cells
    grid = OccupancyGrid((0.0, 0.0), 0.2, data)
    pmap = process_map(grid, (2.0, 3.0), inflation=0.0, near_free_radius=0.0)
    cells = frontier_cells(pmap, min_cluster=3)
    cols = set(cells[:, 1].tolist())
    assert cols == {4, 5, 6, 19}
    assert len(frontier_cells(pmap, min_cluster=9)) == 30  # only the long frontier survives
    mask = disc_mask(pmap.shape, np.array([[5, 5]]), 1.5)
    assert mask[5, 5] and mask[6, 6] and not mask[7, 5] and mask.sum() == 9


@pytest.mark.parametrize(
    "d,r_s", [(0.0, 0.1), (0.3, 0.1), (0.5, 0.3), (1.0, 0.8), (1.5, 1.8), (2.1, 3.0), (9, 3.0)]
)
def test_lookahead_is_eq2(d, r_s):
    assert lookahead_distance(d) == pytest.approx(r_s)


def test_lookahead_is_continuous_and_monotone():
    d = np.linspace(0.0, 3.0, 3001)
    r = np.array([lookahead_distance(x) for x in d])
    assert np.all(np.diff(r) >= -1e-12)
    assert np.max(np.abs(np.diff(r))) < 0.01  # no jumps (slope ≤ 2 on a 1 mm grid)
    assert lookahead_distance(np.inf) == 3.0
    with pytest.raises(ValueError):
        lookahead_distance(np.nan)


def test_rediscretise_and_setpoint_eq3_eq4():
    path = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]])
    dense = rediscretise(path, 0.01)
    assert len(dense) == 301
    np.testing.assert_allclose(np.linalg.norm(np.diff(dense, axis=0), axis=1), 0.01, atol=1e-9)
    np.testing.assert_allclose(dense[[0, 100, -1]], path)
    # vessel beside the path at 0.5 m along, nearest object 0.8 m: r_s = 0.6, n = 60
    p, l, s = setpoint_on_path(dense, [0.5, 0.3], d_min=0.8)
    assert (l, s) == (50, 110)
    np.testing.assert_allclose(p, [1.0, 0.1], atol=1e-9)
    # open water near the end: s = min(n + l, N) clips at the last point
    p, l, s = setpoint_on_path(dense, [1.0, 1.9], d_min=5.0)
    assert s == len(dense) - 1 and np.allclose(p, [1.0, 2.0])
    assert len(rediscretise(np.array([[1.0, 2.0]]))) == 1
