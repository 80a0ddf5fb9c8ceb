"""Wheel odometry in :class:`GraphSlam` (:class:`OdometryMixin`): the odometry model's
covariance (:func:`odometry_covariance`, a random walk), the odometry's scale calibrated
against the steps the scans measured well (:attr:`odometry_scale`) and the odometry
constraints over ``odometry_span``, gated against the scans' own chain of steps.
"""

import numpy as np

from usvdrake.systems.slam.graph_slam.graph import Constraint
from usvdrake.systems.slam.graph_slam.poses import between, compose_covariance


def odometry_covariance(step: np.ndarray, sigma) -> np.ndarray:
    """Covariance of an odometry step (dx, dy, dθ) in the earlier pose's frame: a random walk,
    variance growing with the distance d travelled and the angle turned, σ_x² = σ_y² =
    σ_t² d, σ_θ² = σ_r² |dθ| + σ_d² d, with ``sigma`` = (σ_t [m/√m], σ_r [rad/√rad], σ_d
    [rad/√m]) (the usual odometry model, e.g. Thrun, Burgard & Fox 2005 §5.4, with variances
    additive over steps so that splitting a path into more nodes does not tighten it), above
    a floor of 1 mm / 1 mrad that keeps a step at rest invertible."""
    s_t, s_r, s_d = (float(v) for v in sigma)
    if not all(np.isfinite(v) and v >= 0 for v in (s_t, s_r, s_d)):
        raise ValueError(f"odometry_covariance: sigma must be finite and >= 0, got {sigma}")
    d = float(np.hypot(step[0], step[1]))
    var_xy = s_t**2 * d + 1e-6
    var_th = s_r**2 * abs(float(step[2])) + s_d**2 * d + 1e-6
    return np.diag([var_xy, var_xy, var_th])


class OdometryMixin:
    """Odometry calibration and odometry constraints of :class:`GraphSlam`."""

    @property
    def odometry_scale(self) -> tuple[float, float]:
        """(distance, turn) factors that bring the odometry to the scans' measure: the scans'
        distance (turn) over the odometry's, summed over the node steps the scans measured to
        ``odometry_calibration_sigma`` along the motion; 1 until the odometry has gone 5 m
        (turned 3 rad) over such steps, or with ``odometry_calibrate`` off."""
        d_scan, d_odo, r_scan, r_odo = self._odometry_sums
        if not self.cfg.odometry_calibrate:
            return 1.0, 1.0
        return (d_scan / d_odo if d_odo >= 5.0 else 1.0, r_scan / r_odo if r_odo >= 3.0 else 1.0)

    def _calibrated(self, step: np.ndarray) -> np.ndarray:
        """An odometry step (dx, dy, dθ) in the scans' measure (:attr:`odometry_scale`)."""
        k_d, k_r = self.odometry_scale
        return step * (k_d, k_d, k_r)

    def _measurement(self, c: Constraint) -> tuple[np.ndarray, np.ndarray]:
        """(z, cov) of a constraint for an optimisation: an odometry constraint's step in the
        calibration of the moment, so that the spans tied before the scans had calibrated the
        odometry (a raw log's first metres, at scale 1) do not keep the wheels' error."""
        if c.raw is None:
            return c.z, c.cov
        z = self._calibrated(c.raw)
        return z, odometry_covariance(z, self.cfg.odometry_sigma)

    def _calibrate_odometry(self, prev: int, k: int, rel: np.ndarray, cov: np.ndarray) -> None:
        """Add the node step ``rel`` (covariance ``cov``) to the odometry's calibration sums
        where the scans measured it: translation when its σ along the motion is within
        ``odometry_calibration_sigma`` (not along a corridor), turn when its σ is within a
        degree. Wheel odometry's scale is off by a few per cent and differs per robot (raw
        CARMEN logs' 1 m spans against their corrected poses: Intel 0.956 in distance, 0.944
        in turn; Freiburg 079 0.944, 0.985); the scans measure it in rooms."""
        a, b = self.nodes[prev].odometry, self.nodes[k].odometry
        if a is None or b is None:
            return
        step = between(a, b)
        d = float(np.hypot(step[0], step[1]))
        # the scans' step projected on the odometry's direction, their turn signed by its: a
        # norm of a noisy step is biased long (by σ²/2d: 2 % for 1 cm on Intel's 5 cm steps)
        add = np.zeros(4)
        if d > 1e-3:
            u = step[:2] / d
            if u @ cov[:2, :2] @ u <= self.cfg.odometry_calibration_sigma**2:
                add[:2] = (u @ rel[:2], d)
        if cov[2, 2] <= np.deg2rad(1.0) ** 2:
            add[2:] = (np.sign(step[2]) * rel[2], abs(step[2]))
        # a new array, not +=: copies of this object (__deepcopy__) share the old one
        self._odometry_sums = self._odometry_sums + add

    def _odometry_constraint(self, prev: int, k: int, rel: np.ndarray, cov: np.ndarray) -> None:
        """Tie the new node ``k`` (its scans' step ``rel`` from node ``prev``, covariance
        ``cov``) by odometry to the node its span started at, once the odometry has gone
        ``odometry_span`` since (or turned 1 rad), unless it fails ``odometry_gate`` against
        the scans' steps over the span; a node without odometry ends the span."""
        start = prev if self._odometry_from is None else self._odometry_from
        here, there = self.nodes[k].odometry, self.nodes[start].odometry
        if here is None or there is None:
            self._odometry_from = None if here is None else k
            self._odometry_chain = None
            return
        zero = (np.zeros(3), np.zeros((3, 3)))
        chain = compose_covariance(*(self._odometry_chain or zero), rel, cov)
        step = between(there, here)
        if np.hypot(step[0], step[1]) >= self.cfg.odometry_span or abs(step[2]) >= 1.0:
            raw, step = step, self._calibrated(step)
            step_cov = odometry_covariance(step, self.cfg.odometry_sigma)
            e = step - chain[0]
            e[2] = np.angle(np.exp(1j * e[2]))
            if e @ np.linalg.solve(chain[1] + step_cov, e) <= self.cfg.odometry_gate:
                self.constraints.append(Constraint(start, k, step, step_cov, True, "odometry", raw))
            else:
                self.stats["odometry_rejected"] += 1
            start, chain = k, None
        self._odometry_from, self._odometry_chain = start, chain
