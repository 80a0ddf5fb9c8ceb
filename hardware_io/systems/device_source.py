"""``DeviceSource``: the skeleton shared by the systems that read a real device (serial port or
UDP socket) into one output port of a diagram."""

from __future__ import annotations

from dataclasses import asdict
from typing import Any, Generic, TypeVar

from pydrake.common.value import AbstractValue
from pydrake.systems.framework import LeafSystem

from hardware_io.transport import LinkCounters

__all__ = ["DeviceSource"]

MessageT = TypeVar("MessageT")
StatusT = TypeVar("StatusT")


class DeviceSource(LeafSystem, Generic[MessageT, StatusT]):
    """Messages from a device on ``transport``, published on the output port ``port_name``.

    The last message (initially ``message``, a default "nothing yet" value) and the status
    counters (initially ``status``, a frozen dataclass) are abstract state. A periodic
    unrestricted update every ``period`` seconds (first at t = 0) hands both to the subclass's
    ``poll(t, message, status, *extra) -> (message, status, *extra)``, which talks to the
    transport at simulation time ``t``, decodes what arrived and returns the updated values; the
    output port is the message state. A subclass may declare more abstract state with
    :meth:`_declare_polled_state`: ``poll`` then also receives and returns it, after the
    status, in the order of declaration.

    The output port ``diagnostics`` is the status counters as a flat ``dict`` (field name →
    value: :func:`dataclasses.asdict` of the status) followed by the transport's link
    (``connected``, ``disconnects``, ``reconnects``: its
    :class:`~hardware_io.transport.LinkCounters`, copied into abstract state at each update),
    so runners read them off a port, not off the system.

    The transport and the protocol parsers' partial buffers are I/O and live on the system
    object, not in the Context. So contexts of a device source are not independent (all share
    the one port or socket), and the system cannot be cloned or pickled across processes. Call
    :meth:`close` to release the port or socket.
    """

    def __init__(
        self, transport, port_name: str, message: MessageT, status: StatusT, period: float
    ):
        super().__init__()
        self.transport = transport
        self._message = self.DeclareAbstractState(AbstractValue.Make(message))
        self._status = self.DeclareAbstractState(AbstractValue.Make(status))
        self._link_counters = self.DeclareAbstractState(AbstractValue.Make(LinkCounters()))
        self._polled = [self._message, self._status]
        self.DeclarePeriodicUnrestrictedUpdateEvent(period, 0.0, self._update)
        self.DeclareStateOutputPort(port_name, self._message)
        self.DeclareAbstractOutputPort(
            "diagnostics",
            lambda: AbstractValue.Make({}),
            self._calc_diagnostics,
            {
                self.abstract_state_ticket(self._status),
                self.abstract_state_ticket(self._link_counters),
            },
        )

    def _declare_polled_state(self, value: Any):
        """Declares an abstract state initialised to ``value`` that ``poll`` receives and
        returns after the status; returns its index."""
        index = self.DeclareAbstractState(AbstractValue.Make(value))
        self._polled.append(index)
        return index

    def status(self, context) -> StatusT:
        return context.get_abstract_state(self._status).get_value()

    def close(self) -> None:
        self.transport.close()

    def link_counters(self, context) -> LinkCounters:
        return context.get_abstract_state(self._link_counters).get_value()

    def _calc_diagnostics(self, context, output):
        output.set_value(asdict(self.status(context)) | asdict(self.link_counters(context)))

    def _update(self, context, state):
        values = [context.get_abstract_state(i).get_value() for i in self._polled]
        updated = self.poll(context.get_time(), *values)
        for index, value in zip(self._polled, updated, strict=True):
            state.get_mutable_abstract_state(index).set_value(value)
        state.get_mutable_abstract_state(self._link_counters).set_value(self.transport.link)
