"""Target tracking from AIS reports: one constant-velocity Kalman filter per target.

State s = [east north v_east v_north]. Between reports the track is predicted with the
discretised continuous white-noise-acceleration model (Bar-Shalom 2001 §6.2.2):

    F(Δt) = [[I, Δt I], [0, I]],   Q(Δt) = q [[Δt³/3 I, Δt²/2 I], [Δt²/2 I, Δt I]]

with q the acceleration power spectral density [m²/s³]. A report measures position and, through
COG/SOG, velocity: z = [e, n, sog cos cog, sog sin cog] with R from the report noise (the polar
COG/SOG noise mapped to east/north by its Jacobian). A report whose normalised innovation
squared exceeds the χ²(4) gate is rejected as an outlier; after `max_rejections` rejections in a
row the track is restarted from the report (the target manoeuvred beyond the model or the track
was wrong). Tracks older than `max_age_s` since their last accepted report are dropped.
"""

from dataclasses import dataclass, field

import numpy as np

from usvdrake.systems.colav.ais import AisNoise, AisReport

CHI2_4DOF_999 = 18.467  # χ²(4) 99.9 % quantile: the default gate


@dataclass(frozen=True)
class Track:
    """A target's estimate at time t_s: position [m], velocity [m/s], 4×4 covariance of
    [e n ve vn], age_s = time since the last accepted report."""

    target_id: int
    t_s: float
    position: np.ndarray
    velocity: np.ndarray
    covariance: np.ndarray
    age_s: float
    updates: int

    @property
    def speed(self) -> float:
        return float(np.hypot(*self.velocity))

    @property
    def course(self) -> float:
        """Course over ground, counter-clockwise from east [rad]."""
        return float(np.arctan2(self.velocity[1], self.velocity[0]))


def transition(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """F(Δt), Q(Δt) of the constant-velocity model."""
    i2 = np.eye(2)
    f = np.block([[i2, dt * i2], [np.zeros((2, 2)), i2]])
    qm = q * np.block([[dt**3 / 3.0 * i2, dt**2 / 2.0 * i2], [dt**2 / 2.0 * i2, dt * i2]])
    return f, qm


def measurement(report: AisReport, noise: AisNoise) -> tuple[np.ndarray, np.ndarray]:
    """z and R of one report."""
    c, s = np.cos(report.cog_rad), np.sin(report.cog_rad)
    sog = report.sog_mps
    z = np.array([report.east_m, report.north_m, sog * c, sog * s])
    j = np.array([[c, -sog * s], [s, sog * c]])  # ∂(ve, vn)/∂(sog, cog)
    rv = j @ np.diag([noise.sog_mps**2, noise.cog_rad**2]) @ j.T
    r = np.zeros((4, 4))
    r[:2, :2] = noise.position_m**2 * np.eye(2)
    r[2:, 2:] = rv + 1e-9 * np.eye(2)
    return z, r


@dataclass
class TargetTracker:
    """The filter of one target. `update(report)` fuses a report; `track(t)` predicts to t
    without changing the filter."""

    noise: AisNoise = field(default_factory=AisNoise)
    accel_psd: float = 0.01  # q [m²/s³]: a ship changing speed/course by ~0.1 m/s² at most
    gate: float = CHI2_4DOF_999
    max_rejections: int = 3
    target_id: int = -1
    t_s: float = float("nan")
    state: np.ndarray | None = None
    cov: np.ndarray | None = None
    last_update_s: float = float("nan")
    updates: int = 0
    rejections: int = 0
    last_nis: float = float("nan")

    def _start(self, report: AisReport) -> None:
        z, r = measurement(report, self.noise)
        self.state, self.cov = z.copy(), r.copy()
        self.t_s = self.last_update_s = report.t_s
        self.updates, self.rejections = 1, 0

    def predicted(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        dt = max(0.0, t - self.t_s)
        f, qm = transition(dt, self.accel_psd)
        return f @ self.state, f @ self.cov @ f.T + qm

    def update(self, report: AisReport) -> bool:
        """Fuse one report; False if it was gated out as an outlier."""
        self.target_id = report.target_id
        if self.state is None:
            self._start(report)
            return True
        x, p = self.predicted(report.t_s)
        z, r = measurement(report, self.noise)
        innov = z - x
        s = p + r
        nis = float(innov @ np.linalg.solve(s, innov))
        self.last_nis = nis
        if nis > self.gate:
            self.rejections += 1
            if self.rejections >= self.max_rejections:
                self._start(report)
                return True
            return False
        k = np.linalg.solve(s, p).T  # P Sᵀ⁻¹ = P S⁻¹ (symmetric)
        ikh = np.eye(4) - k
        self.state = x + k @ innov
        self.cov = ikh @ p @ ikh.T + k @ r @ k.T  # Joseph form
        self.t_s = self.last_update_s = report.t_s
        self.updates += 1
        self.rejections = 0
        return True

    def track(self, t: float) -> Track:
        x, p = self.predicted(t)
        return Track(
            target_id=self.target_id,
            t_s=float(t),
            position=x[:2].copy(),
            velocity=x[2:].copy(),
            covariance=p,
            age_s=float(t - self.last_update_s),
            updates=self.updates,
        )


@dataclass
class AisTracker:
    """All targets: one TargetTracker per AIS id; `tracks(t)` lists the live tracks at t."""

    noise: AisNoise = field(default_factory=AisNoise)
    accel_psd: float = 0.01
    max_age_s: float = 60.0
    trackers: dict = field(default_factory=dict)

    def update(self, report: AisReport) -> bool:
        tr = self.trackers.get(report.target_id)
        if tr is None:
            tr = TargetTracker(noise=self.noise, accel_psd=self.accel_psd)
            self.trackers[report.target_id] = tr
        return tr.update(report)

    def tracks(self, t: float) -> list[Track]:
        for key in [k for k, tr in self.trackers.items() if t - tr.last_update_s > self.max_age_s]:
            del self.trackers[key]
        return [tr.track(t) for _, tr in sorted(self.trackers.items())]
