"""``TrajectoryVisualizer``: a planned trajectory (e.g. the NMPC's prediction) as a Meshcat line."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Meshcat, Rgba
from pydrake.systems.framework import LeafSystem

PREDICTION_COLOR = Rgba(0.1, 0.9, 1.0, 1.0)
REFERENCE_COLOR = Rgba(0.3, 1.0, 0.5, 0.8)


def draw_reference(
    meshcat: Meshcat, reference, path: str = "/reference", step: float = 0.5
) -> None:
    """The whole timed reference as a static line (sampled every ``step`` seconds)."""
    times = np.arange(0.0, reference.duration + step, step)
    q, _ = reference.sample(times)
    meshcat.SetLine(
        path, np.vstack([q[:, 0], q[:, 1], np.full(len(q), 0.05)]), 2.0, REFERENCE_COLOR
    )


class TrajectoryVisualizer(LeafSystem):
    """Draws the input states' (x, y) as a line at ``rate_hz`` (live; a recording keeps the
    last line).

    .. pydrake_system::

        name: TrajectoryVisualizer
        input_ports:
        - trajectory
    """

    def __init__(self, meshcat: Meshcat, path: str, rate_hz: float = 10.0):
        super().__init__()
        self._meshcat, self._path = meshcat, path
        self._traj = self.DeclareAbstractInputPort(
            "trajectory", AbstractValue.Make(np.zeros((0, 6)))
        )
        self.DeclarePeriodicPublishEvent(1.0 / rate_hz, 0.0, self._draw)

    def _draw(self, context):
        q = self._traj.Eval(context)
        if len(q) > 1:
            pts = np.vstack([q[:, 0], q[:, 1], np.full(len(q), 0.12)])
            self._meshcat.SetLine(self._path, pts, 4.0, PREDICTION_COLOR)
