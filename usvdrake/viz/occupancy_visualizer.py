"""``OccupancyVisualizer``: an occupancy-grid input (e.g. a SLAM map) drawn in Meshcat."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat
from pydrake.systems.framework import LeafSystem

from usvdrake.viz.meshcat_world import draw_occupancy
from usvdrake.worlds.world import OccupancyGrid


class OccupancyVisualizer(LeafSystem):
    """Draws the occupied cells of its ``map`` input under ``path`` at ``rate_hz`` (live; a
    Meshcat recording keeps the last map).

    .. pydrake_system::

        name: OccupancyVisualizer
        input_ports:
        - map
    """

    def __init__(self, meshcat: Meshcat, path: str = "/slam/map", rate_hz: float = 1.0):
        super().__init__()
        self._meshcat, self._path = meshcat, path
        empty = OccupancyGrid((0.0, 0.0), 1.0, np.zeros((0, 0), np.int8))
        self._grid = self.DeclareAbstractInputPort("map", AbstractValue.Make(empty))
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._draw)

    def _draw(self, context):
        grid = self._grid.Eval(context)
        if grid.data.size and (grid.data == grid.OCCUPIED).any():
            draw_occupancy(self._meshcat, grid, self._path)
