"""Constrained thrust allocation: desired τ → thruster commands that honour every limit.

Two small convex programs, built once per layout in Drake's MathematicalProgram and solved by
Clarabel with their coefficients updated in place (Fossen 2011 §12.3, constrained allocation
with the extended thrust formulation for azimuths):

1. **Closest attainable force** — minimise ‖W^½ (B_e z − τ)‖ subject to the limits
   (fixed thruster: f_min ≤ f ≤ f_max; azimuth: ‖(F_x, F_y)‖ ≤ f_max, a Lorentz cone). Written as
   a second-order cone program in the norm itself, so the interior-point tolerance applies to
   the error and not to its square. Its optimum τ* = B_e z* is the W-weighted projection of τ
   onto the attainable set (unique, W ≻ 0): this is the **documented minimum** returned when τ
   lies outside the attainable set.
2. **Least effort** — among the commands that achieve τ* exactly, minimise Σ (z_i / f_max,i)²
   (forces normalised by each thruster's capacity) subject to the same limits. When τ is
   attainable, τ* := τ, so the mixer reproduces τ to solver precision.

If stage 2 fails numerically (τ* on the boundary of the attainable set, where the feasible set
may shrink to a point), the stage-1 solution is kept: it already achieves the minimum error.
"""

from dataclasses import dataclass

import numpy as np
from pydrake.solvers import ClarabelSolver, MathematicalProgram

from usvdrake.systems.vessel.thrusters import extended_matrix, extended_to_command
from usvdrake.vessel import Thruster

# Below this W-weighted error [N] τ counts as attainable and is achieved exactly by stage 2.
ATTAINABLE_TOL = 1e-6


@dataclass
class AllocationResult:
    command: np.ndarray  # thruster command ([f] or [f, α] per thruster)
    tau_achieved: np.ndarray  # B u [N, N, N m]
    error: float  # ‖W^½ (τ_achieved − τ)‖, the weighted error [N]
    attainable: bool  # τ was inside the attainable set


class ThrustAllocator:
    """Reusable allocator for one thruster layout (the numerical core of ``ThrustAllocation``)."""

    def __init__(self, thrusters: list[Thruster], weight: list[float] | np.ndarray):
        self.thrusters = list(thrusters)
        self.B = extended_matrix(self.thrusters)
        self.W = np.diag(np.asarray(weight, dtype=float))
        self._w_half = np.sqrt(self.W)
        n = self.B.shape[1]
        scale = []
        for t in self.thrusters:
            scale += [t.max_force] * (2 if t.azimuth else 1)
        self._r = np.diag(1.0 / np.square(scale))
        self._solver = ClarabelSolver()

        # Stage 1: min s  s.t. ‖W^½ (B z − τ)‖ ≤ s, limits.
        self._p1 = MathematicalProgram()
        z1 = self._p1.NewContinuousVariables(n, "z")
        s = self._p1.NewContinuousVariables(1, "s")
        self._p1.AddLinearCost([1.0], 0.0, s)
        a = np.zeros((4, n + 1))
        a[0, n] = 1.0
        a[1:, :n] = self._w_half @ self.B
        self._cone1 = self._p1.AddLorentzConeConstraint(a, np.zeros(4), np.concatenate([z1, s]))
        self._add_limits(self._p1, z1)
        self._z1, self._s = z1, s

        # Stage 2: min zᵀ R z  s.t. B z = τ*, limits.
        self._p2 = MathematicalProgram()
        z2 = self._p2.NewContinuousVariables(n, "z")
        self._p2.AddQuadraticCost(2.0 * self._r, np.zeros(n), z2, is_convex=True)
        self._eq2 = self._p2.AddLinearEqualityConstraint(self.B, np.zeros(3), z2)
        self._add_limits(self._p2, z2)
        self._z2 = z2

    def _add_limits(self, prog: MathematicalProgram, z) -> None:
        k = 0
        for t in self.thrusters:
            if t.azimuth:
                prog.AddLorentzConeConstraint(
                    np.vstack([np.zeros(2), np.eye(2)]),
                    np.array([t.max_force, 0.0, 0.0]),
                    z[k : k + 2],
                )
                k += 2
            else:
                prog.AddBoundingBoxConstraint(t.min_force, t.max_force, z[k])
                k += 1

    def _clip(self, z: np.ndarray) -> np.ndarray:
        """Remove the solver's last ~1e-9 of limit violation so limits hold exactly."""
        z = z.copy()
        k = 0
        for t in self.thrusters:
            if t.azimuth:
                norm = np.hypot(z[k], z[k + 1])
                if norm > t.max_force:
                    z[k : k + 2] *= t.max_force / norm
                k += 2
            else:
                z[k] = min(max(z[k], t.min_force), t.max_force)
                k += 1
        return z

    def allocate(self, tau_desired) -> AllocationResult:
        """Allocate ``tau_desired`` = [X, Y, N] (body frame) to the thrusters."""
        tau = np.asarray(tau_desired, dtype=float).reshape(3)
        if not np.all(np.isfinite(tau)):
            raise ValueError(f"ThrustAllocator: tau_desired must be finite, got {tau}")
        n = self.B.shape[1]
        b = np.concatenate([[0.0], -self._w_half @ tau])
        a = np.zeros((4, n + 1))
        a[0, n] = 1.0
        a[1:, :n] = self._w_half @ self.B
        self._cone1.evaluator().UpdateCoefficients(a, b)
        r1 = self._solver.Solve(self._p1)
        if not r1.is_success():
            raise RuntimeError(f"ThrustAllocator stage 1 failed: {r1.get_solution_result()}")
        z = self._clip(r1.GetSolution(self._z1))
        err1 = float(np.linalg.norm(self._w_half @ (self.B @ z - tau)))
        target = tau if err1 <= ATTAINABLE_TOL * max(1.0, np.linalg.norm(tau)) else self.B @ z
        self._eq2.evaluator().UpdateCoefficients(self.B, target)
        r2 = self._solver.Solve(self._p2)
        if r2.is_success():
            z2 = self._clip(r2.GetSolution(self._z2))
            err2 = float(np.linalg.norm(self._w_half @ (self.B @ z2 - tau)))
            if err2 <= err1 + ATTAINABLE_TOL:
                z = z2
        achieved = self.B @ z
        err = float(np.linalg.norm(self._w_half @ (achieved - tau)))
        return AllocationResult(
            command=extended_to_command(self.thrusters, z),
            tau_achieved=achieved,
            error=err,
            attainable=err <= 10 * ATTAINABLE_TOL * max(1.0, np.linalg.norm(tau)),
        )
