"""Small synthetic scenes for tests and benchmarks of scan matching (not worlds to sail in)."""

import numpy as np

from usvdrake.worlds.raycast import ColumnLayout, Scene, cast
from usvdrake.worlds.solids import box, cylinder

# The Hokuyo UTM-30LX beam layout: 270°, 0.25°, 1081 beams.
HOKUYO = ColumnLayout(np.deg2rad(-135.0), np.deg2rad(0.25), 1081)


def cluttered_room() -> Scene:
    """A 24 × 14 m room with boats, a block and posts: PLICP is well constrained anywhere."""
    return Scene.from_solids(
        [
            box("wall", 0, 7, 24, 0.3, 0, -1, 3),
            box("wall", 0, -7, 24, 0.3, 0, -1, 3),
            box("wall", 12, 0, 0.3, 14, 0, -1, 3),
            box("wall", -12, 0, 0.3, 14, 0, -1, 3),
            box("boat", 5, 3, 3, 1.2, 0.4, -1, 2),
            box("boat", -6, -3, 4, 1.5, -0.7, -1, 2),
            box("quay", 7, -4, 2, 2, 0.2, -1, 2),
            box("boat", -1, 5.5, 2.5, 0.8, 0.0, -1, 2),
            cylinder("post", -3, 4, 0.3, -1, 3),
            cylinder("post", 2, -4.5, 0.5, -1, 3),
            cylinder("post", -8, 2, 0.4, -1, 3),
        ]
    )


def noisy_scan_pairs(count: int, seed: int = 0, noise: float = 0.01) -> list[tuple]:
    """``count`` pairs of Hokuyo scans of :func:`cluttered_room` from poses 0-0.5 m and 0-10°
    apart, ranges with ``noise`` [m] Gaussian noise: (points 1 (N × 2), points 2 (M × 2), pose 1,
    pose 2), points in each scan's sensor frame, poses (x, y, θ) in the room."""
    scene, rng = cluttered_room(), np.random.default_rng(seed)
    out = []
    for _ in range(count):
        p1 = np.array([rng.uniform(-3, 3), rng.uniform(-2, 2), rng.uniform(-np.pi, np.pi)])
        d, ang = rng.uniform(0, 0.5), rng.uniform(0, 2 * np.pi)
        p2 = p1 + [d * np.cos(ang), d * np.sin(ang), rng.uniform(-0.17, 0.17)]
        pts = []
        for p in (p1, p2):
            r = cast(scene, HOKUYO, [0.0], p[:2], 1.0, p[2], 30.0)[0]
            ok = np.isfinite(r)
            r = r[ok] + rng.normal(0.0, noise, ok.sum())
            a = HOKUYO.azimuths[ok]
            pts.append(np.column_stack([r * np.cos(a), r * np.sin(a)]))
        out.append((pts[0], pts[1], p1, p2))
    return out
