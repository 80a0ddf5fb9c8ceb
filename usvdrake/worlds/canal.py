"""Canal networks: water from buffered centre lines, quay walls tiling the water's edge,
facades behind a street, moored boats, and bridges (GPS-denied underneath).

The water region is the union of each centre line buffered by half its width (shapely, flat ends,
mitred joins), so junctions and loops come out right. The quay is the strip between the water's
boundary and its outward mitred offset, cut into convex quadrilaterals of at most
``QUAY_PIECE`` m; the facades are quadrilaterals between two further offsets, each with a random
frontage and height. Everything random comes from ``numpy.random.default_rng(seed)``.
"""

from dataclasses import dataclass

import numpy as np
import shapely
from shapely.geometry.polygon import orient

from usvdrake.worlds.solids import Solid, box, prism
from usvdrake.worlds.world import World

QUAY_THICKNESS = 1.0  # [m]
QUAY_HEIGHT = 1.0  # [m] quay top above the water (Amsterdam canals: ~1 m)
QUAY_PIECE = 10.0  # [m] longest quay piece (keeps solids small for culling)
STREET_WIDTH = 4.0  # [m] between the quay and the facades
BRIDGE_CLEARANCE = 2.4  # [m] underside above the water (Amsterdam: ~2.4 m on the ring canals)
BRIDGE_DECK = 0.6  # [m] deck thickness
BRIDGE_WIDTH = 8.0  # [m] along the canal


@dataclass
class Canal:
    centre_line: list[list[float]]  # [[x, y], ...] [m]
    width: float  # [m] water width


def _densify_ring(ring: np.ndarray, step: float) -> np.ndarray:
    """Closed ring (first ≠ last) with vertices at most ``step`` apart along each edge."""
    out = []
    for a, b in zip(ring, np.roll(ring, -1, axis=0), strict=True):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.extend(a + (b - a) * (k / n) for k in range(n))
    return np.array(out)


def _offset_ring(ring: np.ndarray, distance: float) -> np.ndarray:
    """Mitred offset of a closed ring to the right of its direction (outward of the water for
    shapely-oriented polygons: exterior counter-clockwise, holes clockwise)."""
    e = np.roll(ring, -1, axis=0) - ring
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    n = np.column_stack([e[:, 1], -e[:, 0]])  # right-hand normal of edge i
    n_prev = np.roll(n, 1, axis=0)
    m = n_prev + n
    return ring + distance * m / np.maximum(1.0 + np.einsum("ij,ij->i", n_prev, n), 0.2)[:, None]


def _is_convex(quad: np.ndarray) -> bool:
    e = np.roll(quad, -1, axis=0) - quad
    cross = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)
    return bool(np.all(cross > 1e-9) or np.all(cross < -1e-9))


def _rings(water) -> list[np.ndarray]:
    polys = list(water.geoms) if hasattr(water, "geoms") else [water]
    rings = []
    for p in polys:
        p = orient(p, sign=1.0)
        for r in [p.exterior, *p.interiors]:
            rings.append(np.asarray(r.coords)[:-1])
    return rings


def _strip(ring: np.ndarray, inner: float, outer: float) -> list[np.ndarray]:
    """Convex quadrilaterals tiling the band between two offsets of a ring."""
    a, b = _offset_ring(ring, inner) if inner else ring, _offset_ring(ring, outer)
    quads = []
    for i in range(len(ring)):
        j = (i + 1) % len(ring)
        q = np.array([a[i], a[j], b[j], b[i]])
        if _is_convex(q):
            quads.append(q)
    return quads


def canal_network(
    name: str,
    canals: list[Canal],
    seed: int,
    bridges=(),
    boats: int = 0,
    datum: str = "amsterdam",
    description: str = "",
    facades: bool = True,
) -> World:
    """A canal world. ``bridges``: [(canal index, arc length [m])]; ``boats``: how many moored;
    ``facades``: line the streets with buildings (a river bank has none)."""
    rng = np.random.default_rng(seed)
    lines = [shapely.LineString(c.centre_line) for c in canals]
    water = shapely.union_all(
        [
            ln.buffer(c.width / 2, cap_style="flat", join_style="mitre")
            for ln, c in zip(lines, canals, strict=True)
        ]
    )
    water = shapely.simplify(water, 0.01)
    solids: list[Solid] = []
    rings = [_densify_ring(r, QUAY_PIECE) for r in _rings(water)]
    for ring in rings:
        solids += [prism("quay", q, -1.0, QUAY_HEIGHT) for q in _strip(ring, 0.0, QUAY_THICKNESS)]

    # Facades: quads between two offsets of each ring resampled at random frontages; a
    # candidate is dropped where it would reach the street or overlap an accepted neighbour.
    street = QUAY_THICKNESS + STREET_WIDTH
    keep_out = water.buffer(street - 0.05, join_style="mitre")
    candidates = []
    for ring in _rings(water) if facades else []:
        dense = _densify_ring(ring, 1.0)
        idx, k = [], 0
        while k < len(dense):
            idx.append(k)
            k += int(rng.integers(5, 10))
        if len(idx) >= 3:
            depth = rng.uniform(8.0, 12.0)
            candidates += [
                (q, float(rng.uniform(8.0, 20.0)))
                for q in _strip(dense[idx], street, street + depth)
            ]
    polys = shapely.polygons([q for q, _ in candidates]) if candidates else np.array([])
    ok = (
        shapely.is_valid(polys)
        & (shapely.area(polys) > 10.0)
        & ~shapely.intersects(polys, keep_out)
    )
    tree = shapely.STRtree(shapely.buffer(polys, -0.15))
    accepted = np.zeros(len(candidates), bool)
    for i in np.nonzero(ok)[0]:
        hits = tree.query(polys[i].buffer(-0.15), predicate="intersects")
        if not accepted[hits].any():
            accepted[i] = True
            q, height = candidates[i]
            solids.append(prism("building", q, 0.0, height))

    denied = []
    for ci, s in bridges:
        line, w = lines[ci], canals[ci].width
        p, q = line.interpolate(s), line.interpolate(min(s + 0.5, line.length))
        d = np.array([q.x - p.x, q.y - p.y])
        yaw = float(np.arctan2(d[1], d[0]))
        span = w + 2 * (QUAY_THICKNESS + STREET_WIDTH)
        deck = box(
            "bridge",
            p.x,
            p.y,
            BRIDGE_WIDTH,
            span,
            yaw,
            BRIDGE_CLEARANCE,
            BRIDGE_CLEARANCE + BRIDGE_DECK,
        )
        solids.append(deck)
        denied.append(shapely.Polygon(deck.polygon).buffer(1.0))

    # Moored boats alongside straight quay pieces, clear of bridges and of each other.
    boat_zone = []
    tries = 0
    bridge_zone = shapely.union_all(denied).buffer(5.0) if denied else shapely.Polygon()
    while len(boat_zone) < boats and tries < 50 * max(boats, 1):
        tries += 1
        ring = rings[int(rng.integers(len(rings)))]
        i = int(rng.integers(len(ring)))
        a, b = ring[i], ring[(i + 1) % len(ring)]
        if np.linalg.norm(b - a) < QUAY_PIECE * 0.9:
            continue
        d = (b - a) / np.linalg.norm(b - a)
        inward = np.array([-d[1], d[0]])  # left of the ring direction is the water
        beam, length = rng.uniform(1.8, 2.6), rng.uniform(6.0, 9.0)
        c = (a + b) / 2 + inward * (0.3 + beam / 2)
        boat = box("boat", c[0], c[1], length, beam, float(np.arctan2(d[1], d[0])), -0.5, 0.7)
        poly = shapely.Polygon(boat.polygon)
        if (
            not water.contains(poly)
            or poly.intersects(bridge_zone)
            or any(poly.distance(z) < 3.0 for z in boat_zone)
        ):
            continue
        boat_zone.append(poly)
        solids.append(boat)
    return World(
        name=name,
        seed=seed,
        solids=solids,
        water=water,
        gps_denied=shapely.union_all(denied) if denied else shapely.Polygon(),
        datum=datum,
        description=description,
    )


def canal_demo(seed: int = 0) -> World:
    """An L-shaped canal, 14 m wide, 80 m then 50 m, one bridge: the demo's stage."""
    return canal_network(
        "canal_demo",
        [Canal([[-10.0, 0.0], [70.0, 0.0], [70.0, 50.0]], 14.0)],
        seed,
        bridges=[(0, 40.0)],
        boats=3,
        description="L-shaped canal with quays, facades, three moored boats and one bridge",
    )


def _arc(radius: float, a0_deg: float, a1_deg: float, step: float = 10.0) -> list[list[float]]:
    n = max(2, int(np.ceil(np.deg2rad(abs(a1_deg - a0_deg)) * radius / step)) + 1)
    a = np.deg2rad(np.linspace(a0_deg, a1_deg, n))
    return np.column_stack([radius * np.cos(a), radius * np.sin(a)]).tolist()


def charles_river(seed: int = 0) -> World:
    """A reach like the Charles River basin where Roboat II §VI-B tested NMPC and NMHE: 200 m of
    open water (the real basin is ~500 m wide), 900 m long with a gentle bend, walled banks, a few
    moored boats and one long bridge (like the Harvard Bridge). Local origin mid-reach."""
    return canal_network(
        "charles_river",
        [Canal([[-450.0, -60.0], [0.0, 0.0], [450.0, -60.0]], 200.0)],
        seed,
        bridges=[(0, 780.0)],
        boats=6,
        datum="charles_river",
        description="A 200 m wide river reach with walled banks and a bridge",
        facades=False,
    )


def _radial(angle_deg: float, r0: float, r1: float) -> list[list[float]]:
    a = np.deg2rad(angle_deg)
    return [[r0 * np.cos(a), r0 * np.sin(a)], [r1 * np.cos(a), r1 * np.sin(a)]]


def amsterdam_canal_lines() -> list[Canal]:
    """The centre lines of ``amsterdam_canals`` (origin at the ring's centre)."""
    return [
        Canal(_arc(250.0, 200.0, 340.0), 20.0),  # inner ring canal
        Canal(_arc(330.0, 200.0, 340.0), 20.0),  # outer ring canal
        Canal(_radial(200.0, 240.0, 340.0), 14.0),  # radial canals closing the loops
        Canal(_radial(250.0, 240.0, 340.0), 14.0),
        Canal(_radial(340.0, 240.0, 340.0), 14.0),
        Canal(_radial(292.0, 170.0, 720.0), 45.0),  # the river
    ]


def amsterdam_canals(seed: int = 0) -> World:
    """A canal ring after Amsterdam's grachtengordel (Roboat II §VI-A): two concentric arcs (radii
    250 m and 330 m, 20 m wide, like Herengracht and Keizersgracht) joined by three radial
    canals into closed loops, and a 45 m wide river (like the Amstel) crossing both for tracking
    tests; 8 bridges, moored boats, facades 8-20 m tall. ~2.2 km of centre line. The local
    frame's origin is the ring's centre."""
    canals = amsterdam_canal_lines()
    inner, outer = np.deg2rad(1.0) * 250.0, np.deg2rad(1.0) * 330.0  # arc length per degree
    bridges = [
        (0, 30 * inner),
        (0, 60 * inner),
        (0, 120 * inner),
        (1, 15 * outer),
        (1, 50 * outer),
        (1, 80 * outer),
        (1, 125 * outer),
        (5, 470.0),
    ]
    return canal_network(
        "amsterdam_canals",
        canals,
        seed,
        bridges=bridges,
        boats=25,
        datum="amsterdam",
        description="Two ring canals, three radial canals and a river; 8 bridges, moored boats",
    )


def centre_line_length(world_canals: list[Canal]) -> float:
    """Total centre-line length [m] of a canal network."""
    return float(sum(shapely.LineString(c.centre_line).length for c in world_canals))
