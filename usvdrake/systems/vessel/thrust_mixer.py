"""``ThrustMixer``: per-thruster commands → generalised force τ (Roboat II eq. 3), with
saturation."""

import numpy as np
from pydrake.systems.framework import LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from usvdrake.systems.vessel.thrusters import command_size, mix, saturate
from usvdrake.vessel import Thruster


@TemplateSystem.define("ThrustMixer_")
def ThrustMixer_(T):
    class Impl(LeafSystem_[T]):
        """Applies the thrusters' physical limits to a command and sums their forces into τ.

        .. pydrake_system::

            name: ThrustMixer
            input_ports:
            - thruster_command
            output_ports:
            - tau
            - thrust_applied

        ``thruster_command``: per thruster [f] (fixed) or [f, α] (azimuth) [N, rad].
        ``thrust_applied``: the same after saturation to each thruster's limits (what the
        thrusters really push). ``tau`` = B(α) · thrust_applied [N, N, N m], body frame.
        """

        def _construct(self, thrusters: list[Thruster], saturate: bool = True, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._thrusters = list(thrusters)
            self._saturate = saturate
            n = command_size(self._thrusters)
            self._cmd = self.DeclareVectorInputPort("thruster_command", n)
            # τ depends on the command alone: cached across the integrator's derivative
            # evaluations (hundreds per simulated second) while the command holds
            deps = {self.input_port_ticket(self._cmd.get_index())}
            self.DeclareVectorOutputPort("tau", 3, self._calc_tau, prerequisites_of_calc=deps)
            self.DeclareVectorOutputPort(
                "thrust_applied", n, self._calc_applied, prerequisites_of_calc=deps
            )

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._thrusters, other._saturate, converter=converter)

        def _applied(self, context):
            u = self._cmd.Eval(context)
            return saturate(self._thrusters, u) if self._saturate else u

        def _calc_tau(self, context, output):
            # Drake's Build() probes feedthrough with NaN inputs; NaN in, NaN out, no warning.
            with np.errstate(invalid="ignore"):
                output.SetFromVector(mix(self._thrusters, self._applied(context)))

        def _calc_applied(self, context, output):
            output.SetFromVector(self._applied(context))

    return Impl


ThrustMixer = ThrustMixer_[None]
