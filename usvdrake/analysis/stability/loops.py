"""Linear closed loops and their margins: :class:`LinearLoop` (continuous or sampled state
feedback: eigenvalues, stability measure, removal of unregulated integrators, the loop broken at
one plant input, its frequency response and gain/phase margins), :func:`sampled_state_feedback`
(a continuous loop read at the samples with τ held) and the PD loop's phase margin in closed form.

**Loops** (:class:`LinearLoop`): ẋ = F x + G u (or x⁺ = F x + G u when sampled), the
controller's force τ = H x, closed by u = τ. Continuous loops use the laws as if evaluated
continuously; sampled loops discretise the plant exactly with a zero-order hold over the
controller period T (ZOH, ``expm``) and let the law read the state at the sample and hold τ,
which is what the Drake controllers (discrete state, periodic update) do.

**Margins** (``control.stability_margins``): the loop is broken at the plant input of one
channel with the other channels closed, L_i = −e_iᵀ H (sI − F − G (H − e_i e_iᵀ H))⁻¹ G e_i
(negative-feedback convention), continuous and sampled (the exact discrete loop at the
controller rate, which contains the ZOH's T/2 delay). For the decoupled PD about rest,
L = (kp + kd s) / (m s² + d s) and |L(jω_c)| = 1 gives
ω_c² = [kd² − d² + √((kd² − d²)² + 4 m² kp²)] / (2 m²),  PM = 90° + atan2(kd ω_c, kp) −
atan2(m ω_c, d) (the double integrator, d = 0: PM = atan2(kd ω_c, kp)); the gain margin is
infinite in continuous time.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import control
import numpy as np

from usvdrake.analysis.stability.linearisation import CHANNELS, zoh


# --- linear loops ----------------------------------------------------------------------------
@dataclass
class LinearLoop:
    """ẋ = F x + G u (``dt`` = 0) or x⁺ = F x + G u (``dt`` = T), controller force τ = H x,
    closed by u = τ. ``unregulated``: names of integrator states dropped by :meth:`reduced`."""

    name: str
    F: np.ndarray
    G: np.ndarray
    H: np.ndarray
    dt: float = 0.0
    states: list[str] = field(default_factory=list)
    channels: list[str] = field(default_factory=lambda: list(CHANNELS))
    unregulated: list[str] = field(default_factory=list)

    @property
    def sampled(self) -> bool:
        return self.dt > 0

    @property
    def closed(self) -> np.ndarray:
        return self.F + self.G @ self.H

    def eigenvalues(self) -> np.ndarray:
        return np.linalg.eigvals(self.closed)

    def stability_measure(self) -> float:
        """max Re(λ) (continuous) or max |z| (sampled)."""
        ev = self.eigenvalues()
        return float(np.max(np.abs(ev)) if self.sampled else np.max(ev.real))

    def is_stable(self, tol: float = 1e-9) -> bool:
        m = self.stability_measure()
        return bool(m < 1.0 - tol) if self.sampled else bool(m < -tol)

    def reduced(self, drop: list[str]) -> LinearLoop:
        """The loop without states that feed back nowhere (their F column is 0, or e_i when
        sampled, and their H column 0): their eigenvalue (0 or 1) is structural."""
        idx = [self.states.index(s) for s in drop]
        for i in idx:
            col = self.F[:, i] - (np.eye(len(self.F))[:, i] if self.sampled else 0.0)
            if np.max(np.abs(col)) > 1e-9 or np.max(np.abs(self.H[:, i])) > 1e-9:
                raise ValueError(f"{self.name}: state {self.states[i]} feeds back")
        keep = [i for i in range(len(self.F)) if i not in idx]
        return LinearLoop(
            self.name,
            self.F[np.ix_(keep, keep)],
            self.G[keep],
            self.H[:, keep],
            self.dt,
            [self.states[i] for i in keep],
            list(self.channels),
            list(self.unregulated) + list(drop),
        )

    def loop_transfer(self, channel: int) -> control.StateSpace:
        """L_i: the loop broken at the plant input of ``channel``, the others closed (negative
        feedback convention: the closed loop is L/(1 + L))."""
        e = np.zeros((self.H.shape[0], 1))
        e[channel, 0] = 1.0
        a = self.F + self.G @ (self.H - e @ self.H[[channel]])
        return control.ss(a, self.G @ e, -self.H[[channel]], 0.0, self.dt if self.sampled else 0)

    def frequency_grid(self, n: int = 3000) -> np.ndarray:
        """Log-spaced ω [rad/s] from 1e-4 to 100 × the fastest pole (continuous) or to the
        Nyquist frequency π/T (sampled, excluded)."""
        if self.sampled:
            top = np.pi / self.dt * (1.0 - 1e-9)
        else:
            fast = np.abs(np.concatenate([np.linalg.eigvals(self.F), self.eigenvalues()])).max()
            top = 100.0 * fast + 10.0
        return np.logspace(-4.0, np.log10(top), n)

    def frequency_response(self, channel: int, w: np.ndarray) -> np.ndarray:
        """L_i(jω) or L_i(e^{jωT}) evaluated from the state space (batched LAPACK solves)."""
        sys = self.loop_transfer(channel)
        a, b, c = (np.asarray(m) for m in (sys.A, sys.B, sys.C))
        pts = np.exp(1j * w * self.dt) if self.sampled else 1j * w
        m = pts[:, None, None] * np.eye(len(a))[None] - a[None]
        x = np.linalg.solve(m, np.broadcast_to(b, (len(w), *b.shape)).astype(complex))
        return (c[None] @ x)[:, 0, 0]

    def margins(self, channel: int) -> dict:
        """Gain margin [dB], phase margin [deg] and their crossovers [rad/s] by
        ``control.stability_margins`` on the exact frequency response over
        :meth:`frequency_grid` (python-control's polynomial route is ill-conditioned for these
        loops: uncontrollable modes of the other channels, poles at z = 1). Sampled loops whose
        L(e^{jπ}) is real negative reach −180° exactly at the Nyquist frequency, which no grid
        brackets: that gain margin is evaluated there. None = infinite. ``gain_margin_db`` is
        python-control's pick (closest to 0 dB); a negative value is a gain-*reduction* margin
        (conditionally stable loop, e.g. LOS adds an integrator in the heading loop);
        ``all_gain_margins_db`` lists every [GM dB, ω] found."""
        w = self.frequency_grid()
        resp = self.frequency_response(channel, w)
        data = (np.abs(resp), np.degrees(np.angle(resp)), w)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gm, pm, _, wpc, wgc, _ = control.stability_margins(data)
            gms, _, _, wpcs, _, _ = control.stability_margins(data, returnall=True)
        gms, wpcs = list(np.atleast_1d(gms)), list(np.atleast_1d(wpcs))
        if self.sampled:
            nyq = float(self.frequency_response(channel, np.array([np.pi / self.dt]))[0].real)
            if nyq < 0:
                gms.append(-1.0 / nyq)
                wpcs.append(np.pi / self.dt)
                if not np.isfinite(gm) or abs(np.log(-1 / nyq)) < abs(np.log(gm)):
                    gm, wpc = -1.0 / nyq, np.pi / self.dt
        return {
            "gain_margin_db": _finite(20.0 * np.log10(gm)) if gm > 0 else None,
            "phase_margin_deg": _finite(pm),
            "phase_crossover_rad_s": _finite(wpc),
            "gain_crossover_rad_s": _finite(wgc),
            "all_gain_margins_db": [
                [float(20.0 * np.log10(g)), float(x)]
                for g, x in zip(gms, wpcs, strict=True)
                if np.isfinite(g) and g > 0
            ],
        }


def _finite(x) -> float | None:
    x = float(x)
    return x if np.isfinite(x) else None


def sampled_state_feedback(loop: LinearLoop, period: float) -> LinearLoop:
    """The continuous state-feedback loop with the law read at the samples and τ held (ZOH)."""
    phi, gam = zoh(loop.F, loop.G, period)
    return LinearLoop(
        loop.name, phi, gam, loop.H.copy(), period, list(loop.states), list(loop.channels)
    )


# --- margins by hand ---------------------------------------------------------------------------
def pd_phase_margin(m: float, d: float, kp: float, kd: float) -> tuple[float, float]:
    """(PM [deg], ω_c [rad/s]) of L = (kp + kd s)/(m s² + d s) (module docstring)."""
    a = kd * kd - d * d
    wc = np.sqrt((a + np.sqrt(a * a + 4.0 * m * m * kp * kp)) / (2.0 * m * m))
    pm = 90.0 + np.degrees(np.arctan2(kd * wc, kp) - np.arctan2(m * wc, d))
    return float(pm), float(wc)
