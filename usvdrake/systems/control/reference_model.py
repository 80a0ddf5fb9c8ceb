"""Third-order position/heading reference model of Ueland 2017's motion controller (Fossen 2011
§10.2.1).

Per degree of freedom the linear model is the low-pass filter of Fossen 2011 §10.2.1 (the
cascade of a first-order filter and a mass-damper-spring system)

    η_d / r = ω³ / ((s + ω)(s² + 2ζω s + ω²)),

written in state space (the same section; Fossen 2021 §12.1.1 in the 2nd edition) as

    η_d⃛ + (2ζ + 1) ω η̈_d + (2ζ + 1) ω² η̇_d + ω³ η_d = ω³ r.

Equation numbers are not quoted: we could not check them against the printed book. The book's
velocity and acceleration saturation elements (same section) are implemented in this form,
which keeps the *states* inside the limits and so avoids integrator wind-up:

    η̇_d state v, η̈_d state a, e = r − η_d (heading component wrapped to (−π, π])
    d/dt η_d = sat_V(v)
    d/dt v   = Π_V(v, sat_A(a))       (on the boundary |v| = v_max, a's outward part is removed)
    d/dt a   = Π_A(a, j),   j = ω³ e − (2ζ + 1) ω² v − (2ζ + 1) ω a

where sat_V, sat_A scale the planar part [x, y] back onto the discs |·| ≤ v_max, a_max (speed
norm √(ẋ² + ẏ²), not each axis, so a diagonal move is limited like a straight one) and clip
the heading part to r_max, yaw_acc_max; Π_X(x, w) = w except on the boundary |x| ≥ x_max
with w pointing outwards, where the radial component of w is removed. Inside the limits the
model is exactly the linear filter above.

The output ``reference`` = [η_d, η̇_d, η̈_d] (9) is [η_d, sat_V(v), Π_V(v, sat_A(a))]: exactly
the model's η_d, its time derivative and the derivative of that, world frame, so the
controller's feed-forward is consistent. ψ_d is not wrapped (it is continuous); only the error
e_ψ is.

Continuous state (9 states: η_d, v, a) rather than a fixed-step discrete filter: the model is
then integrated by the simulator's error-controlled integrator together with the plant (no
extra rate to choose, no Euler error: the unsaturated response *is* the transfer function
above to integrator accuracy), and the output depends on the state only (no feedthrough). The
saturation elements make the right-hand side only piecewise smooth, at the limit boundaries;
the error-controlled integrator takes a few short steps there.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.systems.framework import BasicVector, LeafSystem

from usvdrake.angles import wrap_angle

_PLANAR = slice(0, 2)


@dataclass
class ReferenceModelConfig:
    """Tuning of the third-order reference model (defaults for Ueland 2017's ntnu_round vessel)."""

    omega: float = 0.3  # [rad/s] ω, natural frequency (planar DOFs; heading too unless set)
    zeta: float = 1.0  # ζ, relative damping
    v_max: float = (
        0.25  # [m/s] limit on the planar speed √(ẋ_d² + ẏ_d²) (Ueland 2017: 0.25 m/s cruise)
    )
    a_max: float = 0.1  # [m/s²] limit on the planar acceleration norm
    r_max: float = 0.3  # [rad/s] limit on |ψ̇_d|
    yaw_acc_max: float = 0.5  # [rad/s²] limit on |ψ̈_d|
    omega_heading: float | None = None  # [rad/s] ω for ψ; None: same as ``omega``
    zeta_heading: float | None = None  # ζ for ψ; None: same as ``zeta``

    def frequencies(self) -> tuple[np.ndarray, np.ndarray]:
        """(ω, ζ) per DOF [x, y, ψ]."""
        wh = self.omega if self.omega_heading is None else self.omega_heading
        zh = self.zeta if self.zeta_heading is None else self.zeta_heading
        return np.array([self.omega, self.omega, wh]), np.array([self.zeta, self.zeta, zh])

    def validate(self) -> None:
        w, z = self.frequencies()
        if not (np.all(w > 0) and np.all(z > 0)):
            raise ValueError(f"ReferenceModelConfig: ω and ζ must be positive, got {w}, {z}")
        for name in ("v_max", "a_max", "r_max", "yaw_acc_max"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ReferenceModelConfig: {name} must be positive (inf: no limit)")


def saturate(vec: np.ndarray, planar_max: float, heading_max: float) -> np.ndarray:
    """[x, y] scaled onto the disc of radius ``planar_max``, ψ clipped to ± ``heading_max``."""
    out = np.array(vec, dtype=float)
    n = np.hypot(out[0], out[1])
    if n > planar_max:
        out[_PLANAR] *= planar_max / n
    out[2] = np.clip(out[2], -heading_max, heading_max)
    return out


def project(state: np.ndarray, rate: np.ndarray, planar_max: float, heading_max: float):
    """Π: ``rate`` (the derivative of ``state``) without the component that would carry a state
    already on its limit further out (planar: the radial part; heading: the whole value)."""
    out = np.array(rate, dtype=float)
    p = state[_PLANAR]
    n2 = float(p @ p)
    if n2 > 0.0 and np.sqrt(n2) >= planar_max:
        outward = float(p @ out[_PLANAR])
        if outward > 0.0:
            out[_PLANAR] -= (outward / n2) * p
    if abs(state[2]) >= heading_max and state[2] * out[2] > 0.0:
        out[2] = 0.0
    return out


def reference_output(cfg: ReferenceModelConfig, x: np.ndarray) -> np.ndarray:
    """[η_d, η̇_d, η̈_d] (9) of state x = [η_d, v, a] (9): [η_d, sat_V(v), Π_V(v, sat_A(a))]."""
    x = np.asarray(x, float)
    v, a = x[3:6], x[6:9]
    vel = saturate(v, cfg.v_max, cfg.r_max)
    acc = project(v, saturate(a, cfg.a_max, cfg.yaw_acc_max), cfg.v_max, cfg.r_max)
    return np.concatenate([x[0:3], vel, acc])


def reference_derivatives(cfg: ReferenceModelConfig, x: np.ndarray, setpoint) -> np.ndarray:
    """ẋ of the saturated third-order model (module docstring) for x = [η_d, v, a], setpoint
    r = [x_s, y_s, ψ_s]; the heading error r_ψ − ψ_d is wrapped to (−π, π]."""
    x = np.asarray(x, float)
    w, z = cfg.frequencies()
    e = np.asarray(setpoint, float) - x[0:3]
    e[2] = wrap_angle(e[2])
    v, a = x[3:6], x[6:9]
    jerk = w**3 * e - (2.0 * z + 1.0) * w**2 * v - (2.0 * z + 1.0) * w * a
    out = reference_output(cfg, x)
    a_dot = project(a, jerk, cfg.a_max, cfg.yaw_acc_max)
    return np.concatenate([out[3:6], out[6:9], a_dot])


def initial_reference_state(pose) -> np.ndarray:
    """x at rest at ``pose`` = [x, y, ψ]: η_d = pose, η̇_d = η̈_d = 0."""
    pose = np.asarray(pose, float)
    if pose.shape != (3,):
        raise ValueError(f"reference model: a pose needs 3 values [x, y, ψ], got {pose.shape}")
    return np.concatenate([pose, np.zeros(6)])


class ReferenceModel(LeafSystem):
    """Smooths a position/heading setpoint into a feasible η_d(t), η̇_d(t), η̈_d(t).

    .. pydrake_system::

        name: ReferenceModel
        input_ports:
        - setpoint
        output_ports:
        - reference

    ``setpoint`` = [x_s, y_s, ψ_s] [m, m, rad], world frame; ``reference`` = [η_d (3), η̇_d (3),
    η̈_d (3)] world frame (continuous state, no direct feedthrough). The model starts at rest at
    ``initial_pose`` (default origin); ``set_initial_pose`` moves a context's start, e.g. to the
    vessel's initial pose.
    """

    def __init__(self, config: ReferenceModelConfig | None = None, initial_pose=None):
        super().__init__()
        self._cfg = ReferenceModelConfig() if config is None else config
        self._cfg.validate()
        x0 = initial_reference_state(np.zeros(3) if initial_pose is None else initial_pose)
        self.DeclareContinuousState(BasicVector(x0))
        self._setpoint = self.DeclareVectorInputPort("setpoint", 3)
        self.DeclareVectorOutputPort(
            "reference", 9, self._calc_reference, prerequisites_of_calc={self.xc_ticket()}
        )

    @property
    def config(self) -> ReferenceModelConfig:
        return self._cfg

    def set_initial_pose(self, context, pose) -> None:
        """Put the model at rest at ``pose`` = [x, y, ψ] in this system's ``context``."""
        context.SetContinuousState(initial_reference_state(pose))

    def DoCalcTimeDerivatives(self, context, derivatives):
        x = context.get_continuous_state_vector().CopyToVector()
        xdot = reference_derivatives(self._cfg, x, self._setpoint.Eval(context))
        derivatives.get_mutable_vector().SetFromVector(xdot)

    def _calc_reference(self, context, output):
        x = context.get_continuous_state_vector().CopyToVector()
        output.SetFromVector(reference_output(self._cfg, x))
