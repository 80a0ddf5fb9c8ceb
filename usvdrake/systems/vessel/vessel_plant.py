"""``VesselPlant``: the 3-DOF vessel of Roboat II eqs. (1)-(8) as a scalar-convertible
LeafSystem."""

import numpy as np
from pydrake.common.containers import namedview
from pydrake.systems.framework import BasicVector_, LeafSystem_
from pydrake.systems.scalar_conversion import TemplateSystem

from usvdrake.systems.vessel.vessel_dynamics import vessel_derivatives, vessel_derivatives_float
from usvdrake.vessel import VesselParams

VesselState = namedview("VesselState", ["x", "y", "psi", "u", "v", "r"])


@TemplateSystem.define("VesselPlant_")
def VesselPlant_(T):
    class Impl(LeafSystem_[T]):
        """Continuous 3-DOF vessel: q = [x y ψ u v r] (world ENU position [m], heading [rad],
        body surge/sway [m/s], yaw rate [rad/s]); q̇ = f(q, τ) of Roboat II eq. (7).

        .. pydrake_system::

            name: VesselPlant
            input_ports:
            - tau
            - tau_env
            - current
            output_ports:
            - state
            - acceleration

        ``tau`` [N, N, N m] is the thrusters' generalised force (body frame); ``tau_env``
        (optional, zero when unconnected) the environmental force (body frame); ``current``
        (optional, zero when unconnected) the water velocity [m/s] in the world frame, felt
        through the drag only (see ``vessel_dynamics``). ``state`` does not depend on the
        inputs (no direct feedthrough); ``acceleration`` = [u̇ v̇ ṙ] (body frame, for the IMU) does.
        """

        def _construct(self, params: VesselParams, initial_state=None, converter=None):
            LeafSystem_[T].__init__(self, converter)
            self._params = params
            q0 = np.zeros(6) if initial_state is None else np.asarray(initial_state, float)
            if q0.shape != (6,):
                raise ValueError(f"VesselPlant: initial_state needs 6 values, got {q0.shape}")
            self._initial_state = q0
            # floats take the scalar-math path; AutoDiffXd / Expression the generic one
            self._derivatives = vessel_derivatives_float if T is float else vessel_derivatives
            self.DeclareContinuousState(BasicVector_[T](q0), 3, 3, 0)
            self._tau = self.DeclareVectorInputPort("tau", 3)
            self._tau_env = self.DeclareVectorInputPort("tau_env", 3)
            self._current = self.DeclareVectorInputPort("current", 2)
            self.DeclareVectorOutputPort(
                "state", 6, self._calc_state, prerequisites_of_calc={self.xc_ticket()}
            )
            self.DeclareVectorOutputPort("acceleration", 3, self._calc_acceleration)

        def _construct_copy(self, other, converter=None):
            Impl._construct(self, other._params, other._initial_state, converter=converter)

        @property
        def params(self) -> VesselParams:
            return self._params

        def _optional(self, port, context, size):
            if port.HasValue(context):
                return port.Eval(context)
            return np.zeros(size)

        def _qdot(self, context):
            q = context.get_continuous_state_vector().CopyToVector()
            args = (
                self._params.hydrodynamics,
                q,
                self._tau.Eval(context),
                self._optional(self._tau_env, context, 3),
                self._optional(self._current, context, 2),
            )
            if T is float:  # scalar math: NaN in, NaN out, never a warning
                return self._derivatives(*args)
            # Drake's Build() probes feedthrough with NaN inputs: NaN in, NaN out, no warning
            # (a NaN reaching the integrator in a real run stops it with its own error).
            with np.errstate(invalid="ignore"):
                return self._derivatives(*args)

        def DoCalcTimeDerivatives(self, context, derivatives):
            derivatives.get_mutable_vector().SetFromVector(self._qdot(context))

        def _calc_acceleration(self, context, output):
            output.SetFromVector(self._qdot(context)[3:6])

        def _calc_state(self, context, output):
            output.SetFromVector(context.get_continuous_state_vector().CopyToVector())

    return Impl


VesselPlant = VesselPlant_[None]
