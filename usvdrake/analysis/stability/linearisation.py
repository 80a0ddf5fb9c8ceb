"""Plant linearisation and the numerical tools the loops are built from: the state and channel
names, the default trim speed, the input matrix ∂q̇/∂τ, Drake's ``Linearize`` of
:class:`VesselPlant` about a straight run and its eigenvalues in closed form, the exact
zero-order-hold discretisation, and Jacobians by AutoDiff and by central differences.

**Plant** (Roboat II eqs. 1-6, ``vessel_dynamics``): :func:`linearize_plant` runs Drake's
``Linearize`` on :class:`VesselPlant` about a straight run at surge speed u0 with its trim thrust
[Xu u0, 0, 0] (not an equilibrium: x grows, so ``equilibrium_check_tolerance=inf``). By hand
(``straight_run_jacobian``) the eigenvalues are 0, 0, 0 (x, y, ψ: no restoring force), −Xu/m11
and the two of the sway-yaw block [[−Yv/m22, −m11 u0/m22], [−(m22 − m11) u0/m33, −Nr/m33]].
"""

from __future__ import annotations

import numpy as np
from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff
from pydrake.systems.primitives import Linearize
from scipy.linalg import expm

from usvdrake.systems.vessel.vessel_dynamics import trim_thrust
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import Hydrodynamics, VesselParams

STATES = ["x", "y", "psi", "u", "v", "r"]
CHANNELS = ["surge", "sway", "yaw"]
DEFAULT_TRIM_SPEED = 0.6  # [m/s] the straight run of the Roboat II analysis (NOTES.md)


# --- plant -----------------------------------------------------------------------------------
def input_matrix(xi: Hydrodynamics) -> np.ndarray:
    """∂q̇/∂τ = [0; M⁻¹] (6×3)."""
    b = np.zeros((6, 3))
    b[3:, :] = np.diag([1.0 / xi.m11, 1.0 / xi.m22, 1.0 / xi.m33])
    return b


def linearize_plant(vessel: VesselParams, surge_speed: float = DEFAULT_TRIM_SPEED):
    """(A, B) of ``VesselPlant`` about the straight run q = [0, 0, 0, u0, 0, 0] with the trim
    thrust, still water (Drake ``Linearize``; the run is not an equilibrium, hence the infinite
    equilibrium tolerance). u0 = 0 gives rest."""
    plant = VesselPlant(vessel)
    ctx = plant.CreateDefaultContext()
    ctx.SetContinuousState([0.0, 0.0, 0.0, surge_speed, 0.0, 0.0])
    plant.GetInputPort("tau").FixValue(ctx, trim_thrust(vessel.hydrodynamics, surge_speed))
    plant.GetInputPort("tau_env").FixValue(ctx, np.zeros(3))
    plant.GetInputPort("current").FixValue(ctx, np.zeros(2))
    lin = Linearize(
        plant,
        ctx,
        input_port_index=plant.GetInputPort("tau").get_index(),
        output_port_index=plant.GetOutputPort("state").get_index(),
        equilibrium_check_tolerance=np.inf,
    )
    return np.array(lin.A()), np.array(lin.B())


def straight_run_eigenvalues(xi: Hydrodynamics, surge_speed: float) -> np.ndarray:
    """The plant's eigenvalues about the straight run, in closed form (module docstring)."""
    a11, a12 = -xi.Yv / xi.m22, -xi.m11 * surge_speed / xi.m22
    a21, a22 = -(xi.m22 - xi.m11) * surge_speed / xi.m33, -xi.Nr / xi.m33
    tr, det = a11 + a22, a11 * a22 - a12 * a21
    disc = np.sqrt(complex(tr * tr / 4.0 - det))
    pair = [tr / 2.0 + disc, tr / 2.0 - disc]
    return np.array([0.0, 0.0, 0.0, -xi.Xu / xi.m11, *pair], dtype=complex)


def zoh(a: np.ndarray, b: np.ndarray, period: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation (Φ, Γ) = (e^{AT}, ∫₀ᵀ e^{As} ds B)."""
    n, m = b.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = a, b
    e = expm(big * period)
    return e[:n, :n], e[:n, n:]


def autodiff_jacobian(fun, x0) -> tuple[np.ndarray, np.ndarray]:
    """(f(x0), ∂f/∂x(x0)) of a function of a vector, through AutoDiffXd."""
    x = InitializeAutoDiff(np.asarray(x0, float)).ravel()
    y = np.asarray(fun(x))
    return ExtractValue(y).ravel(), ExtractGradient(y)


def central_jacobian(fun, x0, h: float = 1e-6) -> np.ndarray:
    """∂f/∂x by central differences (for float-only project functions)."""
    x0 = np.asarray(x0, float)
    cols = []
    for i in range(len(x0)):
        dx = np.zeros_like(x0)
        dx[i] = h
        cols.append((np.asarray(fun(x0 + dx), float) - np.asarray(fun(x0 - dx), float)) / (2 * h))
    return np.array(cols).T
