"""Who takes which ride: the coordinator's numerical core (Roboat II §III).

Roboat's service: "a passenger asks for a ride at a position, the system coordinator gives the
task to the closest unoccupied boat" (Roboat II §III). Closest is measured as a boat must travel it:
the length of the shortest collision-free path on the planning grid, not the straight line
(across a canal ring those differ by hundreds of metres).

* :class:`GridGraph` is the planning grid's free cells as a sparse graph with the same moves
  as :func:`~usvdrake.systems.guidance.grid_astar.grid_astar` (8-connected, orthogonal steps
  1, diagonal √2 cells, no diagonal between two blocked cells). One Dijkstra run from the
  pickup (:meth:`GridGraph.costs_from`, ``scipy.sparse.csgraph``) gives the exact path length
  to *every* vessel at once; the test compares it with one A* per vessel.
* :class:`Dispatch` is the ledger of requests: the queue in arrival order, the assignments,
  pick-ups, deliveries and failures, and the service metrics (wait and trip times).
"""

import copy
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from usvdrake.systems.guidance.grid_astar import SQRT2, PlanningGrid


@dataclass(frozen=True)
class DeliveryRequest:
    """A ride asked for at ``time`` [s]: from ``pickup`` to ``destination`` (world [m])."""

    time: float  # [s] when the passenger asks
    pickup: tuple[float, float]  # [m]
    destination: tuple[float, float]  # [m]


class GridGraph:
    """The unblocked cells of a :class:`PlanningGrid` as an undirected weighted graph [m]."""

    def __init__(self, grid: PlanningGrid):
        self.grid = grid
        free = ~grid.blocked
        rows, cols = free.shape
        self.index = np.full(free.shape, -1, np.int64)
        self.index[free] = np.arange(int(free.sum()))
        src, dst, w = [], [], []
        res = grid.resolution
        # each undirected edge once: right, up, and the two upward diagonals
        for dr, dc, cost in ((0, 1, 1.0), (1, 0, 1.0), (1, 1, SQRT2), (1, -1, SQRT2)):
            r0, r1 = 0, rows - dr
            c0, c1 = max(0, -dc), cols - max(0, dc)
            a = free[r0:r1, c0:c1]
            b = free[r0 + dr : r1 + dr, c0 + dc : c1 + dc]
            ok = a & b
            if dr and dc:  # refuse the diagonal when both cells beside it are blocked
                side1 = free[r0 + dr : r1 + dr, c0:c1]
                side2 = free[r0:r1, c0 + dc : c1 + dc]
                ok &= side1 | side2
            rr, cc = np.nonzero(ok)
            src.append(self.index[rr + r0, cc + c0])
            dst.append(self.index[rr + r0 + dr, cc + c0 + dc])
            w.append(np.full(len(rr), cost * res))
        n = int(free.sum())
        s, d, ww = np.concatenate(src), np.concatenate(dst), np.concatenate(w)
        self.matrix = coo_matrix((ww, (s, d)), shape=(n, n)).tocsr()

    def node(self, xy) -> int:
        """The graph node to plan from for a world point (snapped as ``PlanningGrid.plan``
        snaps a start inside the inflation)."""
        cell, _ = self.grid.snap(np.asarray(xy, float), "point", max_snap=2.0)
        return int(self.index[cell])

    def costs_from(self, xy) -> np.ndarray:
        """Shortest path length [m] from ``xy`` to every node (inf: unreachable)."""
        return dijkstra(self.matrix, directed=False, indices=self.node(xy))

    def path_costs(self, source_xy, points) -> np.ndarray:
        """Shortest path length [m] from ``source_xy`` to each of ``points`` (n × 2)."""
        costs = self.costs_from(source_xy)
        return np.array([costs[self.node(p)] for p in np.asarray(points, float).reshape(-1, 2)])


def closest_vessel(graph: GridGraph, pickup, vessels: dict[str, np.ndarray]):
    """(name, costs) of the vessel with the shortest path to ``pickup`` among ``vessels``
    (name → [x, y]); costs [m] per name. Ties go to the first name. None if none can reach."""
    if not vessels:
        return None, {}
    names = list(vessels)
    costs = graph.path_costs(pickup, np.array([vessels[n][:2] for n in names]))
    best = int(np.argmin(costs))
    if not math.isfinite(costs[best]):
        return None, dict(zip(names, costs.tolist(), strict=True))
    return names[best], dict(zip(names, costs.tolist(), strict=True))


@dataclass
class RideRecord:
    """What happened to one request (times [s]; None: not yet)."""

    request: DeliveryRequest
    vessel: str | None = None  # who has it now
    assigned: float | None = None
    picked_up: float | None = None
    delivered: float | None = None
    released: float | None = None  # its vessel was free again (passengers off, pilot idle)
    costs: dict = field(default_factory=dict)  # path cost [m] of each free vessel when assigned
    positions: dict = field(default_factory=dict)  # where each free vessel was then [m]
    history: list = field(default_factory=list)  # (time, event, vessel)
    stranded: bool = False  # its vessel failed with the passenger on board


@dataclass
class Dispatch:
    """The request ledger (plain data; the ``Coordinator`` keeps one in its Context)."""

    requests: list[DeliveryRequest]
    vessels: list[str]
    rides: list[RideRecord] = field(default_factory=list)
    failed: set = field(default_factory=set)

    def __post_init__(self):
        if not self.rides:
            self.rides = [RideRecord(r) for r in self.requests]

    def copy(self) -> "Dispatch":
        """A deep copy (Drake state must not be mutated in place)."""
        return copy.deepcopy(self)

    def busy(self) -> set:
        """Vessels holding a ride they have not been released from."""
        return {r.vessel for r in self.rides if self._holds(r)}

    @staticmethod
    def _holds(r: RideRecord) -> bool:
        return r.vessel is not None and r.released is None and not r.stranded

    def task_of(self, vessel: str) -> int | None:
        """Index of the ride ``vessel`` holds now."""
        for i, r in enumerate(self.rides):
            if r.vessel == vessel and self._holds(r):
                return i
        return None

    def waiting(self, t: float) -> list[int]:
        """Requests that have arrived by ``t`` and have no vessel, in arrival order."""
        idx = [
            i
            for i, r in enumerate(self.rides)
            if r.request.time <= t and r.vessel is None and not r.stranded
        ]
        return sorted(idx, key=lambda i: (self.rides[i].request.time, i))

    def assign(self, t: float, graph: GridGraph, positions: dict[str, np.ndarray]) -> list[int]:
        """Give each waiting request, oldest first, to the closest free healthy vessel (path
        cost from its position in ``positions``); returns the rides assigned now."""
        done = []
        for i in self.waiting(t):
            free = {
                n: positions[n]
                for n in self.vessels
                if n not in self.busy() and n not in self.failed and n in positions
            }
            name, costs = closest_vessel(graph, self.rides[i].request.pickup, free)
            if name is None:
                break
            ride = self.rides[i]
            ride.vessel, ride.assigned, ride.costs = name, t, costs
            ride.positions = {n: [float(v) for v in xy[:2]] for n, xy in free.items()}
            ride.history.append((t, "assigned", name))
            done.append(i)
        return done

    def mark(self, i: int, event: str, t: float) -> None:
        """Record ``event`` ("picked_up", "delivered" or "released") of ride ``i`` at ``t``
        (each once)."""
        if event not in ("picked_up", "delivered", "released"):
            raise ValueError(f"Dispatch.mark: unknown event {event!r}")
        ride = self.rides[i]
        if getattr(ride, event) is not None:
            return
        setattr(ride, event, t)
        ride.history.append((t, event, ride.vessel))

    def vessel_failed(self, vessel: str, t: float) -> None:
        """Take ``vessel`` out of service. A ride it had not picked up goes back to the queue
        (re-assigned at the next :meth:`assign`); one with the passenger aboard is stranded."""
        if vessel in self.failed:
            return
        self.failed.add(vessel)
        i = self.task_of(vessel)
        if i is None:
            return
        ride = self.rides[i]
        ride.history.append((t, "vessel_failed", vessel))
        if ride.picked_up is None:
            ride.vessel, ride.assigned = None, None
        else:
            ride.stranded = True

    def metrics(self) -> dict:
        """Service metrics: requests served, mean wait (request → pick-up) and trip (pick-up →
        delivery) times [s], re-assignments, stranded rides."""
        served = [r for r in self.rides if r.delivered is not None]
        waits = [r.picked_up - r.request.time for r in self.rides if r.picked_up is not None]
        trips = [r.delivered - r.picked_up for r in served]
        return {
            "requests": len(self.rides),
            "requests_served": len(served),
            "requests_stranded": sum(r.stranded for r in self.rides),
            "mean_wait_s": float(np.mean(waits)) if waits else None,
            "max_wait_s": float(np.max(waits)) if waits else None,
            "mean_trip_s": float(np.mean(trips)) if trips else None,
            "reassignments": sum(
                1 for r in self.rides for _, e, _ in r.history if e == "vessel_failed"
            ),
            "failed_vessels": sorted(self.failed),
        }
