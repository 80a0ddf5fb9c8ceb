"""``ExplorationVisualizer``: Ueland 2017's operator display in Meshcat (§Operator Interaction) —
the planned path, its destination, the frontier cells and the setpoint, drawn live over the SLAM map
(drawn by :class:`~usvdrake.viz.occupancy_visualizer.OccupancyVisualizer`)."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform
from pydrake.perception import BaseField, Fields, PointCloud
from pydrake.systems.framework import LeafSystem

PATH_COLOR = Rgba(1.0, 0.6, 0.0, 1.0)
DESTINATION_COLOR = Rgba(1.0, 0.3, 0.0, 0.9)
FRONTIER_COLOR = Rgba(0.2, 0.9, 1.0, 1.0)
SETPOINT_COLOR = Rgba(0.9, 0.1, 0.9, 1.0)
Z = 0.15  # [m] drawn just above the map


class ExplorationVisualizer(LeafSystem):
    """Draws at ``rate_hz``: ``path`` (n × 2 [m]) as a line, ``destination`` ([x, y, valid,
    cost]) as a sphere, ``goals`` (cells of ``planning_map``) as points and ``setpoint``
    ([x, y, ψ]) as a small sphere.

    .. pydrake_system::

        name: ExplorationVisualizer
        input_ports:
        - path
        - destination
        - planning_map
        - goals
        - setpoint
    """

    def __init__(self, meshcat: Meshcat, prefix: str = "/exploration", rate_hz: float = 2.0):
        super().__init__()
        self._meshcat, self._prefix = meshcat, prefix
        self._path = self.DeclareAbstractInputPort("path", AbstractValue.Make(np.zeros((0, 2))))
        self._dest = self.DeclareVectorInputPort("destination", 4)
        self._map = self.DeclareAbstractInputPort("planning_map", AbstractValue.Make(None))
        self._goals = self.DeclareAbstractInputPort(
            "goals", AbstractValue.Make(np.zeros((0, 2), dtype=int))
        )
        self._setpoint = self.DeclareVectorInputPort("setpoint", 3)
        meshcat.SetObject(f"{prefix}/destination", Sphere(0.12), DESTINATION_COLOR)
        meshcat.SetObject(f"{prefix}/setpoint", Sphere(0.05), SETPOINT_COLOR)
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._draw)

    def _draw(self, context):
        m, p = self._meshcat, self._prefix
        path = np.asarray(self._path.Eval(context)).reshape(-1, 2)
        if len(path) > 1:
            m.SetLine(f"{p}/path", np.vstack([path.T, np.full(len(path), Z)]), 3.0, PATH_COLOR)
        else:
            m.Delete(f"{p}/path")
        dest = self._dest.Eval(context)
        m.SetProperty(f"{p}/destination", "visible", bool(dest[2] > 0))
        if dest[2] > 0:
            m.SetTransform(f"{p}/destination", RigidTransform([dest[0], dest[1], Z]))
        sp = self._setpoint.Eval(context)
        m.SetTransform(f"{p}/setpoint", RigidTransform([sp[0], sp[1], Z]))
        pmap = self._map.Eval(context)
        goals = np.asarray(self._goals.Eval(context)).reshape(-1, 2)
        if pmap is not None and len(goals):
            xy = pmap.cell_centres(goals)
            cloud = PointCloud(len(xy), Fields(BaseField.kXYZs))
            cloud.mutable_xyzs()[:] = np.vstack([xy.T, np.full(len(xy), Z)])
            m.SetObject(f"{p}/frontiers", cloud, 0.08, FRONTIER_COLOR)
        else:
            m.Delete(f"{p}/frontiers")
