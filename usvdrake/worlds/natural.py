"""Lakes with natural shores for 2D lidar SLAM (Pham et al., §V): the 200 m × 200 m Gazebo valley of
§V-B and Phu Tho lake in Ho Chi Minh City of §V-C.

A lake's water is a star-shaped polygon around the origin (the lake's middle), its radius a
smooth random function of the bearing, r(θ) = 1 + Σ_k a_k cos(kθ + φ_k), stretched to the
lake's half-axes. The bank is a strip of convex quadrilaterals between the water's edge and an
outward offset, one per shore vertex, reaching from below the water to 1-3 m above it, so that a
horizontal beam leaving the water in any direction meets it (like the quay strip of
``usvdrake.worlds.canal``). Clutter stands at random arc lengths along the shore, placed by its
signed distance across the water's edge (negative: in the water): rocks (random convex polygons),
trees (tall cylinders), bushes (cylinders and convex prisms) and, at Phu Tho, leaves overhanging
the water. Everything random comes from ``numpy.random.default_rng(seed)``.

Pham et al. gives the worlds' sizes and sensors but no geometry (its figures were lost in the text
extraction): every size, count and height below is a guess, stated with its reason. Counts are
kept such that a 1081-beam Hokuyo scan from 10-30 m off the valley's shore casts well within
1 ms (~1500 (solid, beam) pairs, ~0.4 ms; the ray caster's cost grows with that number).

The local frame's origin is each lake's middle; x east, y north, z up from the water.
"""

import numpy as np
import shapely

from usvdrake.worlds.solids import Solid, box, cylinder, prism
from usvdrake.worlds.world import World


def _radial(rng: np.random.Generator, theta: np.ndarray, harmonics: int, amplitude: float):
    """A smooth random periodic function of θ with mean 0: Σ_k a_k cos(kθ + φ_k) over
    k = 2..harmonics, a_k falling like k^-1.5 and scaled so that Σ|a_k| = ``amplitude``."""
    k = np.arange(2, harmonics + 1)
    a = rng.uniform(0.5, 1.0, len(k)) * k**-1.5
    a *= amplitude / a.sum()
    phase = rng.uniform(0.0, 2 * np.pi, len(k))
    return np.cos(np.outer(theta, k) + phase) @ a


def _shore(
    rng: np.random.Generator,
    half_axes: tuple[float, float],
    amplitude: float,
    roughness: float,
    step: float,
) -> np.ndarray:
    """The water's edge: a counter-clockwise ring (n × 2, first ≠ last), vertices ~``step`` [m]
    apart, star-shaped around the origin. ``amplitude``: relative size of the bays and points
    (harmonics 2-7); ``roughness``: relative size of the small wiggles (harmonics 8-30)."""
    ax, ay = half_axes
    perimeter = np.pi * (3 * (ax + ay) - np.sqrt((3 * ax + ay) * (ax + 3 * ay)))  # Ramanujan
    n = int(np.ceil(perimeter / step))
    theta = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    r = 1.0 + _radial(rng, theta, 7, amplitude)
    fine = np.arange(8, 31)
    r += np.cos(np.outer(theta, fine) + rng.uniform(0, 2 * np.pi, len(fine))) @ (
        rng.uniform(-1.0, 1.0, len(fine)) * roughness / np.sqrt(len(fine))
    )
    return np.column_stack([ax * r * np.cos(theta), ay * r * np.sin(theta)])


def _outward_normals(ring: np.ndarray) -> np.ndarray:
    """Unit normals at each vertex of a counter-clockwise ring, pointing out of the water."""
    e = np.roll(ring, -1, axis=0) - np.roll(ring, 1, axis=0)
    n = np.column_stack([e[:, 1], -e[:, 0]])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _convex(points: np.ndarray) -> np.ndarray:
    """The convex hull of points (k × 2), as the prism footprint it covers."""
    hull = shapely.convex_hull(shapely.MultiPoint(points))
    return np.asarray(hull.exterior.coords)[:-1]


def _bank(ring: np.ndarray, thickness: float, heights: np.ndarray) -> list[Solid]:
    """Bank pieces between the water's edge and its offset by ``thickness`` [m]: quadrilateral i
    spans vertices i and i+1 and rises to ``heights[i]`` [m]. A quadrilateral bent at a tight
    turn is replaced by its convex hull, which still covers it (neighbours may overlap)."""
    outer = ring + thickness * _outward_normals(ring)
    solids = []
    for i in range(len(ring)):
        j = (i + 1) % len(ring)
        quad = np.array([ring[i], ring[j], outer[j], outer[i]])
        e = np.roll(quad, -1, axis=0) - quad
        cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
        if not np.all(cross > 1e-9):
            quad = _convex(quad)
        solids.append(prism("bank", quad, -1.0, heights[i]))
    return solids


def _along_shore(ring: np.ndarray, rng: np.random.Generator, count: int):
    """``count`` points at uniformly random arc length on the ring, with the outward normal of
    the edge each lies on: (points, normals), both (count × 2)."""
    e = np.roll(ring, -1, axis=0) - ring
    length = np.linalg.norm(e, axis=1)
    s = rng.uniform(0.0, length.sum(), count)
    i = np.minimum(np.searchsorted(np.cumsum(length), s), len(ring) - 1)
    f = (s - (np.cumsum(length) - length)[i]) / length[i]
    n = np.column_stack([e[i, 1], -e[i, 0]]) / length[i, None]
    return ring[i] + f[:, None] * e[i], n


def _blob(rng: np.random.Generator, x: float, y: float, radius: float) -> np.ndarray:
    """An irregular convex footprint: the hull of 5-6 points at random bearings and 60-100 % of
    ``radius`` [m] from (x, y) (at most 6 vertices keeps the ray caster's padded edge arrays
    small)."""
    k = int(rng.integers(5, 7))
    a = np.sort(rng.uniform(0.0, 2 * np.pi, k))
    r = radius * rng.uniform(0.6, 1.0, k)
    return _convex(np.column_stack([x + r * np.cos(a), y + r * np.sin(a)]))


def _rock(rng: np.random.Generator, x: float, y: float, radius: float, top: float) -> Solid:
    """A boulder from below the water up to ``top`` [m]."""
    return prism("rock", _blob(rng, x, y, radius), -1.0, top)


def _bush(rng: np.random.Generator, x: float, y: float, radius: float, top: float) -> Solid:
    """A bush from the water's surface (or the bank's foot) up to ``top`` [m]: half are
    cylinders, half irregular convex prisms."""
    if rng.uniform() < 0.5:
        return cylinder("bush", x, y, radius, 0.0, top)
    return prism("bush", _blob(rng, x, y, radius), 0.0, top)


def _shore_clutter(
    rng: np.random.Generator,
    ring: np.ndarray,
    rocks: int,
    trees: int,
    bushes: int,
    offshore_rocks: int,
) -> list[Solid]:
    """Rocks straddling the water's edge (and ``offshore_rocks`` a few metres out), trees at
    the edge and on the bank, bushes along the edge."""
    solids = []
    p, n = _along_shore(ring, rng, rocks + offshore_rocks)
    radius = np.exp(rng.uniform(np.log(0.3), np.log(2.0), len(p)))  # many small, few large
    offset = rng.uniform(-0.8, 0.8, len(p)) * radius
    offset[rocks:] = -(radius[rocks:] + rng.uniform(1.0, 8.0, offshore_rocks))
    for q, m, r, d in zip(p, n, radius, offset, strict=True):
        c = q + d * m
        solids.append(_rock(rng, c[0], c[1], r, max(0.2, r * rng.uniform(0.4, 1.0))))
    p, n = _along_shore(ring, rng, trees)
    radius = rng.uniform(0.15, 0.5, trees)
    offset = rng.uniform(-0.5, 4.0, trees)
    for q, m, r, d in zip(p, n, radius, offset, strict=True):
        c = q + d * m
        solids.append(cylinder("tree", c[0], c[1], r, -0.5, rng.uniform(5.0, 15.0)))
    p, n = _along_shore(ring, rng, bushes)
    radius = rng.uniform(0.25, 1.0, bushes)  # 0.5-2 m across
    offset = rng.uniform(-0.5, 1.0, bushes) * radius
    for q, m, r, d in zip(p, n, radius, offset, strict=True):
        c = q + d * m
        solids.append(_bush(rng, c[0], c[1], r, rng.uniform(0.5, 2.0)))
    return solids


def _islands(
    rng: np.random.Generator, ring: np.ndarray, count: int, keep_out: float
) -> list[Solid]:
    """``count`` rocky islets 4-8 m across, each with a tree or a bush, 40-70 % of the way
    from the middle to the shore, at least 30 m apart, 10 m from the shore and ``keep_out`` [m]
    from the middle (which stays open water)."""
    shore = shapely.Polygon(ring)
    solids, centres = [], []
    for _ in range(50 * count):
        if len(centres) == count:
            break
        i = int(rng.integers(len(ring)))
        c = ring[i] * rng.uniform(0.4, 0.7)
        r = rng.uniform(2.0, 4.0)
        if np.linalg.norm(c) - r < keep_out or any(np.linalg.norm(c - o) < 30.0 for o in centres):
            continue
        if shore.exterior.distance(shapely.Point(c)) < r + 10.0:
            continue
        centres.append(c)
        solids.append(_rock(rng, c[0], c[1], r, rng.uniform(1.5, 4.0)))
        a = rng.uniform(0.0, 2 * np.pi)
        t = c + 0.4 * r * np.array([np.cos(a), np.sin(a)])
        if rng.uniform() < 0.5:
            solids.append(cylinder("tree", t[0], t[1], rng.uniform(0.2, 0.4), 0.0, 10.0))
        else:
            solids.append(_bush(rng, t[0], t[1], rng.uniform(0.5, 1.0), rng.uniform(2.5, 5.0)))
    return solids


def _leaves(rng: np.random.Generator, c: np.ndarray, m: np.ndarray, r: float) -> list[Solid]:
    """4-10 leaf clumps hanging over the water in front of a bush of radius ``r`` [m] at ``c``
    (``m``: the shore's outward normal): up to 1.5 m beyond the bush, 0.2-1.5 m above the water,
    2-30 cm across and 5-30 cm tall; half small boxes, half small cylinders."""
    t = np.array([-m[1], m[0]])  # along the shore
    k = int(rng.integers(4, 11))
    out = rng.uniform(0.0, r + 1.5, k)  # towards the water
    side = rng.uniform(-r, r, k)
    size = rng.uniform(0.02, 0.3, k)
    aspect = rng.uniform(0.3, 1.0, k)
    yaw = rng.uniform(0.0, np.pi, k)
    z0 = rng.uniform(0.2, 1.5, k)
    z1 = z0 + rng.uniform(0.05, 0.3, k)
    boxes = rng.uniform(size=k) < 0.5
    xy = c - out[:, None] * m + side[:, None] * t
    return [
        box("leaf", x, y, a, a * f, w, lo, hi) if b else cylinder("leaf", x, y, a / 2, lo, hi)
        for (x, y), a, f, w, lo, hi, b in zip(xy, size, aspect, yaw, z0, z1, boxes, strict=True)
    ]


def valley(seed: int = 0) -> World:
    """The Gazebo valley of Pham et al. §V-B ("a valley of size 200x200m"): about 200 m × 200 m of
    water inside an irregular natural shore.

    Guessed, to look like a valley lake and to suit the simulated 60 m, 270° lidar: bays and
    points of ±25 % of the 100 m radius plus ±2 % wiggles, a 3 m bank rising 1-3 m above the
    water, 90 rocks straddling the shore and 12 a few metres out, 120 trees, 150 bushes and 4
    rocky islets in the middle ring: with ~630 m of shore, a piece of clutter every 1.7 m. A
    Hokuyo scan from 10-30 m off the shore then holds ~1500 (solid, beam) pairs (~0.5 ms)."""
    rng = np.random.default_rng(seed)
    ring = _shore(rng, (100.0, 100.0), amplitude=0.25, roughness=0.02, step=6.0)
    theta = np.arctan2(ring[:, 1], ring[:, 0])
    heights = 2.0 + _radial(rng, theta, 5, 1.0)  # 1-3 m
    solids = _bank(ring, 3.0, heights)
    solids += _shore_clutter(rng, ring, rocks=90, trees=120, bushes=150, offshore_rocks=12)
    solids += _islands(rng, ring, 4, keep_out=25.0)
    return World(
        name="valley",
        seed=seed,
        solids=solids,
        water=shapely.Polygon(ring),
        # Pham et al. is from Vietnam; the Gazebo world has no place of its own
        datum="ho_chi_minh_city",
        description=(
            "~200 m x 200 m valley lake with an irregular shore of rocks, trees and bushes and "
            "four rocky islets (Pham et al. §V-B)"
        ),
    )


def phu_tho_lake(seed: int = 0) -> World:
    """Phu Tho lake, Ho Chi Minh City (Pham et al. §V-C): a lake shore "cluttered with leaves and
    bushes" that the USV2000 followed closely with a Hokuyo UTM-30LX.

    Guessed: about 150 m × 100 m (a park lake; Pham et al. gives no size), a 2 m bank 0.8-1.2 m
    above the water, a bush every ~2.5 m of shore and trees every ~10 m, and in front of each bush
    4-10 "leaf" solids (2-30 cm across, 5-30 cm tall) hanging over the water 0.2-1.5 m up and up to
    1.5 m out from the bush: a horizontal scan at 0.3-0.6 m cuts some of them, so short-range
    returns are scattered and change with the sensor's height and position, as Pham et al.
    describes."""
    rng = np.random.default_rng(seed)
    ring = _shore(rng, (75.0, 50.0), amplitude=0.15, roughness=0.015, step=4.0)
    heights = rng.uniform(0.8, 1.2, len(ring))
    solids = _bank(ring, 2.0, heights)
    perimeter = float(np.sum(np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1)))
    solids += _shore_clutter(
        rng, ring, rocks=0, trees=int(perimeter / 10.0), bushes=0, offshore_rocks=0
    )
    p, n = _along_shore(ring, rng, int(perimeter / 2.5))
    for q, m in zip(p, n, strict=True):
        r = rng.uniform(0.3, 1.0)
        c = q + rng.uniform(-0.5, 0.5) * r * m
        solids.append(_bush(rng, c[0], c[1], r, rng.uniform(0.5, 1.8)))
        solids += _leaves(rng, c, m, r)
    return World(
        name="phu_tho_lake",
        seed=seed,
        solids=solids,
        water=shapely.Polygon(ring),
        datum="ho_chi_minh_city",
        description=(
            "~150 m x 100 m park lake whose shore is dense with bushes, trees and overhanging "
            "leaves (Pham et al. §V-C)"
        ),
    )
