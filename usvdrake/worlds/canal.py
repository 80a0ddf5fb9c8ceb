"""A canal along a centre-line polyline: quay walls, facades, moored boats and bridges.

The generator is seeded: facade lengths and heights, and where boats are moored, come from
``numpy.random.default_rng(seed)``. The ``canal_demo`` world is a short L-shaped canal with one
bridge, the stage of the demo mission; the full ``amsterdam_canals`` network is built on the same
pieces in the worlds issue.
"""

import numpy as np

from usvdrake.worlds.world import Box, World

QUAY_THICKNESS = 1.0  # [m]
QUAY_HEIGHT = 1.0  # [m] quay top above the water (Amsterdam canals: ~1 m)
STREET_WIDTH = 4.0  # [m] between the quay edge and the facades


def offset_polyline(points: np.ndarray, offset: float) -> np.ndarray:
    """The polyline shifted ``offset`` [m] to its left, with mitred joins."""
    p = np.asarray(points, float)
    d = np.diff(p, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    n = np.stack([-d[:, 1], d[:, 0]], axis=1)
    out = [p[0] + offset * n[0]]
    for i in range(1, len(p) - 1):
        m = n[i - 1] + n[i]
        out.append(p[i] + offset * m / (1.0 + n[i - 1] @ n[i]))
    out.append(p[-1] + offset * n[-1])
    return np.array(out)


def boxes_overlap(a: Box, b: Box) -> bool:
    """Whether two oriented box footprints intersect (separating-axis test)."""

    def corners(bx):
        c, s = np.cos(bx.yaw), np.sin(bx.yaw)
        local = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * [bx.lx / 2, bx.ly / 2]
        return local @ np.array([[c, s], [-s, c]]) + [bx.x, bx.y]

    ca, cb = corners(a), corners(b)
    for yaw in (a.yaw, b.yaw):
        for axis in (np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])):
            pa, pb = ca @ axis, cb @ axis
            if pa.max() <= pb.min() or pb.max() <= pa.min():
                return False
    return True


def _box_along(kind, a, b, width, outward, z_min, z_max, shift=0.0, extend=0.0) -> Box:
    """A box of ``width`` along segment a→b, pushed ``shift`` along the unit ``outward``."""
    d = b - a
    length = np.linalg.norm(d)
    c = (a + b) / 2 + shift * outward
    return Box(
        kind, c[0], c[1], length + 2 * extend, width, float(np.arctan2(d[1], d[0])), z_min, z_max
    )


def canal_world(
    name: str, centre_line, width: float, seed: int, bridges_at=(), boats: int = 3
) -> World:
    rng = np.random.default_rng(seed)
    pts = np.asarray(centre_line, float)
    boxes, water = [], []
    for side in (+1.0, -1.0):
        edge = offset_polyline(pts, side * width / 2)
        for a, b in zip(edge[:-1], edge[1:], strict=True):
            d = (b - a) / np.linalg.norm(b - a)
            outward = side * np.array([-d[1], d[0]])
            boxes.append(
                _box_along(
                    "quay",
                    a,
                    b,
                    QUAY_THICKNESS,
                    outward,
                    -1.0,
                    QUAY_HEIGHT,
                    QUAY_THICKNESS / 2,
                    QUAY_THICKNESS,
                )
            )
            # Facades: a row of buildings of random frontage and height behind the street.
            seg_len = np.linalg.norm(b - a)
            s = 2.0
            while s < seg_len - 4.0:
                frontage = min(rng.uniform(5.0, 9.0), seg_len - 2.0 - s)
                p0, p1 = a + d * s, a + d * (s + frontage)
                depth = 8.0
                shift = QUAY_THICKNESS + STREET_WIDTH + depth / 2
                boxes.append(
                    _box_along(
                        "building", p0, p1, depth, outward, 0.0, rng.uniform(8.0, 18.0), shift
                    )
                )
                s += frontage + 0.3
    # End walls (locks) close the canal so every ray ends somewhere.
    for end, nxt in ((pts[0], pts[1]), (pts[-1], pts[-2])):
        d = (end - nxt) / np.linalg.norm(end - nxt)
        n = np.array([-d[1], d[0]])
        a, b = end - n * (width / 2 + QUAY_THICKNESS), end + n * (width / 2 + QUAY_THICKNESS)
        boxes.append(
            _box_along("wall", a, b, QUAY_THICKNESS, d, -1.0, QUAY_HEIGHT, QUAY_THICKNESS / 2)
        )
    # Water patches, one per segment, overlapping by half a width at the interior joints.
    for i, (a, b) in enumerate(zip(pts[:-1], pts[1:], strict=True)):
        d = (b - a) / np.linalg.norm(b - a)
        a = a - d * (width / 2 if i > 0 else 0.0)
        b = b + d * (width / 2 if i < len(pts) - 2 else 0.0)
        water.append(_box_along("water", a, b, width, np.zeros(2), 0.0, 0.0))
    # Moored boats alongside the quays, away from the ends and the corners.
    seg_lengths = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    for _ in range(boats):
        i = int(rng.integers(len(seg_lengths)))
        if seg_lengths[i] < 25.0:
            continue
        t = rng.uniform(10.0, seg_lengths[i] - 10.0)
        a, b = pts[i], pts[i + 1]
        d = (b - a) / seg_lengths[i]
        side = rng.choice([-1.0, 1.0])
        n = side * np.array([-d[1], d[0]])
        beam = rng.uniform(1.6, 2.2)
        centre = a + d * t + n * (width / 2 - beam / 2 - 0.3)
        boxes.append(
            Box(
                "boat",
                centre[0],
                centre[1],
                rng.uniform(5.0, 8.0),
                beam,
                float(np.arctan2(d[1], d[0])),
                -0.4,
                0.6,
            )
        )
    # Bridges: decks across the canal at the given arc lengths, 2.4 m clear above the water.
    cum = np.concatenate([[0.0], np.cumsum(seg_lengths)])
    for s in bridges_at:
        i = min(int(np.searchsorted(cum, s, side="right")) - 1, len(seg_lengths) - 1)
        a, b = pts[i], pts[i + 1]
        d = (b - a) / seg_lengths[i]
        c = a + d * (s - cum[i])
        yaw = float(np.arctan2(d[1], d[0]))
        boxes.append(
            Box(
                "bridge",
                c[0],
                c[1],
                5.0,
                width + 2 * (QUAY_THICKNESS + STREET_WIDTH),
                yaw,
                2.4,
                3.0,
            )
        )
    xy = np.array([[b.x, b.y] for b in boxes])
    lo, hi = xy.min(axis=0) - 15.0, xy.max(axis=0) + 15.0
    return World(
        name=name, seed=seed, boxes=boxes, water=water, bounds=(lo[0], lo[1], hi[0], hi[1])
    )


def canal_demo(seed: int = 0) -> World:
    """An L-shaped canal, 14 m wide, 80 m then 50 m, one bridge: the demo's stage."""
    return canal_world(
        "canal_demo",
        [[-10.0, 0.0], [70.0, 0.0], [70.0, 50.0]],
        width=14.0,
        seed=seed,
        bridges_at=(40.0,),
        boats=3,
    )


def open_water(seed: int = 0) -> World:
    """Unbounded calm water with no obstacles (for identification and control tests)."""
    patch = Box("water", 0.0, 0.0, 400.0, 400.0, 0.0, 0.0, 0.0)
    return World(
        name="open_water", seed=seed, boxes=[], water=[patch], bounds=(-200.0, -200.0, 200.0, 200.0)
    )
