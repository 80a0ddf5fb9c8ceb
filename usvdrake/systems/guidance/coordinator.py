"""``Coordinator``: the fleet's dispatcher (Roboat II §III) — requests in, one ride per free boat
out."""

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from usvdrake.systems.guidance.fleet_assignment import DeliveryRequest, Dispatch, GridGraph
from usvdrake.systems.guidance.taxi_pilot import IDLE, STATUS

FLEET_STATUS = ("served", "waiting", "riding", "stranded", "failed_vessels")


class Coordinator(LeafSystem):
    """Gives each delivery request, when it arrives, to the unoccupied vessel with the shortest
    path to its pickup on the planning grid (:class:`~.fleet_assignment.GridGraph`), and
    re-queues a ride whose vessel fails before the pickup.

    .. pydrake_system::

        name: Coordinator
        input_ports:
        - <vessel>_state (one per vessel)
        - <vessel>_status (one per vessel)
        output_ports:
        - <vessel>_task (one per vessel)
        - fleet_status
        - all_served

    ``<vessel>_state``: the vessel's estimate [x y ψ u v r]; ``<vessel>_status``: its pilot's
    ``taxi_status``; ``<vessel>_task`` = [ride, pickup x, y, destination x, y] ([−1, …]: none).
    Every ``period`` s: pilots' reports are booked (arrived at a pickup / destination, back to
    idle, failed), then waiting requests are assigned oldest first. A vessel is unoccupied from
    the moment its pilot is idle again after its last delivery. ``fleet_status`` = [served,
    waiting, riding, stranded, failed vessels]; ``all_served`` = [1] once every request is
    delivered or stranded.
    """

    def __init__(
        self,
        requests: list[DeliveryRequest],
        vessels: list[str],
        graph: GridGraph,
        period: float = 1.0,
    ):
        super().__init__()
        if len(set(vessels)) != len(vessels) or not vessels:
            raise ValueError(f"Coordinator: vessel names must be unique and given, got {vessels}")
        self._requests, self._vessels, self._graph = list(requests), list(vessels), graph
        self._states = {n: self.DeclareVectorInputPort(f"{n}_state", 6) for n in vessels}
        self._status = {n: self.DeclareVectorInputPort(f"{n}_status", len(STATUS)) for n in vessels}
        self._ledger = self.DeclareAbstractState(AbstractValue.Make(self._fresh()))
        self.DeclareInitializationUnrestrictedUpdateEvent(self._reset)
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        ticket = {self.abstract_state_ticket(self._ledger)}
        for n in vessels:
            self.DeclareVectorOutputPort(
                f"{n}_task",
                5,
                lambda context, output, n=n: self._calc_task(context, output, n),
                prerequisites_of_calc=ticket,
            )
        self.DeclareVectorOutputPort(
            "fleet_status", len(FLEET_STATUS), self._calc_fleet, prerequisites_of_calc=ticket
        )
        self.DeclareVectorOutputPort(
            "all_served", 1, self._calc_all_served, prerequisites_of_calc=ticket
        )

    @property
    def graph(self) -> GridGraph:
        return self._graph

    def dispatch(self, context) -> Dispatch:
        """The ledger: every ride's assignment, pick-up and delivery (see ``Dispatch``)."""
        return context.get_abstract_state(self._ledger).get_value()

    def _fresh(self) -> Dispatch:
        return Dispatch(self._requests, self._vessels)

    def _reset(self, context, state):
        state.get_mutable_abstract_state(self._ledger).set_value(self._fresh())

    def _update(self, context, state):
        t = context.get_time()
        ledger = self.dispatch(context).copy()
        positions = {}
        for n in self._vessels:
            s = self._status[n].Eval(context)
            phase, picked, delivered, failed = int(s[0]), int(s[2]), int(s[3]), s[4] > 0
            i = ledger.task_of(n)
            if failed:
                ledger.vessel_failed(n, t)
                continue
            if i is not None:
                if picked == i:
                    ledger.mark(i, "picked_up", t)
                if delivered == i:
                    ledger.mark(i, "delivered", t)
            # free again once the pilot has delivered and is idle
            if i is not None and ledger.rides[i].delivered is not None and phase == IDLE:
                ledger.mark(i, "released", t)
            positions[n] = np.asarray(self._states[n].Eval(context), float)[:2]
        ledger.assign(t, self._graph, positions)
        state.get_mutable_abstract_state(self._ledger).set_value(ledger)

    def _calc_task(self, context, output, name):
        ledger = self.dispatch(context)
        i = ledger.task_of(name)
        if i is None:
            output.SetFromVector([-1.0, 0.0, 0.0, 0.0, 0.0])
            return
        r = ledger.rides[i].request
        output.SetFromVector([i, *r.pickup, *r.destination])

    def _calc_fleet(self, context, output):
        ledger = self.dispatch(context)
        t = context.get_time()
        rides = ledger.rides
        output.SetFromVector(
            [
                sum(r.delivered is not None for r in rides),
                len(ledger.waiting(t)),
                sum(r.vessel is not None and r.delivered is None for r in rides),
                sum(r.stranded for r in rides),
                len(ledger.failed),
            ]
        )

    def _calc_all_served(self, context, output):
        rides = self.dispatch(context).rides
        done = all(r.released is not None or r.stranded for r in rides)
        output.SetFromVector([1.0 if done else 0.0])
