"""Hector SLAM: scan-to-map Gauss-Newton matching on a multi-resolution occupancy grid.

The SLAM that Ueland 2017 runs in the NTNU basin ("Hector-SLAM ... does not require odometry data",
§Mapping of Environment; 0.2 m map resolution, RPLIDAR A1 at 5.5 Hz, §Experimental Results).
The algorithm is Kohlbrecher, Meyer, von Stryk and Klingauf, "A Flexible and Scalable SLAM
System with Full 3D Motion Estimation", SSRR 2011, §IV (2D SLAM), written here from the paper:

* Map access (§IV-A, eqs. 1-3): the map value M(Pm) ∈ [0, 1] at a continuous point is the
  bilinear interpolation of the four surrounding cells' occupancy probabilities, and its
  gradient ∇M = (∂M/∂x, ∂M/∂y) is the analytic derivative of that interpolant
  (:func:`interpolate_map`). Cell values sit at cell centres.
* Scan matching (§IV-B, eqs. 4-11): the sensor pose ξ = (pₓ, p_y, ψ) minimises

      ξ* = argmin_ξ Σᵢ [1 − M(Sᵢ(ξ))]²,                                       (eq. 4)
      Sᵢ(ξ) = R(ψ) sᵢ + (pₓ, p_y)                                              (eq. 5)

  for the scan end points sᵢ (sensor frame). Linearising M(Sᵢ(ξ + Δξ)) (eqs. 6-8) gives the
  Gauss-Newton step

      Δξ = H⁻¹ Σᵢ [∇M(Sᵢ(ξ)) ∂Sᵢ(ξ)/∂ξ]ᵀ [1 − M(Sᵢ(ξ))],                       (eq. 9)
      H = Σᵢ [∇M(Sᵢ(ξ)) ∂Sᵢ(ξ)/∂ξ]ᵀ [∇M(Sᵢ(ξ)) ∂Sᵢ(ξ)/∂ξ],                      (eq. 10)
      ∂Sᵢ/∂ξ = [[1, 0, −sin ψ sᵢₓ − cos ψ sᵢ_y], [0, 1, cos ψ sᵢₓ − sin ψ sᵢ_y]]  (eq. 11)

  (:func:`match_scan`). (Equation numbers as we read the paper.) Our one change: a step that
  does not lower eq. 4's cost is halved until it does. A wall one cell thick is a tent in the
  bilinear map, whose kink JᵀJ cannot see, and full steps overshoot it by more than they
  correct: without the halving, matching from 3 cm off cycled ±5 cm on a 0.05 m map.
* Multi-resolution map (§IV-C): one map per level, each with half the resolution of the one
  below (r, 2r, 4r, ...), all updated with the same matched pose; matching runs coarse to fine,
  each level starting from the previous level's estimate, so the coarse maps' wide basins of
  attraction absorb the motion between scans and the fine map gives the accuracy.
* Map updates: the paper inserts every scan; Kohlbrecher's ROS node (hector_mapping) only
  inserts one after the pose moved ``map_update_distance`` (0.4 m) or ``map_update_angle``
  (0.9 rad) since the last insertion, so per-scan errors do not feed back into the map. Both
  are available; the default (0, 0) inserts every scan.
* No odometry: the matcher starts from the previous pose, or from a constant-velocity
  prediction (the last relative motion applied once more), which is our choice, not the
  paper's.

Maps are :class:`~usvdrake.systems.slam.occupancy_mapping.LogOddsGrid` (Bresenham rays, the
log-odds Bayes filter); the probability grid of each level is computed once per update, after
the scan is inserted, and reused by every Gauss-Newton iteration of the next match. That costs
≈ 1.4 ms per 150 000 cells on the development machine, so it grows with the map's area:
windowed refreshes would need the grid to expose log-odds of a window. A 360-beam RPLIDAR
scan takes ≈ 3 ms (median) on a 0.05 m, 3-level map of the basin (44 m × 8.5 m).

Accuracy limit: an end point enters the cell that contains it and the cell's value sits at the
cell centre, so a wall lying on a cell boundary appears half a cell away; the pose follows
the map, so walls aligned with the grid bias the pose by up to half a cell per axis.

Frames: the grid's (x, y) frame is the world frame of the map; poses are the *sensor's* pose
(x [m], y [m], ψ [rad]); scan points are in the sensor frame (x forward, y left).
"""

import time
from dataclasses import dataclass, field

import numpy as np

from usvdrake.sensors.messages import LaserScan
from usvdrake.systems.slam.occupancy_mapping import LogOddsGrid

Pose2 = np.ndarray | tuple[float, float, float]  # (x [m], y [m], ψ [rad])


def interpolate_map(
    prob: np.ndarray, origin: tuple[float, float], resolution: float, xy: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bilinear map value M and its gradient ∇M at world points (Kohlbrecher eqs. 1-3).

    prob: (rows = y, cols = x) cell values [-], the value of cell (r, c) at its centre
    origin + ((c, r) + ½)·resolution; origin: (x, y) [m] of the corner of cell (0, 0);
    resolution [m]; xy: (n, 2) world points [m]. Returns (M (n,) [-], ∇M (n, 2) [1/m],
    inside (n,) bool). Points without four surrounding cell centres in the grid are not
    inside and get M = ½ (unknown) and ∇M = 0.
    """
    u = (xy[:, 0] - origin[0]) / resolution - 0.5
    v = (xy[:, 1] - origin[1]) / resolution - 0.5
    c0 = np.floor(u)
    r0 = np.floor(v)
    fx, fy = u - c0, v - r0
    rows, cols = prob.shape
    inside = (c0 >= 0) & (c0 < cols - 1) & (r0 >= 0) & (r0 < rows - 1)
    c0 = np.where(inside, c0, 0).astype(np.intp)
    r0 = np.where(inside, r0, 0).astype(np.intp)
    flat = prob.ravel()
    i00 = r0 * cols + c0
    p00, p01 = flat[i00], flat[i00 + 1]  # p_rc: r = row offset (y), c = column offset (x)
    p10, p11 = flat[i00 + cols], flat[i00 + cols + 1]
    bottom = p00 + fx * (p01 - p00)  # along x at row r0
    top = p10 + fx * (p11 - p10)  # along x at row r0 + 1
    m = bottom + fy * (top - bottom)
    grad = np.empty((len(m), 2))
    grad[:, 0] = ((1.0 - fy) * (p01 - p00) + fy * (p11 - p10)) / resolution
    grad[:, 1] = (top - bottom) / resolution
    m = np.where(inside, m, 0.5)
    grad[~inside] = 0.0
    return m, grad, inside


def _gauss_newton_system(
    prob: np.ndarray,
    origin: tuple[float, float],
    resolution: float,
    points: np.ndarray,
    pose: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """H (eq. 10), the right-hand side of eq. 9, Σ[1 − M]² and the number of points used."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    sx, sy = points[:, 0], points[:, 1]
    world = np.column_stack([c * sx - s * sy + pose[0], s * sx + c * sy + pose[1]])
    m, grad, inside = interpolate_map(prob, origin, resolution, world)
    jac = np.empty((len(m), 3))  # ∇M ∂Sᵢ/∂ξ (eq. 11), one row per point
    jac[:, :2] = grad
    jac[:, 2] = grad[:, 0] * (-s * sx - c * sy) + grad[:, 1] * (c * sx - s * sy)
    resid = np.where(inside, 1.0 - m, 0.0)  # outside points carry no information
    return jac.T @ jac, jac.T @ resid, float(resid @ resid), int(inside.sum())


def match_scan(
    prob: np.ndarray,
    origin: tuple[float, float],
    resolution: float,
    points: np.ndarray,
    initial_pose: Pose2,
    iterations: int = 5,
    tolerance: float = 1e-5,
    max_halvings: int = 4,
) -> tuple[np.ndarray, np.ndarray, float, int]:
    """Gauss-Newton scan-to-map matching on one map (Kohlbrecher eqs. 4-11).

    prob, origin [m], resolution [m]: the map as in :func:`interpolate_map`; points: (n, 2)
    scan end points in the sensor frame [m]; initial_pose: (x [m], y [m], ψ [rad]);
    iterations: at most this many steps; tolerance: stop when every |Δξ| component is below
    it [m, rad]; max_halvings: step halvings tried before giving up when a Gauss-Newton
    step does not lower the cost (our addition to eq. 9). Returns (pose, H at the pose,
    Σ[1 − M]² [-], points inside the map).
    """
    pose = np.array(initial_pose, dtype=float)
    hess, rhs, cost, used = _gauss_newton_system(prob, origin, resolution, points, pose)
    # A small damping keeps H invertible when the scan constrains a direction weakly (a
    # featureless corridor); it is far below H's entries for a useful scan (~n/resolution²).
    damping = 1e-6 * np.eye(3)
    for _ in range(iterations):
        if used < 3:
            break
        step = np.linalg.solve(hess + damping * max(np.trace(hess), 1.0), rhs)
        if not np.all(np.isfinite(step)):
            break
        # Backtracking: JᵀJ underestimates the curvature of Σ[1 − M]² at the kinks of the
        # bilinear map (a one-cell wall is a tent), so full steps overshoot and can cycle.
        # Halving until the cost drops keeps each iteration a descent step.
        for _ in range(max_halvings + 1):
            trial = pose + step
            trial[2] = (trial[2] + np.pi) % (2.0 * np.pi) - np.pi
            system = _gauss_newton_system(prob, origin, resolution, points, trial)
            if system[2] < cost and system[3] >= used:
                break
            step *= 0.5
        else:
            break
        pose = trial
        hess, rhs, cost, used = system
        if np.all(np.abs(step) < tolerance):
            break
    return pose, hess, cost, used


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SE(2) pose a ⊕ b."""
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def _between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """SE(2) pose a⁻¹ ⊕ b: b seen from a."""
    c, s = np.cos(a[2]), np.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    dpsi = (b[2] - a[2] + np.pi) % (2.0 * np.pi) - np.pi
    return np.array([c * dx + s * dy, -s * dx + c * dy, dpsi])


class HectorMapper:
    """Hector SLAM (Kohlbrecher et al. 2011 §IV; as Ueland 2017 uses it): multi-resolution log-odds
    maps and Gauss-Newton scan-to-map matching, without odometry.

    origin: (x, y) [m] of the maps' south-west corner; size: (width along x, height along y)
    [m] of the mapped area; resolution: finest cell size [m] (Ueland 2017 used 0.2 m; the level
    ``k`` map has cells of resolution·2ᵏ); levels: number of maps in the pyramid;
    initial_pose: (x [m], y [m], ψ [rad]) of the sensor at the first scan, which is inserted
    there unmatched; iterations: Gauss-Newton steps per level at most; predict: start each
    match from a constant-velocity prediction (True) or from the previous pose (False);
    min_points: scans with fewer end points are inserted at the predicted pose unmatched;
    l_occ, l_free [-]: log-odds increments of :class:`LogOddsGrid` (defaults as there).
    """

    def __init__(
        self,
        origin: tuple[float, float],
        size: tuple[float, float],
        resolution: float = 0.05,
        levels: int = 3,
        initial_pose: Pose2 = (0.0, 0.0, 0.0),
        iterations: int = 5,
        predict: bool = True,
        min_points: int = 20,
        map_update_distance: float = 0.0,
        map_update_angle: float = 0.0,
        l_occ: float = 0.85,
        l_free: float = -0.62,
    ):
        if levels < 1 or resolution <= 0.0 or min(size) <= 0.0:
            raise ValueError("need levels ≥ 1, resolution > 0 and a positive size")
        self.origin = (float(origin[0]), float(origin[1]))
        self.iterations = int(iterations)
        self.predict = bool(predict)
        self.min_points = int(min_points)
        self.map_update_distance = float(map_update_distance)
        self.map_update_angle = float(map_update_angle)
        self._map_pose: np.ndarray | None = None  # pose of the latest scan put in the maps
        self.grids: list[LogOddsGrid] = []  # finest first
        for k in range(levels):
            res = resolution * 2**k
            shape = (int(np.ceil(size[1] / res)), int(np.ceil(size[0] / res)))
            self.grids.append(LogOddsGrid(self.origin, res, shape, l_occ=l_occ, l_free=l_free))
        self._prob = [g.probability() for g in self.grids]
        self.pose = np.array(initial_pose, dtype=float)  # [m, m, rad] latest sensor pose
        self._previous: np.ndarray | None = None
        self.hessian = np.zeros((3, 3))  # eq. 10 on the finest map at the latest pose
        self.residual_variance = 0.0  # [-] Σ[1 − M]² / (n − 3) of the latest match
        self.scans = 0  # scans processed
        self.stats = {"tracking_ms": []}  # [ms] wall time of each scan update

    @property
    def resolution(self) -> float:
        """Finest cell size [m]."""
        return self.grids[0].resolution

    @property
    def covariance(self) -> np.ndarray:
        """Covariance of the latest pose, σ² H⁻¹ [m², m·rad, rad²] (x, y, ψ).

        The least-squares covariance of eq. 4 at its minimum: H is eq. 10 on the finest map
        and σ² = Σ[1 − M]² / (n − 3) the residual variance of the map values [-]. It treats
        the map as exact and the beams as independent, so it is a relative, usually
        optimistic, measure; Kohlbrecher et al. give no scale. Infinite before the first match
        or when H is singular.
        """
        if self.scans < 2 or np.linalg.cond(self.hessian) > 1e12:
            return np.full((3, 3), np.inf)
        return self.residual_variance * np.linalg.inv(self.hessian)

    def probability(self, level: int = 0) -> np.ndarray:
        """The cached occupancy probability of one level [-], (rows, cols), finest = 0."""
        return self._prob[level]

    def match(self, points: np.ndarray, initial_pose: Pose2) -> tuple[np.ndarray, np.ndarray]:
        """Scan-to-map matching, coarse to fine through the pyramid (§IV-B, §IV-C).

        points: (n, 2) end points in the sensor frame [m]; initial_pose: (x [m], y [m],
        ψ [rad]). Returns (pose, H): the matched sensor pose and eq. 10's H on the finest map.
        """
        points = np.asarray(points, dtype=float).reshape(-1, 2)
        pose = np.array(initial_pose, dtype=float)
        cost, used = 0.0, 0
        hess = np.zeros((3, 3))
        for level in reversed(range(len(self.grids))):
            grid = self.grids[level]
            pose, hess, cost, used = match_scan(
                self._prob[level], grid.origin, grid.resolution, points, pose, self.iterations
            )
        self.residual_variance = cost / max(used - 3, 1)
        return pose, hess

    # --- the scan-SLAM backend protocol of ``LidarSlam2D`` ------------------------------------
    def process_scan(self, scan, max_range: float | None = None) -> None:
        t0 = time.perf_counter()
        self.update(scan.ranges, scan.angles, max_range or scan.range_max)
        self.stats["tracking_ms"].append((time.perf_counter() - t0) * 1e3)

    @property
    def sensor_pose(self) -> np.ndarray:
        return self.pose

    def pose_covariance(self) -> np.ndarray:
        return self.covariance

    def occupancy(self):
        return self.grids[0].to_occupancy_grid()

    def background(self) -> None:
        """Hector has no deferred work."""

    def update(self, ranges: np.ndarray, angles: np.ndarray, max_range: float) -> np.ndarray:
        """Process one scan: match it against the maps, then insert it into every level.

        ranges [m] and angles [rad] (sensor frame) of each beam; max_range [m]: ranges ≥ it,
        ``inf``, NaN or ≤ 0 are no-returns (they clear free space, :meth:`LogOddsGrid.
        insert_scan`, but are not matched). The first scan is inserted at ``initial_pose``.
        Returns the sensor pose (x [m], y [m], ψ [rad]).
        """
        ranges = np.asarray(ranges, dtype=float)
        angles = np.broadcast_to(np.asarray(angles, dtype=float), ranges.shape)
        hit = (ranges > 0.0) & (ranges < max_range)
        points = np.column_stack(
            [ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])]
        )
        if self.scans > 0:
            guess = self.pose
            if self.predict and self._previous is not None:
                guess = _compose(self.pose, _between(self._previous, self.pose))
            self._previous = self.pose
            if len(points) >= self.min_points:
                self.pose, self.hessian = self.match(points, guess)
            else:
                self.pose = guess
        if self._map_pose is None or self._moved_enough():
            self._map_pose = self.pose.copy()
            for k, grid in enumerate(self.grids):
                grid.insert_scan(self.pose, ranges, angles, max_range)
                self._prob[k] = grid.probability()
        self.scans += 1
        return self.pose.copy()

    def _moved_enough(self) -> bool:
        d = _between(self._map_pose, self.pose)
        return bool(
            np.hypot(d[0], d[1]) >= self.map_update_distance or abs(d[2]) >= self.map_update_angle
        )

    def update_laser_scan(self, scan: LaserScan) -> np.ndarray:
        """:meth:`update` with a :class:`LaserScan` (invalid beams are no-returns)."""
        r = np.where(scan.valid, scan.ranges, np.inf)
        return self.update(r, scan.angles, scan.range_max)


@dataclass
class HectorConfig:
    resolution: float = (
        0.05  # [m] finest map cell (Ueland 2017 maps the basin at 0.2 m; 0.05 matches better)
    )
    levels: int = 3  # map pyramid levels (r, 2r, 4r)
    map_origin: list[float] = field(default_factory=lambda: [-2.025, -1.025])  # [m]
    map_size: list[float] = field(default_factory=lambda: [44.0, 8.5])  # [m] width, height
    iterations: int = 5  # Gauss-Newton steps per level
    map_update_distance: float = 0.0  # [m] insert a scan only after this much motion
    map_update_angle: float = 0.0  # [rad] or this much rotation
    max_range: float = 12.0  # [m] beams at or beyond it are no-returns


def make_hector(cfg: HectorConfig, initial_pose) -> "HectorMapper":
    return HectorMapper(
        tuple(cfg.map_origin),
        tuple(cfg.map_size),
        resolution=cfg.resolution,
        levels=cfg.levels,
        initial_pose=tuple(initial_pose),
        iterations=cfg.iterations,
        map_update_distance=cfg.map_update_distance,
        map_update_angle=cfg.map_update_angle,
    )
