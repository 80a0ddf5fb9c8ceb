"""``TaxiPilot``: one Roboat's side of the ride service (Roboat II §III) — plan to the pickup, wait
while the passenger boards, plan to the destination, and keep clear of the other boats."""

import math
from dataclasses import dataclass, field, replace

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.sensors.lidar_model import sensor_to_world
from usvdrake.sensors.messages import LaserScan, PointCloud
from usvdrake.systems.guidance.grid_astar import NoPathError, PlanningGrid
from usvdrake.systems.guidance.reference_monitor import reference_row
from usvdrake.systems.guidance.reference_trajectory import HoldPose, ReferenceTrajectory
from usvdrake.systems.guidance.taxi_planning import (
    ahead_within,
    detect_vessels,
    grid_around,
    path_conflicts,
)

IDLE, TO_PICKUP, BOARDING, TO_DESTINATION, ALIGHTING, FAILED = range(6)
PHASES = ("idle", "to_pickup", "boarding", "to_destination", "alighting", "failed")
# taxi_status layout
STATUS = ("phase", "ride", "picked_up", "delivered", "failed", "replans", "holds")
SEE_DELAY = 1e-3  # [s] after the lidar's sweep event


@dataclass
class TaxiConfig:
    """How a taxi drives (one per fleet; Roboat II §III, §VI-B)."""

    speed: float = 1.2  # [m/s] cruise surge speed (Amsterdam's canal limit is 6 km/h)
    acceptance_radius: float = 1.5  # [m] at a pickup or destination
    dwell: float = 20.0  # [s] boarding or alighting, held at the stop
    period: float = 0.5  # [s] pilot update (detection, phases, replanning)
    resolution: float = 0.5  # [m] planning grid cell
    inflation: float = 1.6  # [m] hull circumradius 1.12 m + 0.5 m tracking margin
    separation: float = 1.5  # [m] extra room kept around a detected vessel when planning
    port_shift: float = 1.5  # [m] detected vessels are planned as if this far to our port side
    yield_distance: float = 7.0  # [m] a vessel this close ahead on a conflicting path: hold
    lookahead: float = 60.0  # [s] of the reference checked for conflicts
    replan_interval: float = 2.0  # [s] at least this between two replans
    stuck_timeout: float = 90.0  # [s] the reference ended this long ago, goal not reached: replan
    static_margin: float = 1.0  # [m] returns this close to the map are the map, not a vessel


@dataclass
class PilotMemory:
    """The pilot's state (abstract state in the Context)."""

    phase: int = IDLE
    ride: int = -1  # the ride being served (index in the coordinator's list)
    pickup: np.ndarray = field(default_factory=lambda: np.zeros(2))
    destination: np.ndarray = field(default_factory=lambda: np.zeros(2))
    reference: object = None  # ReferenceTrajectory or HoldPose
    since: float = 0.0  # [s] when the phase began
    last_plan: float = -math.inf  # [s]
    picked_up: int = -1  # last ride picked up
    delivered: int = -1  # last ride delivered
    failed: bool = False
    replans: int = 0
    holds: int = 0
    holding: bool = False
    blobs: list = field(default_factory=list)  # vessels seen in the last sweep


class TaxiPilot(LeafSystem):
    """A Roboat taxi's pilot: takes the coordinator's ride, plans A* references on the map
    around the vessels its lidar sees, and reports its progress.

    .. pydrake_system::

        name: TaxiPilot
        input_ports:
        - task
        - state_estimate
        - lidar_points (optional; or lidar_scan)
        output_ports:
        - reference_trajectory
        - taxi_status
        - reference

    ``task`` = [ride, pickup x, y, destination x, y] ([−1 …]: none). Phases: idle → to_pickup →
    boarding (``dwell`` s held at the pickup) → to_destination → alighting → idle. Every
    ``period`` s: the lidar's returns that the map does not explain become vessel discs
    (:func:`detect_vessels`); if the reference of the next ``lookahead`` s comes too close to one,
    the pilot replans around them (:func:`grid_around`, passing them on its starboard side),
    holding position while no path exists or a vessel is within ``yield_distance`` ahead.
    ``taxi_status`` = [phase, ride, picked_up, delivered, failed, replans, holds]
    (picked_up/delivered: the last ride that reached its pickup/destination). ``reference`` =
    [ψ_ref, u_ref, e] as the reference monitor logs it. ``fail_at`` [s]: the vessel reports a
    fault then and holds where it is (an injected failure, for re-assignment tests).
    """

    def __init__(
        self,
        cfg: TaxiConfig,
        grid: PlanningGrid,
        initial_pose,
        lidar_mount=None,
        lidar_kind: str | None = None,
        lidar_period: float = 0.1,
        hull_radius: float = 1.12,
        fail_at: float = math.inf,
    ):
        super().__init__()
        self._cfg, self._grid, self._mount = cfg, grid, lidar_mount
        self._radius, self._fail_at = hull_radius, fail_at
        self._pose0 = np.asarray(initial_pose, float)[:3]
        self._task = self.DeclareVectorInputPort("task", 5)
        self._est = self.DeclareVectorInputPort("state_estimate", 6)
        self._lidar = None
        if lidar_kind == "3d":
            self._lidar = self.DeclareAbstractInputPort(
                "lidar_points", AbstractValue.Make(PointCloud())
            )
        elif lidar_kind == "2d":
            self._lidar = self.DeclareAbstractInputPort(
                "lidar_scan", AbstractValue.Make(LaserScan())
            )
        self._mem = self.DeclareAbstractState(AbstractValue.Make(self._initial()))
        self.DeclareInitializationUnrestrictedUpdateEvent(self._reset)
        self.DeclarePeriodicUnrestrictedUpdateEvent(cfg.period, 0.0, self._update)
        if self._lidar is not None:
            # Just after each sweep: its points are turned into the world with the pose of the
            # sweep's time (a pose 0.1 s off while turning at 0.25 rad/s moves a quay 50 m away
            # by over a metre, into the water, where it would look like a boat).
            self.DeclarePeriodicUnrestrictedUpdateEvent(
                lidar_period, lidar_period + SEE_DELAY, self._see
            )
        ticket = {self.abstract_state_ticket(self._mem)}
        self.DeclareAbstractOutputPort(
            "reference_trajectory",
            lambda: AbstractValue.Make(HoldPose(self._pose0[:2], self._pose0[2])),
            self._calc_reference_trajectory,
            prerequisites_of_calc=ticket,
        )
        self.DeclareVectorOutputPort(
            "taxi_status", len(STATUS), self._calc_status, prerequisites_of_calc=ticket
        )
        self.DeclareVectorOutputPort("reference", 3, self._calc_reference)

    def memory(self, context) -> PilotMemory:
        return context.get_abstract_state(self._mem).get_value()

    def _initial(self) -> PilotMemory:
        return PilotMemory(reference=HoldPose(self._pose0[:2], self._pose0[2]))

    def _reset(self, context, state):
        state.get_mutable_abstract_state(self._mem).set_value(self._initial())

    # --- the pilot's step ----------------------------------------------------------------------
    def _see(self, context, state):
        """The vessels in the sweep just taken (stored for the next pilot step)."""
        mem = replace(self.memory(context))
        mem.blobs = []
        if self._lidar.HasValue(context):
            msg = self._lidar.Eval(context)
            pts = msg.points if isinstance(msg, PointCloud) else msg.points()
            if len(pts):
                q = np.asarray(self._est.Eval(context), float)
                world = sensor_to_world(pts, self._mount, q)
                mem.blobs = detect_vessels(world, self._grid, self._cfg.static_margin)
        state.get_mutable_abstract_state(self._mem).set_value(mem)

    def _plan(self, mem: PilotMemory, q, t: float, goal) -> bool:
        """A new reference from here to ``goal`` around the seen vessels; False if none."""
        cfg = self._cfg
        grid = self._grid
        if mem.blobs:
            grid = grid_around(
                self._grid, mem.blobs, q, cfg.separation, cfg.port_shift, keep_free=(q[:2], goal)
            )
        mem.last_plan = t
        try:
            path = grid.plan(q[:2], goal)
        except (NoPathError, ValueError):
            return False
        mem.reference = ReferenceTrajectory.from_path(
            path, cfg.speed, grid=grid, start_heading=float(q[2]), t0=t
        )
        mem.replans += 1
        mem.holding = False
        return True

    def _hold(self, mem: PilotMemory, q) -> None:
        if not mem.holding:
            mem.holds += 1
        mem.holding = True
        mem.reference = HoldPose(q[:2], float(q[2]))

    def _update(self, context, state):
        cfg = self._cfg
        t = context.get_time()
        q = np.asarray(self._est.Eval(context), float)
        mem = replace(self.memory(context))
        if t >= self._fail_at and not mem.failed:
            mem.failed, mem.phase, mem.since = True, FAILED, t
            self._hold(mem, q)
        task = self._task.Eval(context)
        ride = int(round(task[0]))
        if mem.phase == IDLE and ride >= 0 and ride not in (mem.ride, mem.delivered):
            mem.ride, mem.pickup, mem.destination = ride, task[1:3].copy(), task[3:5].copy()
            mem.phase, mem.since = TO_PICKUP, t
            if not self._plan(mem, q, t, mem.pickup):
                self._hold(mem, q)
        elif mem.phase in (TO_PICKUP, TO_DESTINATION):
            self._drive(mem, q, t)
        elif mem.phase == BOARDING and t - mem.since >= cfg.dwell:
            mem.phase, mem.since = TO_DESTINATION, t
            if not self._plan(mem, q, t, mem.destination):
                self._hold(mem, q)
        elif mem.phase == ALIGHTING and t - mem.since >= cfg.dwell:
            mem.phase, mem.since = IDLE, t
            mem.reference = HoldPose(q[:2], float(q[2]))  # wait here for the next ride
        state.get_mutable_abstract_state(self._mem).set_value(mem)

    def _drive(self, mem: PilotMemory, q, t: float) -> None:
        cfg = self._cfg
        goal = mem.pickup if mem.phase == TO_PICKUP else mem.destination
        ref = mem.reference
        if np.hypot(*(q[:2] - goal)) <= cfg.acceptance_radius and t >= ref.t_end:
            if mem.phase == TO_PICKUP:
                mem.phase, mem.picked_up = BOARDING, mem.ride
            else:
                mem.phase, mem.delivered = ALIGHTING, mem.ride
            mem.since, mem.holding = t, False
            mem.reference = HoldPose(goal, float(q[2]))
            return
        times = t + np.arange(0.0, cfg.lookahead, 1.0)
        ahead = ref.sample(times)[0][:, :2]
        conflict = path_conflicts(ahead, mem.blobs, self._radius, cfg.separation)
        stuck = t - ref.t_end > cfg.stuck_timeout
        may_plan = t - mem.last_plan >= cfg.replan_interval
        if not (conflict or stuck or (mem.holding and may_plan)):
            return
        if may_plan and self._plan(mem, q, t, goal):
            return
        if conflict and ahead_within(q, mem.blobs, cfg.yield_distance, np.deg2rad(60.0)):
            self._hold(mem, q)  # no way round yet and the vessel is close: wait

    # --- outputs -------------------------------------------------------------------------------
    def _calc_reference_trajectory(self, context, value):
        value.set_value(self.memory(context).reference)

    def _calc_status(self, context, output):
        m = self.memory(context)
        output.SetFromVector(
            [m.phase, m.ride, m.picked_up, m.delivered, float(m.failed), m.replans, m.holds]
        )

    def _calc_reference(self, context, output):
        reference = self.memory(context).reference
        output.SetFromVector(reference_row(reference, context.get_time(), self._est.Eval(context)))
