"""``Watchdog``: zero the thruster command while a required sensor is silent.

Host-side companion of the MCU watchdog of ``hardware_io/PROTOCOL.md``: the MCU stops the
thrusters when *commands* stop arriving; this system stops commanding thrust when the
*sensors* the controller depends on stop arriving, so a controller never steers blind.
"""

from __future__ import annotations

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.sensors.messages import GpsFix, ImuSample, LaserScan, PointCloud

__all__ = ["Watchdog"]

# Model values for the abstract input ports of the station's sensor names (all Python messages
# share one C++ type, so any message can be connected; this only documents what is expected).
_MODELS = {"gps": GpsFix, "imu": ImuSample, "lidar_scan": LaserScan, "lidar_points": PointCloud}

# Discrete state layout: [tripped, silent mask, trips, last_ok_0, ..., last_ok_{m-1}]
_TRIPPED, _MASK, _TRIPS, _LAST = 0, 1, 2, 3


class Watchdog(LeafSystem):
    """Passes ``thruster_command`` through, or zero force while a required sensor is silent.

    .. pydrake_system::

        name: Watchdog
        input_ports:
        - thruster_command
        - <one per key of required, e.g. gps, imu, lidar_scan>
        output_ports:
        - thruster_command
        - watchdog_status

    Args:
        command_size: length of the thruster command vector (``command_size(thrusters)``).
        required: sensor port name → timeout [s]. One abstract input port per key, named after
            it, taking the station's messages (``GpsFix``, ``ImuSample``, ``LaserScan`` ...):
            anything with a ``time`` field [s] = simulation time the host received it.
        period: [s] period of the discrete update (first at t = 0).
        force_mask: bool per command entry, True where the entry is a force [N] (default: all).
            For the [f, α] azimuth layout pass False at the angles: a zero command keeps the
            input's angles and zeroes the forces, so the servos do not swing to 0.

    Each update, for sensor i, a message counts as received if its ``time`` is newer than the
    last one accepted and, for messages with a ``valid`` field (``GpsFix``), if it is valid (an
    invalid fix does not keep the vessel navigating). Sensor i is *silent* when
    ``t − last_ok_i > timeout_i``, with ``last_ok_i = 0`` at start: a sensor that never sends
    is given its timeout from t = 0 as grace period. An unconnected sensor port counts as a
    sensor that never sends. The watchdog is *tripped* while any sensor is silent; each
    transition into tripped counts one trip.

    Outputs, computed from the discrete state only (so they change at the updates, at most one
    ``period`` after the sensor fell silent / came back):

    * ``thruster_command`` (``command_size``): the input, or with the force entries set to 0
      while tripped.
    * ``watchdog_status`` (3): [tripped (0/1), bitmask of silent sensors (bit i = i-th key of
      ``required``), number of trips].
    """

    def __init__(
        self,
        command_size: int,
        required: dict[str, float],
        period: float = 0.02,
        force_mask=None,
    ):
        super().__init__()
        if command_size < 1:
            raise ValueError(f"command_size must be positive, got {command_size}")
        if period <= 0.0:
            raise ValueError(f"period must be positive, got {period}")
        self.names = list(required)
        if len(self.names) > 52:  # the mask is a float: exact up to 2^53
            raise ValueError("at most 52 required sensors")
        self.timeouts = np.array([float(required[n]) for n in self.names])
        if np.any(self.timeouts <= 0.0):
            raise ValueError(f"timeouts must be positive: {required}")
        mask = np.ones(command_size, bool) if force_mask is None else np.asarray(force_mask, bool)
        if mask.shape != (command_size,):
            raise ValueError(f"force_mask has shape {mask.shape}, need ({command_size},)")
        self.force_mask = mask
        self._command_in = self.DeclareVectorInputPort("thruster_command", command_size)
        self._sensor_in = []
        for name in self.names:
            model = _MODELS.get(name, GpsFix)()
            self._sensor_in.append(self.DeclareAbstractInputPort(name, AbstractValue.Make(model)))
        self._state = self.DeclareDiscreteState(3 + len(self.names))
        self.DeclarePeriodicDiscreteUpdateEvent(period, 0.0, self._update)
        self.DeclareVectorOutputPort(
            "thruster_command",
            BasicVector(command_size),
            self._calc_command,
            {self.xd_ticket(), self._command_in.ticket()},
        )
        self.DeclareVectorOutputPort(
            "watchdog_status", BasicVector(3), self._calc_status, {self.xd_ticket()}
        )

    def _update(self, context, discrete_state):
        t = context.get_time()
        x = context.get_discrete_state(self._state).CopyToVector()
        silent = 0
        for i, port in enumerate(self._sensor_in):
            if port.HasValue(context):
                msg = port.Eval(context)
                mt = float(getattr(msg, "time", -np.inf))
                # GpsFix.valid flags a fix; LaserScan.valid is a per-beam mask, and a scan with
                # no return (open water) is still the lidar speaking
                valid = getattr(msg, "valid", True)
                if mt > x[_LAST + i] and (valid if isinstance(valid, bool) else True):
                    x[_LAST + i] = mt
            if t - x[_LAST + i] > self.timeouts[i]:
                silent |= 1 << i
        tripped = 1.0 if silent else 0.0
        if tripped and not x[_TRIPPED]:
            x[_TRIPS] += 1.0
        x[_TRIPPED], x[_MASK] = tripped, float(silent)
        discrete_state.get_mutable_vector(self._state).SetFromVector(x)

    def _calc_command(self, context, output):
        u = np.array(self._command_in.Eval(context), dtype=float)
        if context.get_discrete_state(self._state).GetAtIndex(_TRIPPED):
            u[self.force_mask] = 0.0
        output.SetFromVector(u)

    def _calc_status(self, context, output):
        x = context.get_discrete_state(self._state).CopyToVector()
        output.SetFromVector(x[:3])

    def silent_sensors(self, context) -> list[str]:
        """Names of the sensors currently counted silent (from the state)."""
        mask = int(context.get_discrete_state(self._state).GetAtIndex(_MASK))
        return [n for i, n in enumerate(self.names) if mask >> i & 1]
