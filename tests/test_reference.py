"""Grid A* (Hart, Nilsson & Raphael 1968) and the timed NMPC reference of Roboat II §VI-B."""

import math

import numpy as np
import pytest
import shapely
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from usvdrake.systems.guidance.grid_astar import (
    SQRT2,
    NoPathError,
    PlanningGrid,
    grid_astar,
    octile_distance,
    path_cost,
    plan_path,
)
from usvdrake.systems.guidance.reference_trajectory import (
    Curve,
    ReferenceTrajectory,
    RestToRest,
    smooth_corners,
)
from usvdrake.worlds import OccupancyGrid, World, make_world

START, GOAL = (-4.0, 0.0), (70.0, 44.0)  # canal_demo: along the L from its west end
GOALS = [(30.0, 3.0), (70.0, 44.0), (60.0, 0.0)]  # out, up the branch, and back round the bend


def dijkstra_cost(occupied: np.ndarray, start, goal) -> float:
    """Independent shortest-path cost [cells] on the same 8-connected graph as grid_astar:
    no step into occupied cells, no diagonal between two occupied side cells."""
    rows, cols = occupied.shape
    idx = np.arange(rows * cols).reshape(rows, cols)
    src, dst, w = [], [], []
    for dr, dc in [(0, 1), (1, 0), (0, -1), (-1, 0), (1, 1), (1, -1), (-1, 1), (-1, -1)]:
        r0, r1 = max(0, -dr), rows - max(0, dr)
        c0, c1 = max(0, -dc), cols - max(0, dc)
        a = (slice(r0, r1), slice(c0, c1))
        b = (slice(r0 + dr, r1 + dr), slice(c0 + dc, c1 + dc))
        ok = ~occupied[a] & ~occupied[b]
        if dr and dc:
            side1 = occupied[r0 + dr : r1 + dr, c0:c1]
            side2 = occupied[r0:r1, c0 + dc : c1 + dc]
            ok &= ~(side1 & side2)
        src.append(idx[a][ok])
        dst.append(idx[b][ok])
        w.append(np.full(ok.sum(), SQRT2 if dr and dc else 1.0))
    graph = coo_matrix(
        (np.concatenate(w), (np.concatenate(src), np.concatenate(dst))),
        shape=(rows * cols, rows * cols),
    ).tocsr()
    return float(dijkstra(graph, indices=idx[start])[idx[goal]])


def assert_valid_cell_path(occupied: np.ndarray, cells, start, goal):
    c = np.asarray(cells)
    assert tuple(c[0]) == start and tuple(c[-1]) == goal
    assert not occupied[c[:, 0], c[:, 1]].any()
    steps = np.diff(c, axis=0)
    assert np.all(np.abs(steps).max(axis=1) == 1)
    for (r, col), (dr, dc) in zip(c[:-1], steps, strict=False):
        if dr and dc:
            assert not (occupied[r + dr, col] and occupied[r, col + dc]), "corner cut"


def sample_polyline(p: np.ndarray, step: float = 0.05) -> np.ndarray:
    out = [p[0]]
    for a, b in zip(p[:-1], p[1:], strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + (b - a) * np.linspace(0, 1, n + 1)[1:, None])
    return np.vstack(out)


def distance_to_polyline(x: np.ndarray, p: np.ndarray) -> np.ndarray:
    a, b = p[:-1], p[1:]
    ab = b - a
    t = np.clip(np.einsum("nkd,kd->nk", x[:, None] - a, ab) / np.sum(ab * ab, axis=1), 0, 1)
    closest = a + t[..., None] * ab
    return np.linalg.norm(x[:, None] - closest, axis=2).min(axis=1)


@pytest.fixture(scope="module")
def canal():
    world = make_world("canal_demo")
    return world, PlanningGrid.from_world(world, 0.5)


# --- grid A* --------------------------------------------------------------------------------


@pytest.mark.parametrize("seed", range(6))
def test_astar_is_optimal_against_dijkstra(seed):
    rng = np.random.default_rng(seed)
    occupied = rng.random((25, 35)) < 0.3
    free = np.argwhere(~occupied)
    for _ in range(8):
        start, goal = (tuple(int(v) for v in free[i]) for i in rng.choice(len(free), 2))
        cells = grid_astar(occupied, start, goal)
        expected = dijkstra_cost(occupied, start, goal)
        if math.isinf(expected):
            assert cells is None
        else:
            assert_valid_cell_path(occupied, cells, start, goal)
            assert path_cost(cells) == pytest.approx(expected, abs=1e-6)
            assert octile_distance(start, goal) <= expected + 1e-12  # admissible


def test_astar_hand_made_wall_with_a_gap():
    occupied = np.zeros((7, 9), bool)
    occupied[:, 4] = True
    occupied[5, 4] = False  # the only gap
    cells = grid_astar(occupied, (1, 1), (1, 7))
    assert_valid_cell_path(occupied, cells, (1, 1), (1, 7))
    assert (5, 4) in cells
    # Down diagonally to row 4, through the gap on row 5, and up again: 2 (1 + 3√2) steps.
    assert path_cost(cells) == pytest.approx(2 * (1 + 3 * SQRT2))
    assert path_cost(cells) == pytest.approx(dijkstra_cost(occupied, (1, 1), (1, 7)))


def test_astar_no_corner_cutting_between_two_diagonal_obstacles():
    occupied = np.array([[False, True], [True, False]])
    assert grid_astar(occupied, (0, 0), (1, 1)) is None  # the only way squeezes between them
    one = np.array([[False, True], [False, False]])
    assert grid_astar(one, (0, 0), (1, 1)) == [(0, 0), (1, 1)]  # past a single one is fine
    # A diagonal wall of single cells is a wall.
    wall = np.eye(6, dtype=bool)[::-1]
    assert grid_astar(wall, (0, 0), (5, 5)) is None
    assert math.isinf(dijkstra_cost(wall, (0, 0), (5, 5)))


def test_astar_trivial_and_errors():
    occupied = np.zeros((3, 4), bool)
    occupied[1, 1] = True
    assert grid_astar(occupied, (0, 0), (0, 0)) == [(0, 0)]
    with pytest.raises(ValueError, match="start cell \\(1, 1\\) is occupied"):
        grid_astar(occupied, (1, 1), (0, 0))
    with pytest.raises(ValueError, match="goal cell \\(3, 0\\) is outside the 3×4 grid"):
        grid_astar(occupied, (0, 0), (3, 0))
    with pytest.raises(ValueError, match="outside"):
        grid_astar(occupied, (-1, 0), (0, 0))
    with pytest.raises(ValueError, match="2-D"):
        grid_astar(np.zeros(5, bool), (0,), (1,))


# --- planning in a world ----------------------------------------------------------------------


def test_grid_clearance_matches_the_world(canal):
    world, grid = canal
    xs, ys = grid.occupancy.cell_centres()
    gx, gy = np.meshgrid(xs, ys)
    est = grid.clearance
    near = (grid.occupancy.data == 0) & (est < 5.0)
    true = world.clearance(gx[near], gy[near])
    # Land is not a solid; the quays tile the whole water's edge, so solids bound everything.
    assert np.all(np.abs(est[near] - true) <= grid.resolution)


def test_plan_path_in_canal_demo_keeps_clear(canal):
    world, grid = canal
    path = plan_path(world, START, GOAL, resolution=0.5)
    np.testing.assert_allclose(path[0], START)
    np.testing.assert_allclose(path[-1], GOAL)
    assert len(path) < 10  # shortcut: a few straight legs, not a staircase
    dense = sample_polyline(path)
    assert world.in_water(dense[:, 0], dense[:, 1]).all()
    clearance = world.clearance(dense[:, 0], dense[:, 1])
    assert clearance.min() >= 0.5
    assert clearance.min() >= grid.inflation - grid.resolution
    # No longer than the raw A* path (the shortcut only ever shortens).
    raw = grid.plan(START, GOAL, simplify=False)
    length = np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))
    assert length <= np.sum(np.linalg.norm(np.diff(raw, axis=0), axis=1)) + 1e-9
    assert length >= np.hypot(74.0, 44.0)


def test_plan_errors(canal):
    world, grid = canal
    with pytest.raises(ValueError, match="not in free water"):
        grid.plan((20.0, 30.0), GOAL)  # on land
    with pytest.raises(ValueError, match="outside the grid"):
        grid.plan(START, (500.0, 0.0))
    with pytest.raises(ValueError, match="inflation"):
        PlanningGrid.from_world(world, 0.5, inflation=6.9).plan(START, GOAL)  # 14 m canal
    two_ponds = World(
        "two_ponds", 0, water=shapely.union(shapely.box(0, 0, 10, 10), shapely.box(20, 0, 30, 10))
    )
    with pytest.raises(NoPathError, match="no path"):
        plan_path(two_ponds, (5.0, 5.0), (25.0, 5.0))


def test_plan_snaps_a_start_beside_the_quay(canal):
    world, grid = canal
    start = (20.0, -6.0)  # 1 m from the south quay's face: inside the 1.6 m inflation
    assert 0.0 < world.clearance(*start) < grid.inflation
    path = grid.plan(start, GOAL)
    np.testing.assert_allclose(path[0], start)
    dense = sample_polyline(path)
    assert world.clearance(dense[:, 0], dense[:, 1]).min() > 0.5


def test_plan_across_amsterdam():
    world = make_world("amsterdam_canals")
    a, b = np.deg2rad(292.0), np.deg2rad(205.0)
    start, goal = (700 * np.cos(a), 700 * np.sin(a)), (250 * np.cos(b), 250 * np.sin(b))
    path = plan_path(world, start, goal)
    dense = sample_polyline(path, 0.25)
    assert world.in_water(dense[:, 0], dense[:, 1]).all()
    assert world.clearance(dense[:, 0], dense[:, 1]).min() >= 1.0
    assert 700.0 < np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)) < 900.0


# --- the reference trajectory ---------------------------------------------------------------


@pytest.fixture(scope="module")
def reference(canal):
    world, grid = canal
    return ReferenceTrajectory.from_goals(world, START, [GOAL], speed=0.6, grid=grid)


def test_rest_to_rest_profile():
    prof = RestToRest.make(100.0, 0.6, 0.1)
    t = np.linspace(0, prof.duration, 100001)
    p, v, a = prof(t)
    assert p[-1] == pytest.approx(100.0) and v.max() == pytest.approx(0.6)
    assert np.abs(a).max() == pytest.approx(0.1, rel=1e-6)
    np.testing.assert_allclose(np.gradient(p, t), v, atol=1e-4)
    np.testing.assert_allclose(np.gradient(v, t), a, atol=1e-4)
    short = RestToRest.make(1.0, 0.6, 0.1)  # too short to reach 0.6 m/s
    assert short.peak < 0.6 and short(short.duration)[0] == pytest.approx(1.0)


def test_reference_speed_heading_and_yaw_rate(reference):
    ref = reference
    t = np.arange(ref.t0, ref.t_end, 0.01)
    q, nu_dot = ref.sample(t)
    middle = (t > ref.t0 + 20.0) & (t < ref.t_end - 20.0)
    assert np.all(np.abs(q[middle, 3] - 0.6) < 1e-9)  # cruise at u = 0.6 m/s (Roboat II §VI-B)
    assert np.all(q[:, 4] == 0.0) and np.all(nu_dot[:, 1] == 0.0)  # v = 0
    assert np.abs(q[:, 5]).max() <= 0.3  # Roboat II's yaw rate at 0.6 m/s
    assert np.abs(np.diff(q[:, 2])).max() <= 0.3 * 0.01 + 1e-9  # ψ continuous, no wrap jumps
    assert np.abs(nu_dot[:, 0]).max() <= 0.1 + 1e-9  # the acceleration limit
    assert ref.duration > ref.length / 0.6


def test_reference_is_kinematically_consistent(reference):
    """ẋ = u cos ψ, ẏ = u sin ψ, ψ̇ = r, u̇ from ν̇: integrated, they reproduce the positions."""
    ref = reference
    t = np.linspace(ref.t0, ref.t_end, 200001)
    q, nu_dot = ref.sample(t)
    dt = np.diff(t)

    def integral(f):
        return np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * dt)])

    x = q[0, 0] + integral(q[:, 3] * np.cos(q[:, 2]))
    y = q[0, 1] + integral(q[:, 3] * np.sin(q[:, 2]))
    assert np.hypot(x - q[:, 0], y - q[:, 1]).max() < 0.02
    assert np.abs(q[0, 2] + integral(q[:, 5]) - q[:, 2]).max() < 1e-3
    assert np.abs(integral(nu_dot[:, 0]) - q[:, 3]).max() < 1e-4


def test_reference_follows_the_path_and_keeps_clear(canal, reference):
    world, grid = canal
    ref = reference
    q, _ = ref.sample(np.linspace(ref.t0, ref.t_end, 20001))
    path = ref.polylines[0]
    d = distance_to_polyline(q[:, :2], path)
    # Arcs of radius R leave the polyline only near corners, by at most R (sec(Δψ/2) − 1).
    seg = np.diff(path, axis=0)
    heading = np.arctan2(seg[:, 1], seg[:, 0])
    turn = np.abs(np.angle(np.exp(1j * np.diff(heading))))
    cut = ref.radius * (1 / np.cos(turn / 2) - 1)
    tangent = ref.radius * np.tan(turn / 2)
    assert d.max() <= cut.max() + 1e-6
    near_corner = np.linalg.norm(q[:, None, :2] - path[None, 1:-1], axis=2) <= tangent + 1e-6
    assert d[~near_corner.any(axis=1)].max() < 0.01  # on the straight legs: on the path
    assert world.in_water(q[:, 0], q[:, 1]).all()
    assert world.clearance(q[:, 0], q[:, 1]).min() >= 0.5
    assert ref.length <= np.sum(np.linalg.norm(seg, axis=1))


def test_reference_holds_before_and_after(reference):
    ref = reference
    q, nu_dot = ref.sample(np.array([ref.t0 - 50.0, ref.t0, ref.t_end, ref.t_end + 50.0]))
    np.testing.assert_allclose(q[0], q[1])
    np.testing.assert_allclose(q[2], q[3])
    np.testing.assert_allclose(q[0, :2], START)
    np.testing.assert_allclose(q[3, :2], GOAL, atol=1e-9)
    assert np.all(q[:, 3:] == 0.0) and np.all(nu_dot == 0.0)  # at rest
    assert ref.goal_times == pytest.approx([ref.t_end])


def test_reference_through_several_goals(canal):
    world, grid = canal
    ref = ReferenceTrajectory.from_goals(
        world, START, GOALS, grid=grid, start_heading=np.pi / 2, t0=10.0
    )
    assert len(ref.goal_times) == 3 and np.all(np.diff(ref.goal_times) > 0)
    q, nu_dot = ref.sample(ref.goal_times)
    np.testing.assert_allclose(q[:, :2], GOALS, atol=1e-9)  # each goal is reached, at rest
    assert np.all(np.abs(q[:, 3:]) < 1e-12)
    q0, _ = ref.sample(10.0)
    assert q0[0, 2] == pytest.approx(np.pi / 2)  # turns in place from the given heading first
    t = np.arange(ref.t0 - 5, ref.t_end + 5, 0.01)
    q, _ = ref.sample(t)
    assert np.abs(q[:, 5]).max() <= 0.3
    assert np.abs(np.diff(q[:, 2])).max() <= 0.3 * 0.01 + 1e-9
    assert world.clearance(q[:, 0], q[:, 1]).min() >= 0.5
    with pytest.raises(ValueError, match="grid has resolution"):
        ReferenceTrajectory.from_goals(world, START, GOALS, grid=grid, resolution=0.25)


def test_reference_from_a_hand_made_path():
    """A square corner: one arc of R = 0.6 / 0.25 = 2.4 m, 90° of heading at r = 0.25 rad/s."""
    path = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 20.0]])
    ref = ReferenceTrajectory.from_path(path, speed=0.6)
    assert ref.radius == pytest.approx(2.4)
    assert ref.length == pytest.approx(40.0 - 2 * 2.4 + 2.4 * np.pi / 2)
    q, _ = ref.sample(np.linspace(0, ref.t_end, 50001))
    assert q[-1, 2] == pytest.approx(np.pi / 2)
    assert np.abs(q[:, 5]).max() == pytest.approx(0.25)
    mid = np.argmin(np.hypot(q[:, 0] - 20.0, q[:, 1]))  # the arc's closest approach to the corner
    assert np.hypot(q[mid, 0] - 20.0, q[mid, 1]) == pytest.approx(2.4 * (SQRT2 - 1), abs=1e-3)


def test_plan_and_reference_to_where_we_are(canal):
    world, grid = canal
    path = grid.plan(START, START)
    np.testing.assert_allclose(path, [START])
    ref = ReferenceTrajectory.from_goals(world, START, [START], grid=grid, start_heading=0.3)
    q, nu_dot = ref.sample(np.array([-1.0, 0.0, 1.0]))
    np.testing.assert_allclose(q, np.tile([*START, 0.3, 0, 0, 0], (3, 1)))
    assert ref.duration == 0.0 and ref.goal_times == pytest.approx([0.0])
    with pytest.raises(ValueError, match="leg 1 starts"):
        ReferenceTrajectory([np.array([[0.0, 0.0], [1.0, 0.0]]), np.array([[2.0, 0], [3, 0]])])


def block_grid(outer_wall: bool) -> PlanningGrid:
    """40 m × 40 m at 0.5 m; x, y < 20 m is a solid block; ``outer_wall``: also x, y > 23.5 m,
    so the free water is an L-shaped corridor 3.5 m wide round the block's corner (20, 20)."""
    xs = (np.arange(80) + 0.5) * 0.5
    gx, gy = np.meshgrid(xs, xs)
    occupied = (gx < 20) & (gy < 20)
    if outer_wall:
        occupied |= (gx > 23.5) | (gy > 23.5)
    data = np.where(occupied, OccupancyGrid.OCCUPIED, OccupancyGrid.FREE).astype(np.int8)
    return PlanningGrid.from_occupancy(OccupancyGrid((0.0, 0.0), 0.5, data), inflation=1.6)


CORNER_PATH = np.array([[5.0, 21.7], [21.7, 21.7], [21.7, 5.0]])  # 1.7 m off both faces


def test_corner_arc_is_pushed_out_to_keep_the_inflation():
    grid = block_grid(outer_wall=False)
    assert grid.clearance_at(sample_polyline(CORNER_PATH)).min() >= 1.6
    plain, stops = smooth_corners(CORNER_PATH, 2.4)
    arc = Curve.fillet(plain, 2.4)
    xy = arc.at(np.linspace(0, arc.length, 2001))[0]
    # Unchecked, the arc cuts 2.4 (√2 − 1) = 0.99 m into the corner: 1.41 m from the block.
    assert np.hypot(xy[:, 0] - 20, xy[:, 1] - 20).min() == pytest.approx(1.7 * SQRT2 - 0.994, 1e-3)
    pushed, stops = smooth_corners(CORNER_PATH, 2.4, grid)
    assert not stops[1] and pushed[1, 0] > 21.7 and pushed[1, 0] == pytest.approx(pushed[1, 1])
    ref = ReferenceTrajectory.from_path(CORNER_PATH, grid=grid)
    q, _ = ref.sample(np.linspace(0, ref.t_end, 5001))
    assert grid.clearance_at(q[:, :2]).min() >= 1.6 - 1e-9
    # The grid's clearance is good to half a cell (it is 0.1 m optimistic off a corner).
    assert np.hypot(q[:, 0] - 20, q[:, 1] - 20).min() >= 1.6 - 0.25
    assert np.all(q[1:-1, 3] > 0)  # no stop at the corner


def test_corner_without_room_to_push_is_a_stop_and_turn():
    grid = block_grid(outer_wall=True)
    _, stops = smooth_corners(CORNER_PATH, 2.4, grid)
    assert stops.all()
    ref = ReferenceTrajectory.from_path(CORNER_PATH, grid=grid)
    t = np.linspace(0, ref.t_end, 20001)
    q, nu_dot = ref.sample(t)
    at_corner = np.hypot(q[:, 0] - 21.7, q[:, 1] - 21.7) < 1e-9
    turning = at_corner & (np.abs(q[:, 5]) > 1e-6)
    assert turning.any() and np.all(q[turning, 3] == 0.0)  # at rest on the corner, turning
    assert np.abs(q[:, 5]).max() == pytest.approx(0.25)  # r_max in place
    assert q[-1, 2] == pytest.approx(-np.pi / 2)  # east, then a right turn to south
    assert np.abs(nu_dot[:, 2]).max() <= 0.1 + 1e-9
