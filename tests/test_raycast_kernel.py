"""The compiled ray caster against an independent reference: the previous vectorised numpy
caster (kept here, every solid × every column, no culling, no occlusion skip), on the shipped
worlds, standing and moving, 2D and 3D; and the culling's fast arctangent against numpy's."""

import numpy as np
import pytest

from usvdrake.sensors.lidar_model import body_motion
from usvdrake.worlds import make_world
from usvdrake.worlds.raycast import ATAN_ERR, ColumnLayout, Scene, _fast_atan2, _pairs, cast
from usvdrake.worlds.solids import box, cylinder


def _packed(solids):
    """Per-solid arrays with the polygons' edge half-planes padded to a common count."""
    n = len(solids)
    k = max([len(s.polygon) for s in solids if s.polygon is not None] + [3])
    edge_n, edge_d = np.zeros((n, k, 2)), np.ones((n, k))  # padding: 0·p ≤ 1, always true
    cyl, cut = np.zeros((n, 3)), np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    is_cyl = np.array([s.is_cylinder for s in solids], bool)
    for i, s in enumerate(solids):
        if s.is_cylinder:
            cyl[i] = s.circle
        else:
            normals, offsets = s.edge_planes()
            edge_n[i, : len(offsets)], edge_d[i, : len(offsets)] = normals, offsets
        if s.cut is not None:
            cut[i] = s.cut
    z = np.array([(s.z_min, s.z_max) for s in solids])
    return edge_n, edge_d, cyl, cut, is_cyl, z


def reference_cast(solids, layout, tan_e, origins, z_s, headings, max_range, min_range, water=0.0):
    """Ranges (rings × columns) of beams from per-column origins (C × 2) and headings (C)."""
    edge_n, edge_d, cyls, cuts, is_cyl, z = _packed(solids)
    tan_e = np.asarray(tan_e, float)
    cos_e = 1.0 / np.sqrt(1.0 + tan_e**2)
    rings, cols = len(tan_e), layout.count
    out = np.full(rings * cols, np.inf)
    solid = np.repeat(np.arange(len(solids)), cols)
    col = np.tile(np.arange(cols), len(solids))
    az = layout.az0 + layout.daz * col + headings[col]
    h, o = np.column_stack([np.cos(az), np.sin(az)]), origins[col]
    # Cyrus-Beck clipping of o + t h against the footprint's edges; circles by their quadratic.
    nx, ny = edge_n[solid, :, 0], edge_n[solid, :, 1]
    den = nx * h[:, 0:1] + ny * h[:, 1:2]
    num = edge_d[solid] - nx * o[:, 0:1] - ny * o[:, 1:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    t_in = np.max(t, axis=1, where=den < 0, initial=-np.inf)
    t_out = np.min(t, axis=1, where=den > 0, initial=np.inf)
    parallel_out = ((den == 0) & (num < 0)).any(axis=1)
    t_in[parallel_out], t_out[parallel_out] = np.inf, -np.inf
    c = is_cyl[solid]
    f = o[c] - cyls[solid[c], :2]
    b = np.einsum("ij,ij->i", f, h[c])
    disc = b * b - (np.einsum("ij,ij->i", f, f) - cyls[solid[c], 2] ** 2)
    root = np.sqrt(np.maximum(disc, 0.0))
    t_in[c] = np.where(disc < 0, np.inf, -b - root)
    t_out[c] = np.where(disc < 0, -np.inf, -b + root)
    # Each ring's z slab, in horizontal distance; level beams are all-or-nothing.
    zl, zh = z[solid, 0] - z_s, z[solid, 1] - z_s
    enter, leave = np.empty((len(solid), rings)), np.empty((len(solid), rings))
    for r, te in enumerate(tan_e):
        if te == 0.0:
            level = (zl <= 0) & (zh >= 0)
            enter[:, r] = np.where(level, t_in, np.inf)
            leave[:, r] = np.where(level, t_out, -np.inf)
        else:
            lo, hi = (zl, zh) if te > 0 else (zh, zl)
            enter[:, r] = np.maximum(lo / te, t_in)
            leave[:, r] = np.minimum(hi / te, t_out)
        cut = cuts[solid]
        cden = cut[:, 0] * h[:, 0] + cut[:, 1] * h[:, 1] + cut[:, 2] * te
        cnum = cut[:, 3] - (cut[:, 0] * o[:, 0] + cut[:, 1] * o[:, 1]) - cut[:, 2] * z_s
        with np.errstate(divide="ignore", invalid="ignore"):
            ct = cnum / cden
        enter[:, r] = np.where(cden < 0, np.maximum(enter[:, r], ct), enter[:, r])
        leave[:, r] = np.where(cden > 0, np.minimum(leave[:, r], ct), leave[:, r])
        leave[(cden == 0) & (cnum < 0), r] = -np.inf
    limit = max_range * cos_e
    if water is not None and z_s > water:
        with np.errstate(divide="ignore"):
            limit = np.minimum(limit, np.where(tan_e < 0, (water - z_s) / tan_e, np.inf))
    enter, leave = np.maximum(enter, 0.0), np.minimum(leave, limit)
    p, r = np.nonzero(enter <= leave)
    np.minimum.at(out, r * cols + col[p], enter[p, r] / cos_e[r])
    out[out <= min_range] = np.inf
    return out.reshape(rings, cols)


def near_solids(world, centre, reach):
    """The solids whose bounding circle comes within ``reach`` of ``centre`` (a cull so loose
    it cannot matter; it keeps the reference's every-pair arrays small)."""
    return [
        s
        for s in world.solids
        if np.hypot(*(np.array(s.bounding_circle()[:2]) - centre)) - s.bounding_circle()[2] < reach
    ]


LAYOUTS = {
    "hokuyo": (ColumnLayout(np.deg2rad(-135), np.deg2rad(0.25), 1081), [0.0], 0.5, 60.0, 0.1),
    # a VLP-16's span at half its columns and rings: the every-pair reference is the slow part
    "vlp16_cw": (
        ColumnLayout(np.pi, -np.deg2rad(0.8), 450),
        np.tan(np.deg2rad(np.arange(-15.0, 15.1, 4.0))),
        1.0,
        100.0,
        0.5,
    ),
}


@pytest.mark.parametrize("layout_name", sorted(LAYOUTS))
@pytest.mark.parametrize(
    "world_name", ["ntnu_basin", "valley", "phu_tho_lake", "canal_demo", "amsterdam_canals"]
)
def test_kernel_matches_numpy_reference_on_shipped_worlds(world_name, layout_name):
    """Same hits, ranges within 1e-9 m (in practice bit for bit), from free-water poses,
    with the sweep's motion and without."""
    layout, tan_e, z, max_range, min_range = LAYOUTS[layout_name]
    world = make_world(world_name, 0)
    rng = np.random.default_rng(11)
    xmin, ymin, xmax, ymax = world.water.bounds
    hits = tested = 0
    while tested < 3:
        x, y = rng.uniform(xmin, xmax), rng.uniform(ymin, ymax)
        if not world.is_free(x, y, margin=0.5):
            continue
        tested += 1
        q = np.array([x, y, rng.uniform(-np.pi, np.pi), 2.0, 0.3, 0.4])
        dt = np.arange(layout.count) / layout.count * 0.1 - 0.1
        pos, psi = body_motion(q, dt)
        ref = layout.count // 2
        solids = near_solids(world, pos[ref], max_range + 2.0)
        for moving in (False, True):
            origins = pos if moving else np.broadcast_to(pos[ref], pos.shape)
            headings = psi if moving else np.full(layout.count, psi[ref])
            kw = {"column_origin_xy": pos, "column_heading": psi} if moving else {}
            fast = cast(
                world.scene, layout, tan_e, pos[ref], z, psi[ref], max_range, min_range, **kw
            )
            slow = reference_cast(solids, layout, tan_e, origins, z, headings, max_range, min_range)
            np.testing.assert_array_equal(np.isfinite(fast), np.isfinite(slow))
            hit = np.isfinite(fast)
            np.testing.assert_allclose(fast[hit], slow[hit], rtol=0, atol=1e-9)
            hits += int(hit.sum())
    assert hits > 100  # the poses see something: the comparison is not vacuous


def test_fast_atan2_error_within_the_culling_allowance():
    """Up to three fast angles add into one culling span (two corner bearings and the motion's
    widening): each must be well within ATAN_ERR / 3 of numpy's arctan2, in every octant."""
    a = np.linspace(-np.pi, np.pi, 20001)
    for r in (1e-6, 1.0, 1e4):
        x, y = r * np.cos(a), r * np.sin(a)
        fast = np.array([_fast_atan2(yy, xx) for xx, yy in zip(x, y, strict=True)])
        err = np.abs(np.angle(np.exp(1j * (fast - np.arctan2(y, x)))))
        assert err.max() < ATAN_ERR / 3
    assert _fast_atan2(0.0, 0.0) == 0.0


def test_occluded_solids_skipped_without_changing_ranges():
    """A row of posts behind a wall, and one in front of it: the nearest-first skip leaves the
    ranges equal to casting every solid at every column."""
    solids = [box("wall", 10.0, 0.0, 1.0, 30.0, 0.0, -1.0, 2.0)]
    solids += [cylinder("post", 14.0, y, 0.3, -1.0, 3.0) for y in np.linspace(-10, 10, 21)]
    solids.append(cylinder("post", 5.0, 1.0, 0.4, -1.0, 3.0))
    scene = Scene.from_solids(solids)
    layout = ColumnLayout(-np.pi, np.deg2rad(0.25), 1440)
    tan_e = np.tan(np.deg2rad([-2.0, 0.0, 10.0]))
    fast = cast(scene, layout, tan_e, np.zeros(2), 0.5, 0.2, 50.0)
    slow = cast(scene, layout, tan_e, np.zeros(2), 0.5, 0.2, 50.0, cull=False)
    np.testing.assert_array_equal(fast, slow)
    assert np.isfinite(fast[1]).sum() > 100
    # The wall's face at x = 9.5 is what the level beams see, except behind the near post.
    az = layout.azimuths + 0.2
    front = (np.abs(az) < np.arctan2(14.0, 9.5)) & np.isfinite(fast[1])
    assert np.all(fast[1][front] <= 9.5 / np.cos(az[front]) + 1e-9)


def test_pairs_cover_every_hit():
    """Every (solid, column) that returns the nearest hit is in the culling's pair list."""
    world = make_world("valley", 0)
    layout = ColumnLayout(np.deg2rad(-135), np.deg2rad(0.25), 1081)
    solid, col = _pairs(world.scene, np.zeros(2), 0.3, layout, 60.0, 0.0, layout.daz)
    covered = set(zip(solid.tolist(), col.tolist(), strict=True))
    for s in range(len(world.solids)):
        one = Scene.from_solids([world.solids[s]])
        r = cast(one, layout, [0.0], np.zeros(2), 0.5, 0.3, 60.0, cull=False)[0]
        for c in np.nonzero(np.isfinite(r))[0]:
            assert (s, int(c)) in covered


def test_empty_scene_and_sensor_inside():
    layout = ColumnLayout(0.0, 0.1, 10)
    assert np.all(np.isinf(cast(Scene.from_solids([]), layout, [0.0], np.zeros(2), 0.5, 0.0, 9.0)))
    inside = Scene.from_solids([box("quay", 0.0, 0.0, 4.0, 4.0, 0.0, -1.0, 2.0)])
    assert np.all(np.isinf(cast(inside, layout, [0.0, 0.1], np.zeros(2), 0.5, 0.0, 9.0)))
