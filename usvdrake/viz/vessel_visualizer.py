"""``VesselVisualizer``: the hull at its real size, per-thruster force arrows and the path trail."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.geometry import Box as MeshcatBox
from pydrake.geometry import Cylinder, Meshcat, Rgba, Sphere
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.framework import LeafSystem

from usvdrake.scenario import VisualizationConfig
from usvdrake.systems.vessel.thrusters import command_size, split_command
from usvdrake.vessel import VesselParams

# violet: a colour nothing else in the scene uses, so the hull is findable (and testable) on screen
HULL_COLOR = Rgba(0.62, 0.0, 1.0, 1.0)
HALO_ALPHA = 0.5  # the disc under the hull, in the hull's colour
DECK_MARK = Rgba(1.0, 1.0, 1.0, 1.0)
ARROW_COLOR = Rgba(1.0, 0.35, 0.0, 1.0)
TRAIL_COLOR = Rgba(1.0, 0.85, 0.1, 1.0)
ROUTE_COLOR = Rgba(0.3, 1.0, 0.5, 0.8)


FLEET_COLORS = (  # hull colours of a fleet's boats, in order
    (0.95, 0.55, 0.1),
    (0.2, 0.6, 0.95),
    (0.35, 0.8, 0.35),
    (0.85, 0.3, 0.75),
    (0.95, 0.85, 0.2),
)


class VesselVisualizer(LeafSystem):
    """Draws one vessel in Meshcat under ``/vessels/<name>`` at ``rate_hz``; every update is also
    written to Meshcat's recording (if one is running) at the simulation time, so the HTML replay
    shows the same motion, arrows and the trail growing chunk by chunk.

    .. pydrake_system::

        name: VesselVisualizer
        input_ports:
        - state
        - thrust_applied

    The trail points live in the Context (abstract state), so re-simulating starts a fresh trail.
    """

    def __init__(
        self,
        meshcat: Meshcat,
        vessel: VesselParams,
        cfg: VisualizationConfig,
        waypoints=(),
        prefix: str | None = None,
        color=None,
        marker_radius: float = 0.0,
    ):
        super().__init__()
        self._meshcat, self._vessel, self._cfg = meshcat, vessel, cfg
        self._waypoints = np.asarray(waypoints, float).reshape(-1, 2)
        self._prefix = prefix or f"/vessels/{vessel.name}"
        self._hull_color = HULL_COLOR if color is None else Rgba(*color, 1.0)  # (r, g, b) in [0, 1]
        self._period = 1.0 / cfg.rate_hz
        self._chunk = max(1, int(round(cfg.trail_chunk * cfg.rate_hz)))
        # a flat disc of ``marker_radius`` [m] under the hull (0: none) so a small boat is seen
        # in a wide view; the thrust arrows scale with it
        self._marker = max(float(marker_radius), 0.0)
        self._arrow_length = cfg.arrow_length or max(vessel.hull.length, 2.0 * self._marker)
        self._arrow_radius = max(0.08 * vessel.hull.length, 0.12 * self._marker)
        self._state = self.DeclareVectorInputPort("state", 6)
        self._thrust = self.DeclareVectorInputPort("thrust_applied", command_size(vessel.thrusters))
        self._trail = self.DeclareAbstractState(AbstractValue.Make(np.zeros((0, 2))))
        self.DeclareInitializationUnrestrictedUpdateEvent(self._reset_trail)
        self.DeclareInitializationPublishEvent(self._setup)
        self.DeclarePeriodicUnrestrictedUpdateEvent(self._period, 0.0, self._append)
        self.DeclarePeriodicPublishEvent(self._period, 0.0, self._draw)

    # --- events -----------------------------------------------------------------------------
    def _reset_trail(self, context, state):
        state.get_mutable_abstract_state(self._trail).set_value(np.zeros((0, 2)))

    def _append(self, context, state):
        pts = context.get_abstract_state(self._trail).get_value()
        q = self._state.Eval(context)
        state.get_mutable_abstract_state(self._trail).set_value(np.vstack([pts, q[:2]]))

    def _setup(self, context):
        m, p, hull = self._meshcat, self._prefix, self._vessel.hull
        m.Delete(p)
        freeboard = hull.height - hull.draught
        if hull.shape == "round":
            m.SetObject(f"{p}/hull/body", Cylinder(hull.length / 2, hull.height), self._hull_color)
        else:
            m.SetObject(
                f"{p}/hull/body", MeshcatBox(hull.length, hull.beam, hull.height), self._hull_color
            )
        m.SetTransform(f"{p}/hull/body", RigidTransform([0, 0, hull.height / 2 - hull.draught]))
        # A red mark on the fore deck shows where "forward" is.
        mark = MeshcatBox(0.15 * hull.length, 0.3 * hull.beam, 0.02)
        m.SetObject(f"{p}/hull/bow_mark", mark, DECK_MARK)
        m.SetTransform(
            f"{p}/hull/bow_mark", RigidTransform([0.35 * hull.length, 0, freeboard + 0.01])
        )
        if self._marker > 0:
            c = self._hull_color
            halo = Rgba(c.r(), c.g(), c.b(), HALO_ALPHA)
            m.SetObject(f"{p}/hull/halo", Cylinder(self._marker, 0.02), halo)
            m.SetTransform(f"{p}/hull/halo", RigidTransform([0, 0, 0.02]))
        for t in self._vessel.thrusters:
            base = f"{p}/hull/thrusters/{t.name}"
            m.SetObject(f"{base}/scale/arrow", Cylinder(self._arrow_radius, 1.0), ARROW_COLOR)
            m.SetTransform(
                f"{base}/scale/arrow", RigidTransform(RollPitchYaw(0, np.pi / 2, 0), [0.5, 0, 0])
            )
        if len(self._waypoints):
            route = np.vstack([self._state.Eval(context)[:2], self._waypoints])
            pts = np.vstack([route.T, np.full(len(route), 0.05)])
            m.SetLine(f"{p}/route", pts, 2.0, ROUTE_COLOR)
            for i, wp in enumerate(self._waypoints):
                m.SetObject(f"{p}/waypoints/{i}", Sphere(0.25), ROUTE_COLOR)
                m.SetTransform(f"{p}/waypoints/{i}", RigidTransform([wp[0], wp[1], 0.1]))
        self._draw(context)

    def _draw(self, context):
        m, p, t = self._meshcat, self._prefix, context.get_time()
        q = self._state.Eval(context)
        m.SetTransform(
            f"{p}/hull", RigidTransform(RotationMatrix.MakeZRotation(q[2]), [q[0], q[1], 0.0]), t
        )
        deck = self._vessel.hull.height - self._vessel.hull.draught + 0.05
        for th, (f, a) in zip(
            self._vessel.thrusters,
            split_command(self._vessel.thrusters, self._thrust.Eval(context)),
            strict=True,
        ):
            base = f"{p}/hull/thrusters/{th.name}"
            angle = a + (np.pi if f < 0 else 0.0)
            m.SetTransform(
                base, RigidTransform(RotationMatrix.MakeZRotation(angle), [th.x, th.y, deck]), t
            )
            length = max(abs(f) / th.max_force * self._arrow_length, 1e-3)
            m.SetProperty(f"{base}/scale", "scale", [length, 1.0, 1.0], t)
        pts = context.get_abstract_state(self._trail).get_value()
        n = len(pts)
        if n > 1 and (n - 1) % self._chunk == 0:
            k = (n - 1) // self._chunk
            self._draw_trail_piece(k, pts[(k - 1) * self._chunk : n], t)

    def _draw_trail_piece(self, k: int, pts: np.ndarray, t: float) -> None:
        path = f"{self._prefix}/trail/{k}"
        xyz = np.vstack([pts.T, np.full(len(pts), 0.08)])
        self._meshcat.SetLine(path, xyz, 3.0, TRAIL_COLOR)
        self._meshcat.SetProperty(path, "visible", False, 0.0)
        self._meshcat.SetProperty(path, "visible", True, t)

    def finish(self, context) -> None:
        """Draw the trail's last, partial piece (call once after the simulation ends)."""
        pts = context.get_abstract_state(self._trail).get_value()
        n = len(pts)
        if n > 1 and (n - 1) % self._chunk:
            k = (n - 1) // self._chunk + 1
            self._draw_trail_piece(k, pts[(k - 1) * self._chunk : n], context.get_time())
