"""Small test worlds shared by several test modules."""

import shapely

from usvdrake.worlds import World, box, cylinder

# A 20 m × 10 m walled pond with one pillar: walls 1 m thick, 3 m tall (from z = −1).
ROOM = World(
    "room",
    0,
    solids=[
        box("wall", 10.5, 0, 1, 12, 0, -1, 2),
        box("wall", -10.5, 0, 1, 12, 0, -1, 2),
        box("wall", 0, 5.5, 22, 1, 0, -1, 2),
        box("wall", 0, -5.5, 22, 1, 0, -1, 2),
        cylinder("mount", 4.0, 2.0, 0.3, -1, 3),
    ],
    water=shapely.box(-10, -5, 10, 5),
)
