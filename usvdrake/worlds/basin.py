"""The NTNU Marine Cybernetics Laboratory basin as set up for lidar exploration (Ueland 2017,
section Experimental Results): a 40 m × 6.45 m basin with concrete walls, a sloped wave-generator
end, an open middle section with camera mounts, other vessels and hinders on wooden planks, a narrow
passage (position B of Ueland 2017 Fig. 16) and a labyrinth-like section.

Frame: the origin is the south-west corner of the water, x east along the 40 m length, y north
across the 6.45 m width, z up from the water surface. The wave generator closes the west end
(x = 0, "the wall on the very left hand of the basin" in Ueland 2017), the labyrinth the east end.

Only the basin's size comes from Ueland 2017; the paper shows the set-up in photographs (Figs. 14,
16) that the text extraction lost, so the positions, sizes and heights below are guesses, chosen so
that a 0.548 m round vessel (Ueland 2017, Experimental Platform) whose planner inflates the map by
0.4 m (Ueland 2017, Map Processing) reaches every part of the basin: a disc of radius 0.3 m + 0.4 m
must pass every corridor and gap, which on a 0.1 m ground-truth grid (each wall also blackens the
cells it touches) takes 1.8 m. The narrow passage is therefore 1.8-2.0 m wide (Ueland 2017 gives no
width); with ~0.6 m free on each side of the vessel it is still where the velocity law slows it
down. Everything random comes from ``numpy.random.default_rng(seed)`` and only moves things within
those limits.
"""

import numpy as np
import shapely

from usvdrake.worlds.solids import Solid, box, cylinder, prism
from usvdrake.worlds.world import World

LENGTH = 40.0  # [m] basin length (Ueland 2017: "length and width of 40 m and 6.45 m")
WIDTH = 6.45  # [m] basin width (Ueland 2017)
WALL_THICKNESS = 0.5  # [m] concrete walls (guess)
WALL_BOTTOM = -1.5  # [m] the walls reach the floor (MC-Lab is 1.5 m deep)
WALL_TOP = 0.8  # [m] wall top above the water (guess: the lidar on the vessel lid sees it)
BEACH_SLOPE = np.deg2rad(35.0)  # [rad] wave-generator face from the horizontal (guess, 30-45°)
BEACH_DEPTH = 1.5  # [m] extent of the sloped end behind the water's edge (> WALL_TOP / tan)
BOARD = 0.15  # [m] thickness of the internal walls: hinders standing on planks
BOARD_BOTTOM, BOARD_TOP = -0.3, 0.7  # [m] internal walls (guess: above any lidar on a model)
PASSAGE_WIDTH = (1.8, 2.0)  # [m] narrow passage, position B (see the module docstring)
PASSAGE_LENGTH = 2.0  # [m] length of the boards lining the passage
LABYRINTH_GAP = (1.9, 2.2)  # [m] opening at the end of each labyrinth wall
LABYRINTH_PITCH = (2.4, 2.8)  # [m] spacing of the labyrinth walls (corridor width + BOARD)
MIN_GAP = 1.8  # [m] free water kept around every obstacle in the middle section
START = (1.5, WIDTH / 2)  # [m] a free point near the wave-generator end


def _beach() -> Solid:
    """The wave generator's smooth sloped face (Ueland 2017: "not purely vertical"): the solid
    behind x = 0 under the plane z = −x tan(slope), so a horizontal beam at height z meets it at x =
    −z / tan(slope), farther the higher the beam."""
    t = np.tan(BEACH_SLOPE)
    n = np.array([t, 0.0, 1.0]) / np.hypot(t, 1.0)  # n·p ≤ 0  ⇔  z ≤ −x tan(slope)
    footprint = [
        [-BEACH_DEPTH, -WALL_THICKNESS],
        [0.0, -WALL_THICKNESS],
        [0.0, WIDTH + WALL_THICKNESS],
        [-BEACH_DEPTH, WIDTH + WALL_THICKNESS],
    ]
    return prism("wall", footprint, WALL_BOTTOM, WALL_TOP, cut=(n[0], n[1], n[2], 0.0))


def _basin_walls() -> list[Solid]:
    """The two side walls (running behind the beach too, so no beam escapes at the corners)
    and the east end wall. The side walls stay whole: the sensor is always within 3.3 m of
    them, so cutting them into pieces gives the ray caster's culling no fewer beams to test."""
    x0, x1 = -BEACH_DEPTH, LENGTH + WALL_THICKNESS
    h = WALL_THICKNESS / 2
    return [
        box("wall", (x0 + x1) / 2, -h, x1 - x0, WALL_THICKNESS, 0.0, WALL_BOTTOM, WALL_TOP),
        box("wall", (x0 + x1) / 2, WIDTH + h, x1 - x0, WALL_THICKNESS, 0.0, WALL_BOTTOM, WALL_TOP),
        box("wall", LENGTH + h, WIDTH / 2, WALL_THICKNESS, WIDTH, 0.0, WALL_BOTTOM, WALL_TOP),
        _beach(),
    ]


def _board(x0: float, y0: float, x1: float, y1: float) -> Solid:
    """An internal wall along the axis-aligned segment (x0, y0)–(x1, y1), BOARD thick."""
    lx, ly = max(abs(x1 - x0), BOARD), max(abs(y1 - y0), BOARD)
    return box("wall", (x0 + x1) / 2, (y0 + y1) / 2, lx, ly, 0.0, BOARD_BOTTOM, BOARD_TOP)


def _passage_and_labyrinth(rng: np.random.Generator) -> tuple[list[Solid], float]:
    """The cross wall with the narrow passage (position B), lined by two boards, and behind it
    the labyrinth: cross walls alternately joined to the south and north walls, each leaving
    an opening at its other end, so the corridors form a serpentine. Returns the solids and the
    x of the cross wall (the end of the middle section) and the passage's water area."""
    x_b = rng.uniform(24.5, 26.0)
    w = rng.uniform(*PASSAGE_WIDTH)
    y_p = rng.uniform(1.2, WIDTH - 1.2 - w)  # south edge of the passage
    x_p = x_b + PASSAGE_LENGTH
    solids = [
        _board(x_b, 0.0, x_b, y_p),
        _board(x_b, y_p + w, x_b, WIDTH),
        _board(x_b, y_p, x_p, y_p),
        _board(x_b, y_p + w, x_p, y_p + w),
    ]
    x = x_p + rng.uniform(*LABYRINTH_PITCH)
    south = bool(rng.integers(2))
    while x < LENGTH - LABYRINTH_PITCH[0]:
        gap = rng.uniform(*LABYRINTH_GAP)
        solids.append(_board(x, 0.0, x, WIDTH - gap) if south else _board(x, gap, x, WIDTH))
        south = not south
        x += rng.uniform(*LABYRINTH_PITCH)
    return solids, x_b, shapely.box(x_b, y_p, x_p, y_p + w)


def _obstacle_group(kind: str, rng: np.random.Generator, x: float, y: float) -> list[Solid]:
    """One obstacle of the middle section centred at (x, y); its first solid is the footprint
    that must keep MIN_GAP from everything else."""
    yaw = rng.uniform(0.0, np.pi)
    if kind == "mount":  # camera mount: a pole standing on the basin floor (guess: Ø 0.1-0.2 m)
        return [cylinder("mount", x, y, rng.uniform(0.05, 0.1), WALL_BOTTOM, rng.uniform(1.2, 2.0))]
    if kind == "boat":  # another model vessel (guess: 1-2 m long, 0.4-0.8 m beam)
        length, beam = rng.uniform(1.0, 2.0), rng.uniform(0.4, 0.8)
        return [box("boat", x, y, length, beam, yaw, -0.3, rng.uniform(0.4, 0.6))]
    # A wooden plank floating at the surface with two hinders standing on it (Ueland 2017: "hinders
    # placed on wooden planks"); the plank alone is below a lidar's beam, the hinders are not.
    length = rng.uniform(2.0, 3.0)
    c, s = np.cos(yaw), np.sin(yaw)
    group = [box("plank", x, y, length, 0.25, yaw, -0.05, 0.1)]
    for a in (-0.3, 0.3):
        hx, hy = x + a * length * c, y + a * length * s
        group.append(box("wall", hx, hy, 0.3, 0.2, yaw, 0.1, rng.uniform(0.5, 0.8)))
    return group


def ntnu_basin(seed: int = 0) -> World:
    """The 40 m × 6.45 m NTNU basin of Ueland 2017 (Experimental Results) with a sloped
    wave-generator
    end, a middle section holding 3 camera mounts, 2 vessels and 2 planks with hinders (Ueland 2017:
    "camera mounts, other vessels, and hinders placed on wooden planks"), a narrow passage
    (position B) and a labyrinth-like section. Obstacle positions and the labyrinth's
    spacing vary with ``seed``; every part stays reachable from :data:`START`."""
    rng = np.random.default_rng(seed)
    solids = _basin_walls()
    inner, x_b, passage = _passage_and_labyrinth(rng)
    solids += inner
    placed = [shapely.Polygon(s.footprint()) for s in solids] + [shapely.Point(START)]
    for kind in ("boat", "boat", "plank", "plank", "mount", "mount", "mount"):
        for _ in range(200):
            x, y = rng.uniform(3.0, x_b - 1.0), rng.uniform(1.0, WIDTH - 1.0)
            group = _obstacle_group(kind, rng, x, y)
            poly = shapely.Polygon(group[0].footprint())
            if all(poly.distance(p) >= MIN_GAP for p in placed):
                placed.append(poly)
                solids += group
                break
    return World(
        name="ntnu_basin",
        seed=seed,
        solids=solids,
        water=shapely.box(0.0, 0.0, LENGTH, WIDTH),
        datum="trondheim",
        regions={"narrow_passage": passage},
        description=(
            "NTNU MC-Lab basin 40 m x 6.45 m: sloped wave-generator end, camera mounts, vessels, "
            "planks with hinders, a narrow passage and a labyrinth"
        ),
    )
