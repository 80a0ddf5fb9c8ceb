"""Worlds: the canal network's promised features, occupancy, free space, GPS-denied zones."""

import numpy as np
import pytest
import shapely

from usvdrake.errors import ConfigError
from usvdrake.worlds import available_worlds, make_world
from usvdrake.worlds.canal import amsterdam_canal_lines, canal_network, centre_line_length


@pytest.fixture(scope="module")
def amsterdam():
    return make_world("amsterdam_canals", seed=0)


def test_amsterdam_has_what_000_describes(amsterdam):
    kinds = [s.kind for s in amsterdam.solids]
    assert kinds.count("bridge") >= 5
    assert (
        kinds.count("boat") >= 10 and kinds.count("building") >= 200 and kinds.count("quay") >= 200
    )
    heights = [s.z_max for s in amsterdam.solids if s.kind == "building"]
    assert min(heights) < 10.0 < 16.0 < max(heights)  # facades of varied height
    # centre line ≥ 2 km: the water's skeleton is at least area / widest canal
    assert amsterdam.water.area / 45.0 > 1000.0
    # at least one closed loop: the water region has a hole (an island between the ring canals)
    polys = list(amsterdam.water.geoms) if hasattr(amsterdam.water, "geoms") else [amsterdam.water]
    assert sum(len(p.interiors) for p in polys) >= 1
    # a river section at least 40 m wide for tracking tests
    river = shapely.Point(np.cos(np.deg2rad(292)) * 600, np.sin(np.deg2rad(292)) * 600)
    assert amsterdam.water.contains(river.buffer(20.0))


def test_centre_line_length():
    assert centre_line_length(amsterdam_canal_lines()) >= 2000.0


def test_gps_denied_under_every_bridge(amsterdam):
    for s in amsterdam.solids:
        if s.kind == "bridge":
            c = s.polygon.mean(axis=0)
            assert amsterdam.gps_denied_at(c[0], c[1])
    assert not amsterdam.gps_denied_at(0.0, 0.0)


def test_sky_blocked_beside_facades_not_in_the_river(amsterdam):
    x, y = 250 * np.cos(np.deg2rad(230)), 250 * np.sin(np.deg2rad(230))  # inner ring canal
    rx, ry = 650 * np.cos(np.deg2rad(292)), 650 * np.sin(np.deg2rad(292))  # the wide river
    assert amsterdam.sky_blocked(x, y) > amsterdam.sky_blocked(rx, ry)


def test_free_space_and_occupancy_agree(amsterdam):
    grid = amsterdam.occupancy(1.0)
    xs, ys = grid.cell_centres()
    rng = np.random.default_rng(1)
    rows = rng.integers(0, grid.shape[0], 400)
    cols = rng.integers(0, grid.shape[1], 400)
    free = amsterdam.is_free(xs[cols], ys[rows], margin=0.5)
    # a cell whose centre is clearly free (0.5 m from any solid) is free in the grid
    assert np.all(grid.data[rows, cols][free] == 0)
    assert (grid.data == 0).sum() > 10_000 and (grid.data == 100).sum() > 10_000


def test_occupancy_any_resolution_marks_a_known_box():
    w = canal_network(
        "t",
        [__import__("usvdrake.worlds.canal", fromlist=["Canal"]).Canal([[0, 0], [50, 0]], 10.0)],
        seed=0,
    )
    for res in (0.1, 0.25, 1.0):
        g = w.occupancy(res, bounds=(-5, -10, 55, 10))
        r, c = g.to_cell(25.0, 0.0)
        assert g.data[r, c] == 0  # mid-canal water
        r, c = g.to_cell(25.0, 5.5)
        assert g.data[r, c] == 100  # inside the quay (5 .. 6 m)


def test_worlds_are_seeded():
    a, b, c = make_world("canal_demo", 0), make_world("canal_demo", 0), make_world("canal_demo", 1)
    za = [s.z_max for s in a.solids]
    assert za == [s.z_max for s in b.solids]
    assert za != [s.z_max for s in c.solids]


def test_unknown_world_is_one_clear_line():
    with pytest.raises(ConfigError, match="amsterdam_canals") as err:
        make_world("atlantis")
    assert "\n" not in str(err.value) and "'atlantis'" in str(err.value)
    assert "canal_demo" in available_worlds()


def test_round_hull_clearance_is_the_same_at_every_heading():
    """Ueland 2017's round vessel: the clearance is the distance to the circle of its top diameter,
    not to the square around it (whose corners stick out 0.11 m further)."""
    from usvdrake.worlds.solids import box
    from usvdrake.worlds.world import World, hull_clearance

    world = World("wall", 0, solids=[box("wall", 0.0, -0.5, 10.0, 1.0, 0.0, -1.0, 1.0)])
    states = [[0.0, 1.0, psi, 0, 0, 0] for psi in np.linspace(0.0, np.pi, 7)]
    round_c = hull_clearance(world, np.array(states), 0.548, 0.548, 0.2, "round")
    np.testing.assert_allclose(round_c, 1.0 - 0.274, atol=2e-3)
    square = hull_clearance(world, np.array(states), 0.548, 0.548, 0.2)
    assert square.min() < 1.0 - 0.274 - 0.1  # the square's corner at 45°
