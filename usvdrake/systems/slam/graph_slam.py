"""Sliding-window 2D lidar graph SLAM of 002 §II-C, §III-B, §IV-B (numerical core).

* **Tracking**: every scan is matched by PLICP (002 eqs. 1-3) against the latest node's scan,
  starting from the previous relative motion; the pose is the node's pose composed with it.
  A poor match (``correlative_trigger``; 0: every scan) is re-seeded by the branch-and-bound
  correlative search (Olson 2009, :mod:`correlative`) over ± ``search_linear_window`` /
  ± ``search_angular_window``, which wins if its likelihood is ``search_prior_margin`` higher
  (if the scans' stamps give the motion a time base; otherwise the higher likelihood wins).
  With ``field_refine_unconverged``, a PLICP refinement of the searched pose that does not
  converge competes with a Gauss-Newton ascent of the search's likelihood field (Hector's).
* **Nodes**: a new node when the match exceeds ``node_translation`` or ``node_rotation``. Its
  consecutive constraint (to the previous node) carries the Censi covariance (002 eqs. 4-10)
  — or, with ``landscape_temperature``, the spread of the tracking field's score around the
  match (Olson 2009 §III-C), which is wide where the scene leaves a direction free — and is
  robustified with Barron's kernel (002 eqs. 13-14, ``alpha``, ``c``); it is also
  densely linked (plain Gaussian) to the window's nodes within ``link_radius`` whose match
  converges with a small residual.
* **Optimisation**: Levenberg-Marquardt (gtsam, at most 100 iterations, as 002 §V-A) over the
  nodes of the sliding window; nodes outside it that constrain it are held fixed by tight priors,
  so the update time does not grow with the map.
* **Loops** (002 §II-C): a node whose index differs from an older node's by ``loop_index_gap``
  and lies within ``loop_radius`` of it is matched to it (from the graph's relative pose, with
  PLICP's rotation search); an accepted match adds a robustified loop constraint and marks the
  whole graph for optimisation, which :meth:`GraphSlam.optimise_pending` runs when the caller
  decides (its own slower event in ``LidarSlam2D``, so the per-scan update never stalls).
  For logs whose drift outgrows PLICP's basin (ours, not 002's): ``loop_per_chain`` matches one
  node per earlier pass; ``loop_linear_window`` > 0 first searches the new node's recent scans
  against the candidate's neighbours by the correlative matcher and refuses fits that are weak
  (``min_loop_score``) or repeated elsewhere in the window (``max_loop_ambiguity``: corridors);
  ``loop_gnc`` makes loops Gaussian and lets each full optimisation reject inconsistent ones by
  graduated non-convexity (Yang et al. 2020, gtsam's GncLMOptimizer with the TLS loss).
* **Map** (002 §IV): a log-odds grid; a node's scan is inserted when the node is created and
  re-rendered (removed at its old pose, inserted at its new one) when optimisation moved it by
  more than ``rerender_translation`` / ``rerender_rotation``.

Everything is plain Python/numpy/gtsam state in one object, so a LeafSystem can keep it in the
Context and ``copy.deepcopy`` it.
"""

import copy
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from usvdrake.systems.slam.censi_covariance import plicp_covariance
from usvdrake.systems.slam.correlative import (
    LikelihoodField,
    correlative_match,
    lateral_motion,
    match_covariance,
)
from usvdrake.systems.slam.hector import match_scan
from usvdrake.systems.slam.occupancy_mapping import LogOddsGrid
from usvdrake.systems.slam.plicp import PlicpResult, plicp, plicp_at, rot
from usvdrake.systems.slam.pose_graph_solve import (
    PoseGraphProblem,
    PoseGraphSolution,
    SolveFailed,
    solve_pose_graph,
    solved,
    worker,
)
from usvdrake.systems.slam.robust_kernel import gtsam_barron


@dataclass
class GraphSlamConfig:
    node_translation: float = 0.5  # [m] motion since the last node that makes a new node
    node_rotation: float = 0.17  # [rad] (~10°) likewise
    window: int = 15  # [nodes] optimised together on each new node
    link_radius: float = 4.0  # [m] dense links to window nodes within this distance
    max_link_residual: float = 0.15  # [m] RMS point-to-line error accepting a match (≥ noise)
    # a tracking match whose residual exceeds this many max_link_residual is re-seeded by a
    # correlative search (Olson 2009); lower = more robust to large motions, slower
    correlative_trigger: float = 2.0
    search_linear_window: float = 1.2  # [m] ± translation of that search about the guess
    search_angular_window: float = 0.7  # [rad] (~40°) ± rotation of that search
    search_from_rest: bool = False  # centre it on no motion (True) or constant velocity
    # the searched pose replaces PLICP's from the constant-velocity guess only if its
    # likelihood score is higher by this much: along a featureless corridor the two tie and
    # the motion model decides (Olson 2009's motion prior, as a margin). A scan stamped no
    # later than the previous one (a log with identical stamps) gives the motion no time
    # base to extrapolate over: there the higher score wins
    search_prior_margin: float = 0.02
    # [1/m²] the search's and that choice's scores lose this × the step's sideways motion²
    # (correlative.lateral_motion: 0 along any arc; for vehicles that cannot slide; 0: off)
    lateral_weight: float = 0.0
    refine_max_distance: float = 1.0  # [m] PLICP's pairing distance refining the search
    # PLICP's refinement of the search's pose that does not converge (it slid along a corridor,
    # or cycles) is set against a Gauss-Newton ascent of the search's own likelihood field from
    # that pose (Kohlbrecher 2011 eqs. 4-11, hector.match_scan); the higher score is kept
    field_refine_unconverged: bool = False
    search_resolution: float = 0.05  # [m] its grid (and the likelihood field's cells)
    search_sigma: float = 0.1  # [m] width of a reference point in the likelihood field
    min_link_points: int = 40  # correspondences a match needs
    trim: float = 0.9  # fraction of PLICP's pairs kept, least point-to-line error first
    # [m] RMS point-to-line error above which a tracking match failed (garbage, a blinded or
    # half-empty scan): the pose follows the constant-velocity guess and the scan never
    # becomes a node, so it cannot become the reference of the scans after it
    max_track_residual: float = 0.2
    reanchor_after: int = 10  # [scans] failed in a row: the current scan becomes a node
    loop_index_gap: int = 40  # [nodes] index difference that makes a loop candidate
    loop_radius: float = 6.0  # [m] distance that makes a loop candidate
    max_loop_residual: float = 0.05  # [m] stricter acceptance for loops (a false loop is costly)
    min_loop_points: int = 100  # correspondences a loop match needs
    # [m] > 0: a loop candidate is first searched by the correlative matcher within this
    # window (and ± loop_angular_window) of the graph's relative pose, and kept only if its
    # likelihood score reaches min_loop_score; 0: PLICP's own rotation search (002)
    loop_linear_window: float = 0.0
    loop_submap: int = 3  # [nodes] either side of a loop candidate (before the new node) matched
    # PLICP refines a searched loop against the candidate's submap (True) or its scan (False)
    loop_refine_submap: bool = False
    loop_robust: bool = True  # Barron-robustified loop constraints (False: Gaussian)
    # full optimisations reject outlier loops by GNC (TLS loss) instead of a robust kernel;
    # the loops' covariance gets this floor [m, m, rad] (what a correct loop may still be off)
    loop_gnc: bool = False
    loop_min_sigma: list[float] = field(default_factory=lambda: [0.03, 0.03, 0.01])
    loop_per_chain: bool = False  # match one node per pass near the new node, not every one
    loop_max_chains: int = 8  # [-] passes matched per new node, nearest first
    loop_angular_window: float = 0.5  # [rad]
    loop_distinct: float = 0.5  # [m] a runner-up pose this far from the best is a rival
    max_loop_ambiguity: float = 0.9  # [-] rival score / best score above which a loop is refused
    # [m] > 0: a searched loop's pose is searched again for the new node's scan alone, within
    # this window (and ± loop_rematch_angle [rad]) of the pose the recent scans found: those sit
    # where tracking put them relative to the new node, and one wrong step there moves the
    # whole query with it (ours; 0: the recent scans' pose is refined as it is)
    loop_rematch_window: float = 0.0
    loop_rematch_angle: float = 0.1
    min_loop_score: float = 0.5  # [-] mean likelihood of the loop scan's points, in [0, 1]
    # [m] > 0: after the last scan (GraphSlam.relink, offline), every node is matched by PLICP
    # from the final estimate to the older nodes within this radius (index gap ≥ 2; at most
    # relink_max_links of them, spread over their indices; 0: all), a match moving less than
    # relink_max_correction [m] from it, scoring min_loop_score and passing the link checks is
    # added as a loop (GNC candidate, tracking covariance), and the whole graph is optimised
    # once more (ours, not 002's)
    relink_radius: float = 0.0
    relink_max_links: int = 0
    relink_max_correction: float = 0.3
    alpha: float = 0.0  # Barron α of the robustified constraints (0: Cauchy)
    c: float = 1.0  # Barron scale c (in units of the whitened error)
    range_sigma: float = 0.02  # [m] range noise for the Censi covariance
    # > 0: consecutive constraints take the spread of the tracking field's score around the
    # match at this temperature (Olson 2009 §III-C, correlative.match_covariance) above the
    # min_sigma floor, instead of Censi's closed form, which stays centimetre-small along a
    # corridor (ours, not 002's; 0: Censi's)
    landscape_temperature: float = 0.0
    min_sigma: list[float] = field(default_factory=lambda: [0.01, 0.01, 0.005])  # [m, m, rad] floor
    # Wheel odometry, when the scans come with it (GraphSlam.process's ``odometry``; ours, not
    # 002's, which has none). It ties a node to the node where the odometry had gone
    # odometry_span [m] (or 1 rad) before, a robust constraint
    # with a random walk's covariance of [m/√m travelled, rad/√rad turned, rad/√m travelled]
    # (odometry_covariance): along a corridor, where the scans do not measure the motion, it
    # does. A span, not every step: logged odometry drops out and catches up (raw MIT-CSAIL
    # reads no motion for 4 scans while the robot moved 0.65 m, then a 0.34 m step for 0.22 m)
    odometry_sigma: list[float] = field(default_factory=lambda: [0.05, 0.3, 0.05])
    odometry_span: float = 1.0
    # an odometry constraint is left out when it disagrees with the scans' own chain of
    # steps over its span: χ² of the difference under both covariances above this (3 dof,
    # 16.27: p = 0.001). Raw Freiburg 079's logged odometry has gross errors while the robot
    # manoeuvres (a 2.2 m forward step where the scans and the corrected poses back up 2.3 m):
    # robustified only, they took its ATE from 0.09 to 1.3 m over the first 1800 scans.
    # Along a corridor the chain's covariance is long, the gate wide: the odometry stays
    odometry_gate: float = 16.27
    # odometry also seeds a second tracking match beside the constant velocity's, kept unless
    # that one scores search_prior_margin higher. Off: on raw MIT-CSAIL, whose logged odometry
    # lags and jitters by up to 0.3 rad a scan, it took the ATE from 0.21 to 0.29 m
    odometry_seed: bool = False
    # the odometry's distance and turn are scaled by what the scans measured where they could
    # (GraphSlam.odometry_scale): steps whose tracking σ along the motion is within this [m]
    odometry_calibrate: bool = True
    odometry_calibration_sigma: float = 0.02
    max_iterations: int = 100  # LM steps (002 §V-A)
    # the full optimisations a loop asks for run in a worker process (002: its own thread),
    # started and merged by the caller's slower event (GraphSlam.background); False: inline
    full_in_worker: bool = True
    # De-skew each scan to its last beam with the last scan-to-scan motion as a constant
    # twist, when the scan says its beams fired over time (``LaserScan.time_increment`` > 0).
    # Ours, not 002's: on valley_survey the sweep's own motion biased the matches while
    # turning (180 s: online ATE 0.153 m with the motion simulated, 0.052 m without).
    deskew: bool = True
    map_resolution: float = 0.2  # [m] online map (002 §V-B: 0.4 m in the valley)
    map_origin: list[float] = field(default_factory=lambda: [-150.0, -150.0])  # [m]
    map_size: list[float] = field(default_factory=lambda: [300.0, 300.0])  # [m] width, height
    max_range: float = 30.0  # [m] beyond this a beam counts as no return for the map
    rerender_translation: float = 0.05  # [m]
    rerender_rotation: float = 0.01  # [rad]


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊕ b for planar poses (x, y, θ)."""
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def deskew_scan(points: np.ndarray, age: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """2D points (n × 2) [m], each measured ``age`` [s] before the scan's time in the sensor
    frame of its firing instant, expressed in the frame at the scan's time, the sensor moving
    with the constant twist (v_x, v_y [m/s], ω [rad/s]) of its own frame: the planar case of
    :func:`usvdrake.systems.slam.lidar_inertial.deskew`."""
    from usvdrake.systems.slam.lidar_inertial import deskew

    vx, vy, w = np.asarray(twist, float)
    p3 = np.column_stack([points, np.zeros(len(points))])
    return deskew(p3, age, np.array([0.0, 0.0, w]), np.array([vx, vy, 0.0]))[:, :2]


def body_pose(sensor_pose: np.ndarray, mount: np.ndarray) -> np.ndarray:
    """The vessel's pose (x, y, θ) from its sensor's, the sensor mounted at ``mount`` = (x, y,
    θ) in the body frame: sensor ⊕ mount⁻¹."""
    return compose(np.asarray(sensor_pose, float), between(np.asarray(mount, float), np.zeros(3)))


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


def compose_covariance(a, cov_a, b, cov_b) -> tuple[np.ndarray, np.ndarray]:
    """(a ⊕ b, its covariance) to first order for independent planar poses a, b with
    covariances ``cov_a``, ``cov_b`` (each in its own earlier frame): J_a Σ_a J_aᵀ + J_b Σ_b
    J_bᵀ, J_a = ∂(a ⊕ b)/∂a = [[1, 0, −(R_a b)_y], [0, 1, (R_a b)_x], [0, 0, 1]], J_b =
    diag(R_a, 1) (Smith, Self & Cheeseman 1990's compounding)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c, s = np.cos(a[2]), np.sin(a[2])
    rb = np.array([c * b[0] - s * b[1], s * b[0] + c * b[1]])
    j_a = np.array([[1.0, 0.0, -rb[1]], [0.0, 1.0, rb[0]], [0.0, 0.0, 1.0]])
    j_b = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cov = j_a @ np.asarray(cov_a, float) @ j_a.T + j_b @ np.asarray(cov_b, float) @ j_b.T
    return compose(a, b), cov


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a⁻¹ ⊕ b: b expressed in a's frame; for stacks of poses (… × 3) row by row."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    dth = np.angle(np.exp(1j * (b[..., 2] - a[..., 2])))
    return np.stack([c * dx + s * dy, -s * dx + c * dy, dth], axis=-1)


class _AppendLog:
    """An append-only list shared by copies of a :class:`GraphSlam`; each copy remembers how
    many entries are its own and forks the list if another copy appended first."""

    def __init__(self, items=None):
        self.items = [] if items is None else items


@dataclass
class Node:
    pose: np.ndarray  # (x, y, θ) in the map frame
    points: np.ndarray  # (n, 2) scan points, sensor frame
    ranges: np.ndarray  # for the map
    angles: np.ndarray
    time: float
    rendered_pose: np.ndarray | None = None  # the pose its scan is in the map with
    # index in GraphSlam.constraints of its first constraint: every constraint is added with
    # its newest node as ``j``, so the constraints touching nodes ≥ k are those from node k's on
    first_constraint: int = 0
    tree: cKDTree | None = None
    odometry: np.ndarray | None = None  # the odometry pose its scan came with, if any
    _field: LikelihoodField | None = None

    def field(self, cfg: "GraphSlamConfig") -> LikelihoodField:
        """The likelihood field of its scan for the tracking search (built on first use,
        shared by copies, dropped once a newer node takes over; loops search fields of
        submaps)."""
        if self._field is None:
            self._field = LikelihoodField.build(
                self.points,
                cfg.search_resolution,
                cfg.search_sigma,
                margin=cfg.search_linear_window + 1.0,
            )
        return self._field


@dataclass
class Constraint:
    i: int
    j: int
    z: np.ndarray  # (x, y, θ) of node j in node i's frame
    cov: np.ndarray  # 3 × 3
    robust: bool
    kind: str  # "consecutive", "odometry", "link", "loop"


class GraphSlam:
    def __init__(self, cfg: GraphSlamConfig, initial_pose=(0.0, 0.0, 0.0)):
        self.cfg = cfg
        self.nodes: list[Node] = []
        self.constraints: list[Constraint] = []
        self.pose = np.asarray(initial_pose, float)
        self._rel = np.zeros(3)  # current scan relative to the last node
        self._last_step = np.zeros(3)
        self._odometry: np.ndarray | None = None  # odometry pose of the last tracked scan
        self._odometry_from: int | None = None  # the node the next odometry constraint is from
        # (scan distance, odometry distance, scan turn, odometry turn) summed over the steps the
        # scans measured well: the odometry's calibration (_calibrate_odometry)
        self._odometry_sums = np.zeros(4)
        # (pose, covariance) of the scans' consecutive steps since the odometry span started
        self._odometry_chain: tuple[np.ndarray, np.ndarray] | None = None
        self._last_t: float | None = None  # [s] time of the last tracked scan
        self._last_dt = 0.0  # [s] between the last two tracked scans
        self._twist: np.ndarray | None = None  # (v_x, v_y, ω) of the sensor, smoothed
        self._fail_streak = 0  # tracking matches failed in a row
        self._rejected: frozenset[int] = frozenset()  # loop constraints GNC called outliers
        # [m] (x, y) of every node, kept with Node.pose: the loop candidates' distances
        self._xy = np.zeros((0, 2))
        res = cfg.map_resolution
        shape = (int(cfg.map_size[1] / res), int(cfg.map_size[0] / res))
        self.map = LogOddsGrid(tuple(cfg.map_origin), res, shape)
        self.stats = {
            "tracking_ms": [],
            "optimisation_ms": [],
            "full_optimisation_ms": [],
            "full_wait_ms": [],  # the scans' waits for a full optimisation still solving
            "loops": 0,
            "failed_matches": 0,
            "odometry_rejected": 0,  # odometry constraints left out by odometry_gate
        }
        self.full_pending = False
        self._full_job = None  # (job, problem, node count) of the running full optimisation
        self._anchors, self._n_anchors = _AppendLog(), 0  # (time, node, pose relative to it)
        gtsam_barron(cfg.alpha, cfg.c)  # a bad α or c fails here, not at the first solve

    # --- per scan -----------------------------------------------------------------------------
    def process(
        self,
        points: np.ndarray,
        ranges: np.ndarray,
        angles: np.ndarray,
        t: float,
        odometry=None,
    ) -> np.ndarray:
        """Track one scan; returns the current pose (x, y, θ). ``odometry``: the sensor's pose
        (x, y, θ) by wheel odometry when the scan was taken, in the odometry's own frame (only
        its steps are used), or None. Its steps between nodes, scaled by what the scans
        measured (:attr:`odometry_scale`), become constraints (``odometry_span``,
        ``odometry_sigma``); with ``odometry_seed`` its step since the previous scan also seeds
        a tracking match."""
        t0 = time.perf_counter()
        odometry_step = self._odometry_step(odometry)
        if odometry_step is not None:
            odometry_step = self._calibrated(odometry_step)
        motion = self._last_step if odometry_step is None else odometry_step
        if len(points) < self.cfg.min_link_points:
            # too few returns to match (blinded, NaN): coast on the odometry or the constant
            # velocity
            self.stats["failed_matches"] += 1
            if self.nodes:
                self._rel = compose(self._rel, motion)
                self.pose = compose(self.nodes[-1].pose, self._rel)
                self._last_t = t  # the next step is measured from this coasted pose
                self._record(t)
            return self.pose.copy()
        if not self.nodes:
            self._add_node(self.pose.copy(), points, ranges, angles, t)
            self._record(t)
            self.stats["tracking_ms"].append((time.perf_counter() - t0) * 1e3)
            return self.pose.copy()
        last = self.nodes[-1]
        guess = compose(self._rel, self._last_step)  # constant velocity
        res = plicp(last.points, points, initial=tuple(guess), tree=last.tree, trim=self.cfg.trim)
        if odometry_step is not None and self.cfg.odometry_seed:
            # the odometry's guess, preferred unless the constant velocity's fits clearly better
            guess = compose(self._rel, odometry_step)
            by_odometry = plicp(
                last.points, points, initial=tuple(guess), tree=last.tree, trim=self.cfg.trim
            )
            if by_odometry.n_valid >= self.cfg.min_link_points and (
                res.n_valid < self.cfg.min_link_points
                or self._score(last, points, res)
                <= self._score(last, points, by_odometry) + self.cfg.search_prior_margin
            ):
                res = by_odometry
        trigger = self.cfg.correlative_trigger * self.cfg.max_link_residual
        if res.n_valid < self.cfg.min_link_points or res.residual > trigger:
            # a failed match from the constant-velocity guess: seed PLICP by a correlative search
            # over rotations × translations (Olson 2009) and keep the better of the two
            seed = correlative_match(
                last.field(self.cfg),
                points,
                self._rel if self.cfg.search_from_rest else guess,
                self.cfg.search_linear_window,
                self.cfg.search_angular_window,
                prior_from=self._rel,
                lateral_weight=self.cfg.lateral_weight,
            ).pose
            # the seed is good to a grid cell: refine it locally, PLICP must not wander off
            retry = plicp(
                last.points,
                points,
                initial=tuple(seed),
                tree=last.tree,
                max_distance=self.cfg.refine_max_distance,
                trim=self.cfg.trim,
            )
            if self.cfg.field_refine_unconverged and not retry.converged:
                alt = self._field_refine(last, points, seed)
                if alt.n_valid >= 3 and self._score(last, points, alt) > self._score(
                    last, points, retry
                ):
                    retry = alt
            # no time since the last scan (identical stamps): no motion model to favour
            timed = self._last_t is not None and t > self._last_t
            margin = self.cfg.search_prior_margin if timed else 0.0
            if retry.n_valid >= self.cfg.min_link_points and (
                res.n_valid < self.cfg.min_link_points
                or self._score(last, points, retry) > self._score(last, points, res) + margin
            ):
                res = retry
        failed = (
            res.n_valid < self.cfg.min_link_points
            or not np.isfinite(res.theta)
            or not res.residual <= self.cfg.max_track_residual
        )
        if failed:
            self.stats["failed_matches"] += 1
            self._fail_streak += 1
            rel = guess
        else:
            self._fail_streak = 0
            rel = res.pose
        self._last_step = between(self._rel, rel)
        self._last_dt = t - self._last_t if self._last_t is not None else 0.0
        self._last_t = t
        if self._last_dt > 0:  # the sensor's twist, smoothed over ~5 scans (PLICP's step noise)
            twist = self._last_step / self._last_dt
            self._twist = (
                twist if self._twist is None else self._twist + 0.2 * (twist - self._twist)
            )
        self._rel = rel
        self.pose = compose(last.pose, rel)
        if not failed and (
            np.hypot(rel[0], rel[1]) > self.cfg.node_translation
            or abs(rel[2]) > self.cfg.node_rotation
        ):
            cov = (
                self._tracking_covariance(last, points, res)
                if res.n_valid >= self.cfg.min_link_points
                else None
            )
            self._new_node(points, ranges, angles, t, rel, cov)
        elif failed and self._fail_streak >= self.cfg.reanchor_after:
            # the last node itself may be the problem (e.g. a garbage first scan): start a new
            # reference here, at the coasted pose, tied to the last by a weak constraint
            self._new_node(points, ranges, angles, t, rel, None)
            self._fail_streak = 0
        self._record(t)
        self.stats["tracking_ms"].append((time.perf_counter() - t0) * 1e3)
        return self.pose.copy()

    def _odometry_step(self, odometry) -> np.ndarray | None:
        """The odometry step since the last tracked scan (None without odometry now or then),
        and ``odometry`` kept for the next scan and the next node."""
        previous = self._odometry
        self._odometry = None
        if odometry is None:
            return None
        odometry = np.asarray(odometry, float).reshape(-1)
        if odometry.shape != (3,):
            raise ValueError(f"GraphSlam.process: odometry must be (x, y, θ), got {odometry}")
        if not np.all(np.isfinite(odometry)):
            return None  # a broken reading: as if there were none
        self._odometry = odometry
        return None if previous is None else between(previous, odometry)

    def _field_refine(self, node: Node, points: np.ndarray, seed) -> PlicpResult:
        """``points`` matched to ``node``'s scan by Gauss-Newton on its tracking likelihood
        field (values in [0, 1], 1 on the surfaces: the map M of Kohlbrecher 2011 eqs. 4-11,
        bilinearly interpolated, :func:`hector.match_scan`) from ``seed``, as a
        :class:`PlicpResult` at that pose (:func:`plicp_at`). The field is the objective the
        correlative search maximised on its grid, so this ascends to its maximum between the
        grid's cells instead of sliding to PLICP's distant fixed point."""
        field = node.field(self.cfg)
        pose = match_scan(
            field.fine, tuple(field.origin), field.resolution, points, seed, iterations=20
        )[0]
        return plicp_at(
            node.points,
            points,
            pose,
            max_distance=self.cfg.refine_max_distance,
            trim=self.cfg.trim,
            tree=node.tree,
        )

    def _score(self, node: Node, points: np.ndarray, res) -> float:
        """Likelihood score of ``points`` at a match result in ``node``'s field, less the
        sideways-motion penalty (``lateral_weight``) of the step from the previous scan."""
        pose = res.pose
        penalty = self.cfg.lateral_weight * lateral_motion(self._rel, pose) ** 2
        return node.field(self.cfg).score(points, pose) - penalty

    def _record(self, t: float) -> None:
        if len(self._anchors.items) != self._n_anchors:  # another copy appended: fork
            self._anchors = _AppendLog(self._anchors.items[: self._n_anchors])
        self._anchors.items.append((t, len(self.nodes) - 1, self._rel.copy()))
        self._n_anchors += 1

    def final_trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """(times, poses n × 3) of every tracked scan, re-expressed from its node's current
        (optimised) pose — the SLAM's final trajectory estimate, as benchmarks score it."""
        items = self._anchors.items[: self._n_anchors]
        if not items:
            return np.zeros(0), np.zeros((0, 3))
        t = np.array([i[0] for i in items])
        return t, np.array([compose(self.nodes[k].pose, rel) for _, k, rel in items])

    @property
    def _floor(self) -> np.ndarray:
        """The constraints' covariance floor, diag(``min_sigma``²)."""
        return np.diag(np.square(self.cfg.min_sigma))

    def _tracking_covariance(self, node: Node, points: np.ndarray, res) -> np.ndarray:
        """The consecutive constraint's covariance: Censi's, or with ``landscape_temperature``
        the spread of ``node``'s tracking field (:func:`match_covariance`) above the
        ``min_sigma`` floor."""
        if self.cfg.landscape_temperature <= 0:
            return self._covariance(node.points, points, res)
        pose = res.pose
        field = node.field(self.cfg)
        spread = match_covariance(field, points, pose, self.cfg.landscape_temperature)
        return spread + self._floor

    def _covariance(self, ref, cur, res) -> np.ndarray:
        try:
            cov = plicp_covariance(ref, cur, res, self.cfg.range_sigma)
        except np.linalg.LinAlgError:
            cov = self._floor * 100.0
        if not np.all(np.isfinite(cov)):
            return self._floor * 100.0
        return cov + self._floor

    # --- nodes and constraints ----------------------------------------------------------------
    def _add_node(self, pose, points, ranges, angles, t) -> Node:
        node = Node(pose, points, ranges, angles, t, tree=cKDTree(points))
        node.odometry = self._odometry
        node.first_constraint = len(self.constraints)
        self.nodes.append(node)
        self._sync_xy()
        self._render(node)
        return node

    def _new_node(self, points, ranges, angles, t, rel, cov) -> None:
        prev = len(self.nodes) - 1
        # only the latest node is searched by tracking: its predecessor's likelihood field
        # (megabytes per scan) goes, or a long log's fields fill the memory
        self.nodes[prev]._field = None
        node = self._add_node(self.pose.copy(), points, ranges, angles, t)
        k = len(self.nodes) - 1
        if cov is None:
            cov = self._floor * 100.0
        self.constraints.append(Constraint(prev, k, rel.copy(), cov, True, "consecutive"))
        self._calibrate_odometry(prev, k, rel, cov)
        self._odometry_constraint(prev, k, rel, cov)
        self._rel = np.zeros(3)
        lo = max(0, k - self.cfg.window)
        for i in range(lo, prev):
            other = self.nodes[i]
            if np.hypot(*(other.pose[:2] - node.pose[:2])) <= self.cfg.link_radius:
                self._link(i, k, robust=False, kind="link")
        loop = False
        for i in self._loop_candidates(k):
            loop |= self._link(i, k, robust=self.cfg.loop_robust, kind="loop", search=True)
        t0 = time.perf_counter()
        self.optimise(full=False)
        self.stats["optimisation_ms"].append((time.perf_counter() - t0) * 1e3)
        if loop:
            self.stats["loops"] += 1
            self.full_pending = True  # the whole graph, at the caller's pace (optimise_pending)

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
            step = self._calibrated(step)
            step_cov = odometry_covariance(step, self.cfg.odometry_sigma)
            e = step - chain[0]
            e[2] = np.angle(np.exp(1j * e[2]))
            if e @ np.linalg.solve(chain[1] + step_cov, e) <= self.cfg.odometry_gate:
                self.constraints.append(Constraint(start, k, step, step_cov, True, "odometry"))
            else:
                self.stats["odometry_rejected"] += 1
            start, chain = k, None
        self._odometry_from, self._odometry_chain = start, chain

    def _sync_xy(self, changed=()) -> None:
        """Bring the node positions' array up to date: rows for the nodes added since (by
        ``_add_node`` or behind its back), and the nodes ``changed`` that got a new pose. The
        loop candidates' search reads it instead of gathering every node's pose per new node."""
        n = len(self._xy)
        if n < len(self.nodes):
            self._xy = np.vstack([self._xy, [node.pose[:2] for node in self.nodes[n:]]])
        if len(changed):
            self._xy[list(changed)] = [self.nodes[k].pose[:2] for k in changed]

    def _loop_candidates(self, k: int) -> list[int]:
        """Older nodes (index gap > ``loop_index_gap``) within ``loop_radius`` of node k; with
        ``loop_per_chain``, only the nearest of each run of consecutive such nodes (one pass
        of the vessel), at most ``loop_max_chains`` of them, nearest first."""
        return self._near(
            k,
            self.cfg.loop_index_gap,
            self.cfg.loop_radius,
            self.cfg.loop_max_chains if self.cfg.loop_per_chain else None,
        )

    def _near(self, k: int, gap: int, radius: float, chains: int | None) -> list[int]:
        """Nodes whose index is more than ``gap`` below k within ``radius`` [m] of node k; with
        ``chains``, only the nearest of each run of consecutive such nodes (one pass of the
        vessel), at most ``chains`` of them, nearest first."""
        old = np.arange(max(0, k - gap))
        if not len(old):
            return []
        self._sync_xy()
        d = np.hypot(*(self._xy[old] - self.nodes[k].pose[:2]).T)
        near = old[d <= radius]
        if chains is None or not len(near):
            return list(near)
        runs = np.split(near, np.flatnonzero(np.diff(near) > 1) + 1)
        best = [int(run[np.argmin(d[run])]) for run in runs]
        best.sort(key=lambda i: d[i])
        return best[:chains]

    def _submap(self, k: int, indices) -> np.ndarray:
        """The scans of the nodes ``indices`` (those that exist) in node k's frame."""
        base = self.nodes[k].pose
        parts = []
        for j in indices:
            if 0 <= j < len(self.nodes):
                x, y, th = between(base, self.nodes[j].pose)
                parts.append(self.nodes[j].points @ rot(th).T + (x, y))
        return np.vstack(parts)

    def _link(self, i: int, k: int, robust: bool, kind: str, search: bool = False) -> bool:
        a, b = self.nodes[i], self.nodes[k]
        guess = between(a.pose, b.pose)
        rotation_search, pairing = search, 1.0  # PLICP's own rotation search, default pairing
        reference, tree, searched = a.points, a.tree, False
        if search and self.cfg.loop_linear_window > 0:
            h = self.cfg.loop_submap
            submap = self._submap(i, range(i - h, i + h + 1))
            candidate = LikelihoodField.build(
                submap,
                self.cfg.search_resolution,
                self.cfg.search_sigma,
                margin=self.cfg.loop_linear_window + 1.0,
            )
            match = correlative_match(
                candidate,
                self._submap(k, range(k - h, k + 1)),
                guess,
                self.cfg.loop_linear_window,
                self.cfg.loop_angular_window,
                distinct=self.cfg.loop_distinct,
                # only whether a rival comes that close matters, not its exact score
                rival_above=min(max(self.cfg.max_loop_ambiguity, 0.0), 1.0),
            )
            guess = match.pose
            # a weak fit, or one the scene repeats (a corridor): not a loop
            if (
                match.score < self.cfg.min_loop_score
                or match.runner_up > self.cfg.max_loop_ambiguity * match.score
            ):
                self.stats["failed_matches"] += 1
                return False
            if self.cfg.loop_rematch_window > 0:
                guess = correlative_match(
                    candidate,
                    b.points,
                    guess,
                    self.cfg.loop_rematch_window,
                    self.cfg.loop_rematch_angle,
                ).pose
            rotation_search, pairing, searched = False, self.cfg.refine_max_distance, True
            if self.cfg.loop_refine_submap:
                # the new scan refined against the candidate's whole submap (each of its scans
                # in beam order, so PLICP's scan-order neighbours stay on one scan; the jumps
                # between scans exceed max_segment): far more overlap than its single scan
                reference, tree = submap, cKDTree(submap)
        res = plicp(
            reference,
            b.points,
            initial=tuple(guess),
            tree=tree,
            rotation_search=rotation_search,
            max_distance=pairing,
        )
        loop = kind == "loop"
        need = self.cfg.min_loop_points if loop else self.cfg.min_link_points
        limit = self.cfg.max_loop_residual if loop else self.cfg.max_link_residual
        # a searched loop starts in the right basin: PLICP cycling between two correspondence
        # sets at the end (not converged) still leaves a good pose, which the residual checks
        settled = res.converged or (searched and self.cfg.loop_refine_submap)
        if not (settled and res.n_valid >= need and res.residual <= limit):
            self.stats["failed_matches"] += 1
            return False
        z = res.pose
        # (against a submap, Censi's covariance takes every reference point's range noise along
        # its bearing from node i, though its neighbours' points were ranged from elsewhere)
        self.constraints.append(
            Constraint(i, k, z, self._covariance(reference, b.points, res), robust, kind)
        )
        return True

    def relink(self, progress: bool = False) -> int:
        """Link every node to the older nodes within ``relink_radius`` (index gap ≥ 2, at most
        ``relink_max_links`` of them, evenly spread over their indices) by PLICP from the
        graph's current relative pose, and optimise the whole graph (after merging a full
        optimisation still running; with ``relink_radius`` 0 nothing happens). The
        final estimate is already consistent to a few centimetres where the tracking and the
        loops reach; the links then tie every pass to its neighbours several metres away, which
        the chain of ~1 m steps and the few 4 m loops constrain only through their noise. A
        match is kept if it converges within ``relink_max_correction`` [m] of the current
        relative pose, with ``min_link_points`` pairs, an RMS residual within
        ``max_link_residual`` and a likelihood score of at least ``min_loop_score``; it joins
        as a loop, so GNC may reject it. ``progress``: a progress bar over the nodes matched
        against. Returns the links added."""
        if self.cfg.relink_radius <= 0 or len(self.nodes) < 3:
            return 0
        t0 = time.perf_counter()
        self.finish_full()  # the links are matched from the latest estimate
        linked = {(c.i, c.j) for c in self.constraints}
        pairs: dict[int, list[int]] = {}  # reference node -> the nodes matched to it
        for k in range(2, len(self.nodes)):
            near = self._near(k, 1, self.cfg.relink_radius, None)
            most = self.cfg.relink_max_links
            if 0 < most < len(near):  # evenly over the older nodes' indices: every pass keeps some
                near = [
                    near[j]
                    for j in np.unique(np.linspace(0, len(near) - 1, most).round().astype(int))
                ]
            for i in near:
                if (i, k) not in linked:
                    pairs.setdefault(i, []).append(k)
        added = 0
        last = self.nodes[-1]
        order = sorted(pairs)
        if progress:
            from tqdm import tqdm

            order = tqdm(order, unit="node", desc="relink")
        for i in order:
            a = self.nodes[i]
            for k in pairs[i]:
                b = self.nodes[k]
                guess = between(a.pose, b.pose)
                res = plicp(
                    a.points,
                    b.points,
                    initial=tuple(guess),
                    tree=a.tree,
                    max_distance=self.cfg.refine_max_distance,
                    trim=self.cfg.trim,
                )
                z = res.pose
                if not (
                    res.converged
                    and res.n_valid >= self.cfg.min_link_points
                    and res.residual <= self.cfg.max_link_residual
                    and np.hypot(*(z[:2] - guess[:2])) <= self.cfg.relink_max_correction
                    and a.field(self.cfg).score(b.points, z) >= self.cfg.min_loop_score
                ):
                    continue
                cov = self._tracking_covariance(a, b.points, res)
                self.constraints.append(Constraint(i, k, z, cov, False, "loop"))
                added += 1
            if a is not last:  # one field at a time (megabytes each); tracking keeps the last's
                a._field = None
        self.stats["relinks"] = added
        if added:
            self.full_pending = True
            self.optimise_pending()
        self.stats["relink_ms"] = (time.perf_counter() - t0) * 1e3
        return added

    # --- optimisation ---------------------------------------------------------------------------
    # --- the scan-SLAM backend protocol of ``LidarSlam2D`` ------------------------------------
    def process_scan(self, scan, max_range: float | None = None, odometry=None) -> None:
        a, r = scan.angles, np.asarray(scan.ranges, float)
        with np.errstate(invalid="ignore"):  # NaN ranges (a broken driver): not returns
            v = np.asarray(scan.valid, bool) & np.isfinite(r) & (r > 0)
        r = np.where(v, r, np.inf)  # what the map renders: no return
        points = np.column_stack([r[v] * np.cos(a[v]), r[v] * np.sin(a[v])])
        if self.cfg.deskew and scan.time_increment > 0 and self._twist is not None:
            age = (len(r) - 1 - np.flatnonzero(v)) * scan.time_increment
            points = deskew_scan(points, age, self._twist)
            # the rays the map renders follow the points (r, a are this call's own arrays)
            r[v], a[v] = (
                np.hypot(points[:, 0], points[:, 1]),
                np.arctan2(points[:, 1], points[:, 0]),
            )
        self.process(points, r, a, scan.time, odometry)

    @property
    def sensor_pose(self) -> np.ndarray:
        return self.pose

    def pose_covariance(self) -> np.ndarray:
        """The covariance of the latest node's consecutive constraint (Censi's, or the
        tracking field's spread with ``landscape_temperature``)."""
        for c in reversed(self.constraints):
            if c.kind == "consecutive":
                return c.cov
        return self._floor

    def occupancy(self):
        return self.map.to_occupancy_grid()

    def background(self) -> None:
        """The LeafSystem's slower event: merge the full optimisation started at the last
        event (waiting for it if it is still running) and start the next one, if a loop asked
        for it, in the worker process (``full_in_worker``). The result thus lands one event
        after it started, whatever the machine: the simulation stays deterministic."""
        self.finish_full()
        self.start_full()

    def optimise_pending(self) -> bool:
        """Run the full-graph optimisation a loop closure asked for, here and now, after
        merging one still running. Returns whether one ran."""
        merged = self.finish_full()
        if self.start_full(in_worker=False):
            merged = self.finish_full()
        return merged

    @property
    def full_running(self) -> bool:
        """Whether a full optimisation has started and is not merged yet."""
        return self._full_job is not None

    def start_full(self, in_worker: bool | None = None) -> bool:
        """Start the full-graph optimisation a loop closure asked for, on a snapshot of the
        graph: in the worker process (:func:`pose_graph_solve.worker`) or solved here at
        once, as ``in_worker`` says (default: ``cfg.full_in_worker``). Nothing
        starts while one is running or when none is pending. Its result is merged by
        :meth:`finish_full`. Returns whether one started."""
        if not self.full_pending or self._full_job is not None:
            return False
        problem = self._problem(full=True)
        in_worker = self.cfg.full_in_worker if in_worker is None else in_worker
        job = worker().submit(problem) if in_worker else solved(problem)
        self._full_job = (job, problem, len(self.nodes))
        self.full_pending = False
        return True

    def finish_full(self) -> bool:
        """Merge the running full optimisation's result, waiting for it if need be (the wait
        is logged in ``stats["full_wait_ms"]``, its solve and merge in
        ``stats["full_optimisation_ms"]``). Nodes added since it started move with the last
        node it solved for. A job the worker failed is solved here. Returns whether
        one was merged."""
        if self._full_job is None:
            return False
        job, problem, n_nodes = self._full_job
        self._full_job = None
        t0 = time.perf_counter()
        try:
            solution = job.result()
        except SolveFailed:
            solution = solve_pose_graph(problem)
        t1 = time.perf_counter()
        self._apply(solution, n_nodes)
        self.stats["full_wait_ms"].append((t1 - t0) * 1e3)
        merge_ms = (time.perf_counter() - t1) * 1e3
        self.stats["full_optimisation_ms"].append(solution.solve_ms + merge_ms)
        return True

    def optimise(self, full: bool = False) -> None:
        """LM over the window (or the whole graph) with gtsam, here and now; moves nodes and
        re-renders them."""
        problem = self._problem(full)
        self._apply(solve_pose_graph(problem), len(self.nodes))

    def _problem(self, full: bool) -> PoseGraphProblem:
        """The window's (or the whole graph's) pose graph as plain data: the active nodes'
        constraints (a window's are the list's tail), the nodes outside the window that they
        reach held fixed, as is the oldest active node. In a full optimisation with
        ``loop_gnc`` every loop is a GNC candidate with the ``loop_min_sigma`` floor and
        nothing is robustified; otherwise loops GNC rejected last are left out."""
        n = len(self.nodes)
        active = set(range(n)) if full else set(range(max(0, n - self.cfg.window), n))
        gnc = full and self.cfg.loop_gnc
        loop_floor = np.diag(np.square(self.cfg.loop_min_sigma))
        # a window's constraints are the list's tail (Node.first_constraint): not a scan of
        # the whole list per node, which on Intel's raw log (10 700 nodes) cost minutes
        start = 0 if full else self.nodes[min(active)].first_constraint
        rows, covs, loop_ids, used = [], [], [], set()
        for n_c in range(start, len(self.constraints)):
            c = self.constraints[n_c]
            if not (c.i in active or c.j in active):
                continue
            candidate = c.kind == "loop" and gnc
            if c.kind == "loop" and not gnc and n_c in self._rejected:
                continue
            rows.append(c)
            covs.append(c.cov + loop_floor if candidate else c.cov)
            loop_ids.append(n_c if candidate else -1)
            used.update((c.i, c.j))
        anchor = min(active)
        keys = list(used | {anchor})
        problem = PoseGraphProblem(
            keys=np.array(keys, int),
            poses=np.array([self.nodes[k].pose for k in keys], float).reshape(-1, 3),
            fixed=np.array([k not in active or k == anchor for k in keys], bool),
            i=np.array([c.i for c in rows], int),
            j=np.array([c.j for c in rows], int),
            z=np.array([c.z for c in rows], float).reshape(-1, 3),
            cov=np.array(covs, float).reshape(-1, 3, 3),
            robust=np.array([c.robust and not gnc for c in rows], bool),
            loop_id=np.array(loop_ids, int),
            alpha=self.cfg.alpha,
            c=self.cfg.c,
            max_iterations=self.cfg.max_iterations,
        )
        return problem

    def _apply(self, solution: PoseGraphSolution, n_nodes: int) -> None:
        """Take the solved poses of ``solution`` (of the graph's first ``n_nodes`` nodes);
        the nodes added after it was posed keep their pose relative to the last of those
        nodes. Updates the GNC rejections, the current pose and the map."""
        nodes = self.nodes
        later = range(n_nodes, len(nodes))
        rel = [between(nodes[n_nodes - 1].pose, nodes[k].pose) for k in later]
        for k, pose in zip(solution.keys, solution.poses, strict=True):
            nodes[k].pose = pose.copy()
        for k, r in zip(later, rel, strict=True):
            nodes[k].pose = compose(nodes[n_nodes - 1].pose, r)
        if solution.rejected is not None:
            self._rejected = solution.rejected
            self.stats["rejected_loops"] = len(self._rejected)
        moved = sorted(int(k) for k in solution.keys) + list(later)
        self._sync_xy(moved)
        self.pose = compose(nodes[-1].pose, self._rel)
        # only the nodes just solved for (or carried along) can have moved since their last
        # check
        self._rerender_moved(moved)

    # --- map ------------------------------------------------------------------------------------
    def _render(self, node: Node) -> None:
        self.map.insert_scan(node.pose, node.ranges, node.angles, self.cfg.max_range)
        node.rendered_pose = node.pose.copy()

    def _rerender_moved(self, indices) -> None:
        """Re-render the scans of the nodes ``indices`` whose pose has moved from the one they
        were rendered at by more than ``rerender_translation`` / ``rerender_rotation``."""
        if not len(indices):
            return
        nodes = [self.nodes[k] for k in indices]
        d = between([n.rendered_pose for n in nodes], [n.pose for n in nodes])
        moved = (np.hypot(d[:, 0], d[:, 1]) > self.cfg.rerender_translation) | (
            np.abs(d[:, 2]) > self.cfg.rerender_rotation
        )
        for node in (n for n, m in zip(nodes, moved, strict=True) if m):
            self.map.remove_scan(node.rendered_pose, node.ranges, node.angles, self.cfg.max_range)
            self._render(node)

    def trajectory(self) -> np.ndarray:
        """Node poses (n × 3)."""
        return np.array([n.pose for n in self.nodes])

    def __deepcopy__(self, memo) -> "GraphSlam":
        """A structural copy: node scans (points, ranges, angles, KD-tree) and constraints never
        change after creation, so copies share them; poses, the map's arrays and the statistics
        are copied. Drake copies a Context's abstract state on every update, so this keeps a
        LeafSystem's state independent per Context at the cost of the map arrays only."""
        other = copy.copy(self)
        other.nodes = [copy.copy(n) for n in self.nodes]
        for n in other.nodes:
            n.pose = n.pose.copy()
            n.rendered_pose = None if n.rendered_pose is None else n.rendered_pose.copy()
        other.constraints = list(self.constraints)
        other._xy = self._xy.copy()
        other.pose, other._rel, other._last_step = (
            self.pose.copy(),
            self._rel.copy(),
            self._last_step.copy(),
        )
        other.map = copy.copy(self.map)
        other.map._sum, other.map._count = self.map._sum.copy(), self.map._count.copy()
        other.stats = {k: (list(v) if isinstance(v, list) else v) for k, v in self.stats.items()}
        return other
