"""Ray casting: exact ranges against analytic shapes (circle, box, plane), occlusion, culling."""

import numpy as np
import pytest

from usvdrake.worlds.raycast import ColumnLayout, Scene, cast
from usvdrake.worlds.solids import box, cylinder, prism

FULL = ColumnLayout(az0=-np.pi, daz=2 * np.pi / 720, count=720)


def scan2d(solids, origin=(0.0, 0.0), z=0.5, heading=0.0, layout=FULL, max_range=100.0, **kw):
    return cast(
        Scene.from_solids(solids), layout, [0.0], np.array(origin), z, heading, max_range, **kw
    )[0]


def test_circle_every_range_is_exact():
    """A cylinder seen from outside: the range is the smaller root of |o + t h − c| = R."""
    c, r = np.array([7.0, -3.0]), 2.5
    ranges = scan2d([cylinder("rock", c[0], c[1], r, -1.0, 2.0)], origin=(0.3, 0.4))
    az = FULL.azimuths
    o = np.array([0.3, 0.4])
    f = o - c
    b = np.cos(az) * f[0] + np.sin(az) * f[1]
    disc = b**2 - (f @ f - r**2)
    expected = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    expected = np.where(expected > 0, expected, np.inf)
    hit = np.isfinite(expected)
    assert hit.sum() > 20
    np.testing.assert_array_equal(np.isfinite(ranges), hit)
    np.testing.assert_allclose(ranges[hit], expected[hit], atol=1e-6)


def test_room_of_four_walls_exact():
    """Inside a 20 × 10 m room of four wall boxes: range = distance to the wall plane / cos."""
    walls = [
        box("wall", 10.5, 0, 1, 12, 0, -1, 2),
        box("wall", -10.5, 0, 1, 12, 0, -1, 2),
        box("wall", 0, 5.5, 22, 1, 0, -1, 2),
        box("wall", 0, -5.5, 22, 1, 0, -1, 2),
    ]
    o = np.array([1.0, -2.0])
    r = scan2d(walls, origin=o, heading=0.4)
    az = FULL.azimuths + 0.4
    c, s = np.cos(az), np.sin(az)
    with np.errstate(divide="ignore"):
        tx = np.where(c > 0, (10 - o[0]) / c, np.where(c < 0, (-10 - o[0]) / c, np.inf))
        ty = np.where(s > 0, (5 - o[1]) / s, np.where(s < 0, (-5 - o[1]) / s, np.inf))
    np.testing.assert_allclose(r, np.minimum(tx, ty), atol=1e-6)


def test_box_exact_and_occlusion():
    near = box("boat", 5.0, 0.0, 2.0, 2.0, 0.0, -0.5, 1.0)
    far = box("quay", 20.0, 0.0, 2.0, 40.0, 0.0, -1.0, 1.0)
    layout = ColumnLayout(az0=-0.5, daz=0.001, count=1001)
    r = scan2d([far, near], layout=layout)
    az = layout.azimuths
    front = np.abs(4.0 * np.tan(az)) <= 1.0  # beams through the near box's front face
    np.testing.assert_allclose(r[front], 4.0 / np.cos(az[front]), atol=1e-6)
    back = ~front & (np.abs(az) < 0.45)
    np.testing.assert_allclose(r[back], 19.0 / np.cos(az[back]), atol=1e-6)


def test_beam_over_a_low_solid_and_water_plane():
    """3D: a quay top at z = 1 seen from z = 2 at −10°: range = 1 / sin(10°); a beam that
    misses everything ends at the water: no return."""
    quay = box("quay", 23.0, 0.0, 40.0, 4.0, 0.0, -1.0, 1.0)  # x from 3 to 43
    e = np.deg2rad([-10.0, -60.0, 5.0])
    layout = ColumnLayout(az0=0.0, daz=0.01, count=1)
    r = cast(Scene.from_solids([quay]), layout, np.tan(e), np.zeros(2), 2.0, 0.0, 200.0)[:, 0]
    assert r[0] == pytest.approx(1.0 / np.sin(np.deg2rad(10.0)), abs=1e-6)  # top face at x = 5.67
    side = box("quay", 30.0, 0.0, 40.0, 4.0, 0.0, -1.0, 1.0)  # x from 10: the beam meets the side
    r_side = cast(Scene.from_solids([side]), layout, np.tan(e[:1]), np.zeros(2), 2.0, 0.0, 200.0)[
        0, 0
    ]
    assert r_side == pytest.approx(10.0 / np.cos(np.deg2rad(10.0)), abs=1e-6)
    assert r[1] == np.inf  # −60° hits the water at x = 1.15 m, before the quay
    assert r[2] == np.inf  # upward beam passes over the 1 m quay
    wall = box("building", 30.0, 0.0, 4.0, 4.0, 0.0, 0.0, 15.0)
    r = cast(Scene.from_solids([wall]), layout, np.tan(e[2:]), np.zeros(2), 2.0, 0.0, 200.0)[0, 0]
    assert r == pytest.approx(28.0 / np.cos(np.deg2rad(5.0)), abs=1e-6)


def test_sloped_plane_cut():
    """A wave-generator beach: the box x ∈ [10, 14] cut by the plane z ≤ (x − 10) (45°).
    A horizontal beam at height z hits at x = 10 + z."""
    beach = prism(
        "wall", [[10, -3], [14, -3], [14, 3], [10, 3]], -1.0, 4.0, cut=(-1.0, 0.0, 1.0, -10.0)
    )
    layout = ColumnLayout(az0=0.0, daz=0.01, count=1)
    for z in (0.2, 0.7, 1.5):
        r = cast(Scene.from_solids([beach]), layout, [0.0], np.zeros(2), z, 0.0, 50.0)[0, 0]
        assert r == pytest.approx(10.0 + z, abs=1e-9)


def test_range_limits_and_sensor_inside():
    rock = cylinder("rock", 10.0, 0.0, 1.0, -1.0, 2.0)
    layout = ColumnLayout(az0=0.0, daz=0.01, count=1)
    assert scan2d([rock], layout=layout, max_range=8.0)[0] == np.inf
    assert scan2d([rock], layout=layout, max_range=9.5)[0] == pytest.approx(9.0)
    assert scan2d([rock], layout=layout, min_range=9.5)[0] == np.inf  # too close: no return
    assert scan2d([rock], origin=(10.0, 0.2), layout=layout)[0] == np.inf  # inside: never 0


def test_column_layout_with_fov_and_reverse_direction():
    """A 270° scanner (Hokuyo) and a clockwise scanner see the same box at the same angles."""
    b = box("boat", 0.0, 6.0, 2.0, 2.0, 0.0, -1, 1)  # straight to the left (+y)
    hok = ColumnLayout(az0=np.deg2rad(-135), daz=np.deg2rad(0.25), count=1081)
    r = scan2d([b], layout=hok)
    left = np.argmin(np.abs(hok.azimuths - np.pi / 2))
    assert r[left] == pytest.approx(5.0)
    cw = ColumnLayout(az0=np.pi, daz=-np.deg2rad(1.0), count=360)
    r2 = scan2d([b], layout=cw)
    k = np.argmin(np.abs(np.angle(np.exp(1j * (cw.azimuths - np.pi / 2)))))
    assert r2[k] == pytest.approx(5.0)
    assert np.isfinite(r2).sum() == pytest.approx(
        np.isfinite(scan2d([b], layout=FULL)).sum() / 2, abs=2
    )


def test_moving_sweep_uses_each_columns_origin():
    """With per-column origins, each beam is exact from its own origin."""
    wall = box("wall", 10.5, 0, 1, 40, 0, -1, 2)
    layout = ColumnLayout(az0=-0.3, daz=0.01, count=61)
    origins = np.column_stack([np.linspace(0.0, 1.0, 61), np.zeros(61)])
    r = cast(
        Scene.from_solids([wall]),
        layout,
        [0.0],
        origins.mean(axis=0),
        0.5,
        0.0,
        50.0,
        column_origin_xy=origins,
    )[0]
    np.testing.assert_allclose(r, (10.0 - origins[:, 0]) / np.cos(layout.azimuths), atol=1e-9)


@pytest.mark.parametrize("world_name", ["ntnu_basin", "valley", "phu_tho_lake", "canal_demo"])
def test_culling_never_drops_a_hit(world_name):
    """Against casting every solid at every beam, on the real worlds, standing and moving."""
    from usvdrake.sensors.lidar_model import body_motion
    from usvdrake.worlds import make_world

    world = make_world(world_name, 0)
    rng = np.random.default_rng(7)
    xmin, ymin, xmax, ymax = world.water.bounds
    layout = ColumnLayout(az0=-np.pi, daz=np.deg2rad(0.5), count=720)
    tested = 0
    while tested < 6:
        x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        if not world.is_free(x, y, margin=0.5):
            continue
        tested += 1
        q = np.array([x, y, rng.uniform(-np.pi, np.pi), 2.0, 0.3, 0.4])
        for moving in (False, True):
            kw = {}
            if moving:
                dt = np.arange(layout.count) / layout.count * 0.2 - 0.2
                pos, psi = body_motion(q, dt)
                kw = {"column_origin_xy": pos, "column_heading": psi}
            for z, tan_e in ((0.5, [0.0]), (1.0, np.tan(np.deg2rad([-5.0, 3.0, 15.0])))):
                fast = cast(world.scene, layout, tan_e, q[:2], z, q[2], 60.0, **kw)
                slow = cast(world.scene, layout, tan_e, q[:2], z, q[2], 60.0, cull=False, **kw)
                np.testing.assert_array_equal(fast, slow)
