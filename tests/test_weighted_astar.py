"""The weighted multi-goal A* of Ueland 2017 §Path Planner
(usvdrake.systems.guidance.weighted_astar):
neighbour offsets, the edge model against shapely, optimality against scipy's Dijkstra on the
explicit graph, the 8-connected special case against grid_astar, and Ueland 2017 Fig. 8 on a real
map.
"""

from math import gcd

import numpy as np
import pytest
import shapely
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from usvdrake.systems.guidance.grid_astar import grid_astar, path_cost
from usvdrake.systems.guidance.weighted_astar import (
    AStarResult,
    connection_offsets,
    edge_table,
    path_length,
    weighted_astar,
)

# --- offsets and edge table ----------------------------------------------------------------


@pytest.mark.parametrize(("d", "count"), [(1, 8), (2, 16), (3, 32), (4, 48)])
def test_offsets_count_and_symmetry(d, count):
    off = connection_offsets(d)
    assert off.shape == (count, 2)
    pairs = {tuple(o) for o in off.tolist()}
    assert len(pairs) == count
    assert pairs == {(-r, -c) for r, c in pairs}  # symmetric under reversal
    assert pairs == {(c, r) for r, c in pairs}  # and under transposition
    assert all(max(abs(r), abs(c)) <= d and gcd(abs(r), abs(c)) == 1 for r, c in pairs)
    if d > 1:
        assert {tuple(o) for o in connection_offsets(d - 1).tolist()} < pairs


@pytest.mark.parametrize("bad", [0, 5, -1, 2.0, True, "4"])
def test_bad_connection_distance(bad):
    with pytest.raises(ValueError, match=repr(bad).replace(".", r"\.")):
        connection_offsets(bad)
    with pytest.raises(ValueError):
        edge_table(bad)
    with pytest.raises(ValueError):
        weighted_astar(np.ones((3, 3), bool), np.ones((3, 3)), (0, 0), (2, 2), bad)


def test_edge_table_matches_shapely():
    t = edge_table(4)
    window = range(-5, 6)
    for k, (dr, dc) in enumerate(t.offsets.tolist()):
        line = shapely.LineString([(0.0, 0.0), (float(dr), float(dc))])
        crossed, touched = {}, set()
        for r in window:
            for c in window:
                cell = shapely.box(r - 0.5, c - 0.5, r + 0.5, c + 0.5)
                if not line.intersects(cell):
                    continue
                length = line.intersection(cell).length
                if length > 1e-12:
                    crossed[(r, c)] = length
                else:
                    touched.add((r, c))
        cells, lengths = t.crossed(k)
        got = {tuple(c): ln for c, ln in zip(cells.tolist(), lengths.tolist(), strict=True)}
        assert set(got) == set(crossed), (dr, dc)
        for cell, ln in crossed.items():
            assert got[cell] == pytest.approx(ln, abs=1e-9), (dr, dc, cell)
        assert tuple(cells[0]) == (0, 0) and tuple(cells[-1]) == (dr, dc)  # ordered
        assert lengths.sum() == pytest.approx(np.hypot(dr, dc), abs=1e-12)
        assert t.length[k] == pytest.approx(np.hypot(dr, dc), abs=1e-12)
        # cells met only at a point: exactly the two beside a corner passage
        expected = {tuple(c) for c in t.corner[k].tolist()} if t.has_corner[k] else set()
        assert touched == expected, (dr, dc)
        assert t.has_corner[k] == (dr % 2 == 1 and dc % 2 == 1)


def test_unit_step_costs():
    t = edge_table(1)
    w = np.array([[2.0, 3.0], [5.0, 7.0]])
    k_right = [tuple(o) for o in t.offsets.tolist()].index((0, 1))
    k_diag = [tuple(o) for o in t.offsets.tolist()].index((1, 1))
    assert t.edge_cost(w, (0, 0), k_right) == pytest.approx(0.5 * (2 + 3))
    assert t.edge_cost(w, (0, 0), k_diag) == pytest.approx(np.sqrt(2) / 2 * (2 + 7))


# --- optimality against Dijkstra -----------------------------------------------------------


def explicit_graph(trav: np.ndarray, w: np.ndarray, d: int):
    """All allowed edges of connection distance d as a sparse (n × n) cost matrix."""
    rows, cols = trav.shape
    t = edge_table(d)
    tp = np.pad(trav, d, constant_values=False)  # outside the grid is blocked
    wp = np.pad(np.where(trav, w, 0.0), d)
    r, c = np.nonzero(trav)
    src, dst, cost = [], [], []
    for k, (dr, dc) in enumerate(t.offsets.tolist()):
        cells, lengths = t.crossed(k)
        ok = np.ones(len(r), bool)
        ck = np.zeros(len(r))
        for (cr, cc), ln in zip(cells.tolist(), lengths.tolist(), strict=True):
            ok &= tp[r + cr + d, c + cc + d]
            ck += wp[r + cr + d, c + cc + d] * ln
        if t.has_corner[k]:
            (ar, ac), (br, bc) = t.corner[k].tolist()
            ok &= tp[r + ar + d, c + ac + d] | tp[r + br + d, c + bc + d]
        src.append((r * cols + c)[ok])
        dst.append(((r + dr) * cols + c + dc)[ok])
        cost.append(ck[ok])
    n = rows * cols
    m = coo_matrix((np.concatenate(cost), (np.concatenate(src), np.concatenate(dst))), (n, n))
    return m.tocsr()


def check_path(res: AStarResult, trav, w, start, d):
    t = edge_table(d)
    index = {tuple(o): k for k, o in enumerate(t.offsets.tolist())}
    cells = res.cells
    assert cells.dtype.kind == "i" and cells.shape[1] == 2
    assert tuple(cells[0]) == tuple(start)
    total = 0.0
    for a, b in zip(cells[:-1], cells[1:], strict=True):
        k = index[tuple((b - a).tolist())]  # KeyError: not an allowed offset
        assert t.edge_free(trav, a, k), (a, b)
        total += t.edge_cost(w, a, k)
    assert total == pytest.approx(res.cost, abs=1e-9)


@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_astar_equals_dijkstra(d):
    found = unreachable = 0
    for seed in range(4):
        rng = np.random.default_rng(100 * d + seed)
        rows, cols = 30, 40
        trav = rng.random((rows, cols)) > 0.25
        trav[1:8, 1:8] = False  # a walled pocket: its goals are unreachable
        trav[2:7, 2:7] = True
        w = rng.uniform(1.0, 20.0, (rows, cols))
        if seed == 3:
            w[:] = 1.0  # uniform weights: many exact ties
        w[~trav] = np.nan  # never read
        free = np.argwhere(trav)
        outside = free[(free[:, 0] > 8) | (free[:, 1] > 8)]
        start = tuple(outside[rng.integers(len(outside))])
        dist = dijkstra(explicit_graph(trav, w, d), indices=start[0] * cols + start[1])
        dist = dist.reshape(rows, cols)
        queries = [free[rng.integers(len(free), size=1)] for _ in range(6)]
        queries += [
            np.argwhere(np.ones((rows, cols)))[rng.integers(rows * cols, size=n)] for n in (3, 8)
        ]
        queries += [free[rng.integers(len(free), size=n)] for n in (2, 5, 20)]
        queries += [np.array([[4, 4], [2, 6], [1, 1]]), np.array([[3, 5], [20, 30]])]
        for goals in queries:
            res = weighted_astar(trav, w, start, goals, d)
            ok = trav[goals[:, 0], goals[:, 1]]
            best = dist[goals[ok, 0], goals[ok, 1]].min() if ok.any() else np.inf
            if not np.isfinite(best):
                assert res is None
                unreachable += 1
                continue
            found += 1
            assert res is not None
            assert res.cost == pytest.approx(best, abs=1e-9, rel=0)
            assert ok[res.goal_index]
            assert tuple(res.cells[-1]) == tuple(goals[res.goal_index])
            assert dist[tuple(res.cells[-1])] == pytest.approx(best, abs=1e-9)
            assert res.expanded <= trav.sum()
            check_path(res, trav, w, start, d)
    assert found >= 40 and unreachable >= 4


def test_d1_with_unit_weights_matches_grid_astar():
    """d = 1, w ≡ 1: the classic 8-connected grid (steps 1 and √2, the same corner rule)."""
    for seed in range(5):
        rng = np.random.default_rng(seed)
        occ = rng.random((25, 35)) < 0.3
        free = np.argwhere(~occ)
        for _ in range(5):
            s, g = (tuple(int(v) for v in free[i]) for i in rng.integers(len(free), size=2))
            ref = grid_astar(occ, s, g)
            res = weighted_astar(~occ, np.ones(occ.shape), s, g, 1)
            assert (ref is None) == (res is None)
            if ref is not None:
                assert res.cost == pytest.approx(path_cost(ref), abs=1e-5)


# --- special cases and errors --------------------------------------------------------------


def test_special_cases():
    trav = np.ones((6, 7), bool)
    w = np.ones(trav.shape)
    res = weighted_astar(trav, w, (2, 3), (2, 3))
    assert res.cells.tolist() == [[2, 3]] and res.cost == 0.0 and res.goal_index == 0
    res = weighted_astar(trav, w, (0, 0), (3, 4))  # one straight d = 4 edge
    assert res.cells.tolist() == [[0, 0], [3, 4]] and res.cost == pytest.approx(5.0)
    trav[1:5, 5] = False
    assert weighted_astar(trav, w, (0, 0), [(2, 5), (3, 5)]) is None  # goals blocked
    assert weighted_astar(trav, w, (0, 0), np.zeros((0, 2), int)) is None
    res = weighted_astar(trav, w, (0, 0), [(2, 5), (5, 0), (0, 6)])
    assert res.goal_index == 1 and res.cost == pytest.approx(5.0)
    # a wall cut only by a corner passage between two blocked cells is closed for d = 1
    trav = np.ones((4, 4), bool)
    trav[[0, 1, 2, 3], [3, 2, 1, 0]] = False
    for d in (1, 2, 3, 4):
        assert weighted_astar(trav, np.ones(trav.shape), (0, 0), (3, 3), d) is None
    trav[3, 0] = True  # open the wall's end
    assert weighted_astar(trav, np.ones(trav.shape), (0, 0), (3, 3), 1) is not None


def test_errors():
    trav = np.ones((4, 5), bool)
    trav[1, 1] = False
    w = np.ones(trav.shape)
    with pytest.raises(ValueError, match="outside"):
        weighted_astar(trav, w, (4, 0), (0, 0))
    with pytest.raises(ValueError, match="not traversable"):
        weighted_astar(trav, w, (1, 1), (0, 0))
    with pytest.raises(ValueError, match="outside"):
        weighted_astar(trav, w, (0, 0), [(0, 1), (0, 5)])
    for bad in (0.5, np.nan):
        w2 = w.copy()
        w2[2, 3] = bad
        with pytest.raises(ValueError, match="≥ 1"):
            weighted_astar(trav, w2, (0, 0), (3, 4))
    w2 = w.copy()
    w2[1, 1] = 0.0  # non-traversable cells are not read
    assert weighted_astar(trav, w2, (0, 0), (3, 4)) is not None
    with pytest.raises(ValueError, match="shape"):
        weighted_astar(trav, np.ones((4, 4)), (0, 0), (3, 3))


# --- Ueland 2017 Fig. 8 on the NTNU basin
# -----------------------------------------------------------


def test_connection_distance_four_shortens_paths_in_ntnu_basin():
    from usvdrake.worlds import make_world

    g = make_world("ntnu_basin", 0).occupancy(0.1)
    res = g.resolution
    clearance = ndimage.distance_transform_edt(g.data != 100) * res
    trav = clearance > 0.4  # Ueland 2017 §Map Processing: 0.4 m inflation
    w = 1.0 + 5.0 / (0.1 + clearance)  # Ueland 2017 eq. (1)

    def cell(x, y):
        r, c = int((y - g.origin[1]) / res), int((x - g.origin[0]) / res)
        assert trav[r, c]
        return r, c

    start, goal = cell(2.0, 3.2), cell(38.0, 3.2)
    p1 = weighted_astar(trav, w, start, goal, 1)
    p4 = weighted_astar(trav, w, start, goal, 4)
    assert p1 is not None and p4 is not None
    check_path(p4, trav, w, start, 4)
    len1, len4 = path_length(p1.cells) * res, path_length(p4.cells) * res
    print(
        f"ntnu_basin {start}->{goal}: d=1 {len1:.2f} m ({p1.expanded} expanded), "
        f"d=4 {len4:.2f} m ({p4.expanded} expanded), ratio d4/d1 {len4 / len1:.4f}"
    )
    assert len4 < len1
    assert p4.cost <= p1.cost + 1e-9  # the d = 4 graph contains the d = 1 graph
