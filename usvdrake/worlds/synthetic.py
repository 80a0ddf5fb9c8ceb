"""Small synthetic scenes for tests and benchmarks of scan matching (not worlds to sail in)."""

import numpy as np

from usvdrake.worlds.raycast import ColumnLayout, Scene
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
