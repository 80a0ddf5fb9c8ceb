"""Log-odds occupancy grid: a box room, exact insert/remove, Bresenham against the textbook loop."""

import weakref

import numpy as np
import pytest

from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.slam.occupancy_mapping import LogOddsGrid, bresenham_cells
from usvdrake.worlds.world import OccupancyGrid

RES = 0.05


def reference_bresenham(x0: int, y0: int, x1: int, y1: int) -> list[tuple[int, int]]:
    """The textbook all-octant integer Bresenham loop (error term, no floats)."""
    dx, sx = abs(x1 - x0), 1 if x0 < x1 else -1
    dy, sy = -abs(y1 - y0), 1 if y0 < y1 else -1
    err, cells = dx + dy, []
    while True:
        cells.append((x0, y0))
        if x0 == x1 and y0 == y1:
            return cells
        e2 = 2 * err
        if e2 >= dy:
            err += dy
            x0 += sx
        if e2 <= dx:
            err += dx
            y0 += sy


def test_bresenham_cells_equal_reference():
    rng = np.random.default_rng(3)
    c0, r0 = 7, -4
    c1, r1 = rng.integers(-300, 300, 500), rng.integers(-300, 300, 500)
    c1[:4], r1[:4] = [c0, c0 + 5, c0, c0 - 9], [r0, r0, r0 - 6, r0 + 9]  # point, axes, diagonal
    ray, col, row = bresenham_cells(c0, r0, c1, r1)
    for k in range(len(c1)):
        ours = list(zip(col[ray == k].tolist(), row[ray == k].tolist(), strict=True))
        assert ours == reference_bresenham(c0, r0, int(c1[k]), int(r1[k])), k


def test_scan_cells_equal_reference_rays():
    """The vectorised scan update touches exactly the reference Bresenham cells."""
    rng = np.random.default_rng(4)
    grid = LogOddsGrid((-20.0, -20.0), RES, (800, 800))
    pose = (0.37, -1.21, 0.4)
    angles = np.linspace(-np.pi, np.pi, 300, endpoint=False)
    ranges = rng.uniform(0.01, 14.0, angles.size)
    ranges[::7] = np.inf  # no return
    max_range = 12.0
    grid.insert_scan(pose, ranges, angles, max_range)

    c0, r0 = int(np.floor((pose[0] + 20) / RES)), int(np.floor((pose[1] + 20) / RES))
    free, occ = set(), set()
    for r, a in zip(ranges, angles, strict=True):
        hit = r < max_range
        d = r if hit else max_range
        c1 = int(np.floor((pose[0] + d * np.cos(pose[2] + a) + 20) / RES))
        r1 = int(np.floor((pose[1] + d * np.sin(pose[2] + a) + 20) / RES))
        cells = reference_bresenham(c0, r0, c1, r1)
        if hit:
            occ.add(cells[-1])
            cells = cells[:-1]
        free.update(cells)
    free -= occ
    lo = grid.log_odds
    assert {(c, r) for r, c in zip(*np.nonzero(lo > 0), strict=True)} == occ
    assert {(c, r) for r, c in zip(*np.nonzero(lo < 0), strict=True)} == free
    assert np.all(lo[lo > 0] == pytest.approx(grid.l_occ))
    assert np.all(lo[lo < 0] == pytest.approx(grid.l_free))


def _box_room_scan(pose, xlo, xhi, ylo, yhi, n):
    """Exact ranges from inside an axis-aligned room [m]."""
    angles = np.linspace(-np.pi, np.pi, n, endpoint=False)
    d = np.stack([np.cos(pose[2] + angles), np.sin(pose[2] + angles)])
    with np.errstate(divide="ignore"):
        tx = np.where(d[0] > 0, (xhi - pose[0]) / d[0], (xlo - pose[0]) / d[0])
        ty = np.where(d[1] > 0, (yhi - pose[1]) / d[1], (ylo - pose[1]) / d[1])
    return np.minimum(np.abs(tx), np.abs(ty)), angles


def test_box_room_walls_occupied_inside_free():
    # Walls through cell centres, so float rounding of the end points cannot pick a neighbour.
    grid = LogOddsGrid((-1.0, -1.0), RES, (220, 260))
    xlo, xhi, ylo, yhi = 0.025, 10.025, 0.025, 8.025
    pose = (3.0, 2.5, 0.3)
    ranges, angles = _box_room_scan(pose, xlo, xhi, ylo, yhi, 2000)
    grid.insert_scan(pose, ranges, angles, max_range=30.0)
    out = grid.to_occupancy_grid()
    assert isinstance(out, OccupancyGrid) and out.data.dtype == np.int8
    assert out.origin == (-1.0, -1.0) and out.resolution == RES
    r_lo, c_lo = (int(v) for v in out.to_cell(xlo, ylo))
    r_hi, c_hi = (int(v) for v in out.to_cell(xhi, yhi))
    data = out.data
    inside = data[r_lo + 1 : r_hi, c_lo + 1 : c_hi]
    assert np.all(inside == OccupancyGrid.FREE)
    walls = np.concatenate(
        [
            data[r_lo, c_lo : c_hi + 1],
            data[r_hi, c_lo : c_hi + 1],
            data[r_lo : r_hi + 1, c_lo],
            data[r_lo : r_hi + 1, c_hi],
        ]
    )
    assert np.mean(walls == OccupancyGrid.OCCUPIED) > 0.9
    ring = np.zeros(data.shape, bool)
    ring[r_lo : r_hi + 1, c_lo : c_hi + 1] = True
    ring[r_lo + 1 : r_hi, c_lo + 1 : c_hi] = False
    assert np.all(data[~ring] != OccupancyGrid.OCCUPIED)  # nothing occupied off the walls
    outside = np.ones(data.shape, bool)
    outside[r_lo : r_hi + 1, c_lo : c_hi + 1] = False
    assert np.all(data[outside] == OccupancyGrid.UNKNOWN)


def test_no_return_rays_clear_but_mark_nothing():
    grid = LogOddsGrid((-10.0, -10.0), RES, (400, 400))
    angles = np.linspace(-np.pi / 2, np.pi / 2, 181)
    grid.insert_scan((0.0, 0.0, 0.0), np.full(181, np.inf), angles, max_range=5.0)
    assert not np.any(grid.log_odds > 0)
    out = grid.to_occupancy_grid()
    free = out.data == OccupancyGrid.FREE
    # A point 4.9 m straight ahead is cleared, one 5.2 m ahead is not.
    r, c = out.to_cell([4.9, 5.2], [0.01, 0.01])
    assert free[r[0], c[0]] and not free[r[1], c[1]]


def test_insert_then_remove_restores_zeros_exactly():
    rng = np.random.default_rng(5)
    grid = LogOddsGrid((-15.0, -15.0), RES, (500, 600))
    angles = np.linspace(-3 * np.pi / 4, 3 * np.pi / 4, 1081)
    scans = []
    for _ in range(5):
        ranges = rng.uniform(0.2, 35.0, angles.size)  # some beyond max_range, some off the grid
        ranges[rng.random(angles.size) < 0.1] = np.inf
        pose = (rng.uniform(-5, 5), rng.uniform(-5, 5), rng.uniform(-np.pi, np.pi))
        scans.append((pose, ranges))
        grid.insert_scan(pose, ranges, angles, 30.0)
    only_last = LogOddsGrid((-15.0, -15.0), RES, (500, 600))
    only_last.insert_scan(*scans[-1], angles, 30.0)
    for pose, ranges in scans[-2::-1]:
        grid.remove_scan(pose, ranges, angles, 30.0)
    np.testing.assert_array_equal(grid.log_odds, only_last.log_odds)
    grid.remove_scan(*scans[-1], angles, 30.0)
    assert np.all(grid.log_odds == 0.0) and not np.any(grid.observed)
    assert np.all(grid.to_occupancy_grid().data == OccupancyGrid.UNKNOWN)


def test_sensor_off_grid_and_laser_scan_message():
    grid = LogOddsGrid((0.0, 0.0), RES, (100, 100))
    scan = LaserScan(
        angle_min=-0.3,
        angle_increment=0.01,
        range_max=8.0,
        ranges=np.full(61, 4.0),
        valid=np.ones(61, bool),
    )
    grid.insert_laser_scan((-1.0, 2.5, 0.0), scan)  # starts 1 m left of the grid
    assert np.any(grid.log_odds > 0) and np.any(grid.log_odds < 0)
    grid.insert_laser_scan((-50.0, -50.0, 0.0), scan)  # never reaches the grid: no-op
    with pytest.raises(ValueError):
        LogOddsGrid((0.0, 0.0), RES, (10, 10), l_occ=-1.0)


def test_shared_copy_is_independent_once_either_writes():
    """Copy on write: Drake clones the SLAM state at every update, so copies share the arrays
    until one of them inserts a scan; neither may then see the other's scans."""
    angles = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    grid = LogOddsGrid((-10.0, -10.0), 0.1, (200, 200))
    grid.insert_scan((0.0, 0.0, 0.0), np.full(90, 4.0), angles, 8.0)
    before = grid.log_odds.copy()
    copy_ = grid.shared_copy()
    assert np.shares_memory(copy_._sum, grid._sum)  # nothing written yet: no copy paid
    copy_.insert_scan((2.0, 1.0, 0.3), np.full(90, 3.0), angles, 8.0)
    assert np.array_equal(grid.log_odds, before)
    grid.insert_scan((-3.0, 0.0, 0.0), np.full(90, 2.0), angles, 8.0)
    other = LogOddsGrid((-10.0, -10.0), 0.1, (200, 200))
    for pose, r in (((0.0, 0.0, 0.0), 4.0), ((2.0, 1.0, 0.3), 3.0)):
        other.insert_scan(pose, np.full(90, r), angles, 8.0)
    assert np.array_equal(copy_.log_odds, other.log_odds)
    assert not np.array_equal(grid.log_odds, copy_.log_odds)


def test_shared_copy_queues_scans_until_read():
    """A grid cloned at every update pays one copy per read, not one per inserted scan."""
    angles = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    grid = LogOddsGrid((-10.0, -10.0), 0.1, (200, 200))
    grid.insert_scan((0.0, 0.0, 0.0), np.full(90, 4.0), angles, 8.0)
    copy_ = grid.shared_copy()
    ranges = np.full(90, 3.0)
    for x in (1.0, 2.0, 3.0):
        copy_ = copy_.shared_copy()  # as Drake's clone at every update
        copy_.insert_scan((x, 0.0, 0.0), ranges, angles, 8.0)
    ranges[:] = 1.0  # the caller reuses its array: the queued scans must not change
    assert np.shares_memory(copy_._sum, grid._sum)  # queued, not yet applied
    other = LogOddsGrid((-10.0, -10.0), 0.1, (200, 200))
    for x, r in ((0.0, 4.0), (1.0, 3.0), (2.0, 3.0), (3.0, 3.0)):
        other.insert_scan((x, 0.0, 0.0), np.full(90, r), angles, 8.0)
    assert np.array_equal(copy_.log_odds, other.log_odds)
    assert not np.shares_memory(copy_._sum, grid._sum)
    assert grid.observed.sum() < copy_.observed.sum()


@pytest.mark.parametrize(
    "occupied_above, free_below", [(0.6, 0.4), (0.5, 0.5), (0.99, 0.01), (0.1, 0.95), (1.0, 0.0)]
)
def test_occupancy_grid_classes_equal_the_probability_thresholds(occupied_above, free_below):
    """The integer-space classification equals thresholding 1 / (1 + exp(−clamped l)), also
    for thresholds beyond the clamp (p ≈ 0.12 … 0.97)."""
    rng = np.random.default_rng(3)
    grid = LogOddsGrid((0.0, 0.0), 0.1, (60, 70))
    grid._sum[:] = rng.integers(-40000, 50000, size=grid.shape)
    grid._count[:] = rng.integers(0, 3, size=grid.shape)
    p = grid.probability()
    want = np.full(grid.shape, OccupancyGrid.UNKNOWN, np.int8)
    want[p < free_below] = OccupancyGrid.FREE
    want[p > occupied_above] = OccupancyGrid.OCCUPIED
    want[grid._count == 0] = OccupancyGrid.UNKNOWN
    got = grid.to_occupancy_grid(occupied_above, free_below).data
    assert np.array_equal(got, want)
    if 0.12 < free_below <= occupied_above < 0.97:  # thresholds inside the clamp: all three
        assert set(np.unique(want)) == {-1, 0, 100}


def test_occupancy_classes_are_updated_only_where_scans_changed_them():
    """to_occupancy_grid keeps its classes and reclassifies only the windows scans touched
    since: after insertions, a removal and a shared copy written on either side, every read
    equals the classes of a grid built afresh from the same scans."""
    angles = np.linspace(-np.pi, np.pi, 120, endpoint=False)

    def fresh(scans, *thresholds):
        g = LogOddsGrid((-10.0, -10.0), 0.1, (200, 200))
        for pose, r in scans:
            g.insert_scan(pose, np.full(120, r), angles, 8.0)
        return g.to_occupancy_grid(*thresholds).data

    grid = LogOddsGrid((-10.0, -10.0), 0.1, (200, 200))
    scans = [((0.0, 0.0, 0.0), 4.0)]
    grid.insert_scan((0.0, 0.0, 0.0), np.full(120, 4.0), angles, 8.0)
    assert np.array_equal(grid.to_occupancy_grid().data, fresh(scans))
    for pose, r in (((3.0, 1.0, 0.2), 2.5), ((-4.0, -2.0, 1.0), 6.0)):
        grid.insert_scan(pose, np.full(120, r), angles, 8.0)
        scans.append((pose, r))
    first = grid.to_occupancy_grid()
    assert np.array_equal(first.data, fresh(scans))
    grid.remove_scan((3.0, 1.0, 0.2), np.full(120, 2.5), angles, 8.0)
    scans.pop(1)
    copy_ = grid.shared_copy()
    copy_.insert_scan((5.0, 5.0, 0.0), np.full(120, 1.5), angles, 8.0)
    assert np.array_equal(grid.to_occupancy_grid().data, fresh(scans))
    assert np.array_equal(copy_.to_occupancy_grid().data, fresh([*scans, ((5.0, 5.0, 0.0), 1.5)]))
    assert np.array_equal(grid.to_occupancy_grid().data, fresh(scans))  # the copy's scan unseen
    assert np.array_equal(first.data, fresh(scans[:1] + [((3.0, 1.0, 0.2), 2.5)] + scans[1:]))
    # other thresholds: classified anew
    assert np.array_equal(grid.to_occupancy_grid(0.9, 0.1).data, fresh(scans, 0.9, 0.1))


def test_a_copy_whose_sharer_is_gone_writes_in_place():
    """Copy on write only while another grid still holds the arrays: Drake drops the state a
    clone replaced, and a read of the clone then needs no copy of the (large) arrays."""
    angles = np.linspace(-np.pi, np.pi, 90, endpoint=False)
    grid = LogOddsGrid((-10.0, -10.0), 0.1, (200, 200))
    grid.insert_scan((0.0, 0.0, 0.0), np.full(90, 4.0), angles, 8.0)
    assert grid.observed.any()  # applied
    clone = grid.shared_copy()
    clone.insert_scan((1.0, 0.0, 0.0), np.full(90, 3.0), angles, 8.0)
    before = weakref.ref(clone._sum)  # (a plain reference would be a holder itself)
    del grid  # the state the clone replaced
    assert clone.observed.sum() > 0 and clone._sum is before()  # written in place, no copy
    kept = clone.shared_copy()
    clone.insert_scan((2.0, 0.0, 0.0), np.full(90, 3.0), angles, 8.0)
    assert clone.observed.sum() > 0
    assert clone._sum is not kept._sum and kept._sum is before()  # the sharer is alive: copied
