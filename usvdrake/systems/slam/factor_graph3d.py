"""Factor-graph back end of Roboat II's lidar-IMU-GPS SLAM on iSAM2 (Roboat II §V), numerical core.

The graph has one variable type, the keyframe pose X(k) ∈ SE(3) (gtsam ``Pose3``, world = the
local ENU frame of :class:`usvdrake.sensors.geodesy.LocalFrame`), and these factors
(Roboat II §V, Fig. 6), after LIO-SAM (Shan et al., IROS 2020, Roboat II ref. [22]):

* **Keyframes** (Roboat II §V-A): a lidar frame becomes a keyframe when the vessel has moved more
  than 1 m or turned more than 10° since the last keyframe (:class:`KeyframeSelector`); the
  frames in between are dropped.
* **Lidar odometry factor** (Roboat II §V-A): the keyframe's LOAM features are registered
  (:func:`scan_registration3d.register_scan`) against the voxel map M_t of the previous
  n = 25 keyframes, placed in the world frame with their *current* estimates, starting from the
  caller's guess (Roboat II: IMU integration since the last keyframe). The result T_w,k gives the
  ``BetweenFactor`` X(k−1)⁻¹X(k) = T̂_w,k−1⁻¹ T_w,k with the noise of :func:`lidar_noise_model`.
* **Attitude factor** (our addition, as LIO-SAM blends the IMU's roll and pitch into each
  match): the gravity direction measured by the AHRS in the body frame, b, must be the world's
  up, R_k b = e_z (gtsam ``AttitudeFactorPose3``, 2 residuals: roll and pitch, yaw free).
  Roll and pitch are absolutely observable from gravity; without it they drift through the
  submap and a tilt turns forward motion into climbing (see ``attitude_sigma``).
* **Water-level factor** (our addition, optional): a floating hull's origin stays on the
  waterline, t_z = h (a 1-residual ``CustomFactor``, ∂t_z/∂v = R[2, :] for Pose3's right
  perturbation t ← t + R v). See ``water_level_sigma``.
* **GPS factor** (Roboat II §V-B): a fix converted to ENU (Roboat II ref. [27]; here pyproj's
  topocentric conversion) becomes a ``GPSFactor`` on the keyframe it is associated with — only
  after the validity, covariance and χ² innovation checks of :meth:`FactorGraph3D.add_gps`.
* **Loop closure factor** (Roboat II §V-C): the nearest old keyframe i within 15 m (Euclidean,
  on the current estimate), excluding the most recent ones; the new keyframe is registered
  against the map of keyframes i−m … i+m (m = 12) and, when the match converges with a small
  RMS and is not degenerate, ``BetweenFactor`` X(i)⁻¹X(k) is added (Gaussian, as LIO-SAM's),
  followed by extra iSAM2 updates (LIO-SAM's ``addLoopFactor`` + repeated ``isam->update()``).

Every new keyframe triggers ``ISAM2.update`` (Kaess et al., "iSAM2: Incremental smoothing and
mapping using the Bayes tree", IJRR 2012, Roboat II ref. [24]). All state is plain Python / numpy /
gtsam in one object, so a later LeafSystem can keep it in its Context.
"""

import time
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np
from gtsam.symbol_shorthand import X
from scipy.stats import chi2

from usvdrake.sensors.geodesy import LocalFrame
from usvdrake.sensors.messages import GpsFix
from usvdrake.systems.slam.lidar_features import LidarFeatures
from usvdrake.systems.slam.scan_registration3d import (
    RegistrationParams,
    RegistrationResult,
    build_feature_map,
    register_scan,
    transform_points,
)
from usvdrake.systems.slam.voxel_map import VoxelMap, voxel_filter


def _odometry_registration() -> RegistrationParams:
    # LIO-SAM down-samples the new scan's surface points (0.4 m) and corners (0.2 m). Surface
    # points at 0.6 m here: canal_survey lidar-only over 300 s, 0.16 m RMSE at 0.6 against 0.20 m
    # at 0.4, with 40 % fewer points to match (registration median 26 ms against 48 ms)
    return RegistrationParams(source_edge_voxel=0.2, source_planar_voxel=0.6)


def _loop_registration() -> RegistrationParams:
    # A loop's initial guess carries the whole drift since the old visit: a wide first stage.
    return RegistrationParams(
        max_correspondence_distances=[2.0, 1.0], source_edge_voxel=0.2, source_planar_voxel=0.4
    )


@dataclass
class FactorGraph3DConfig:
    """Parameters of :class:`FactorGraph3D` (Roboat II §V values where the paper gives them)."""

    keyframe_translation: float = 1.0  # [m] keyframe when position change exceeds (Roboat II §V-A)
    keyframe_rotation: float = float(np.deg2rad(10.0))  # [rad] or rotation change exceeds
    submap_keyframes: int = 25  # [keyframes] n: previous keyframes in M_t (Roboat II §V-A)
    submap_edge_voxel: float = 0.2  # [m] voxel of M^e (LIO-SAM)
    submap_planar_voxel: float = 0.4  # [m] voxel of M^p (LIO-SAM)
    registration: RegistrationParams = field(default_factory=_odometry_registration)
    # Lidar factor noise (see lidar_noise_model)
    # [rad] floor of the factor's σ. LIO-SAM's 1e-3 overstates this matcher's drift 40-fold:
    # lidar-only on canal_survey the heading drifted 0.03° in 430 keyframes (2.5e-5 rad per
    # keyframe as a random walk). With 1e-3 the graph believed it drifted ~1 m per 150 m, so the
    # correlated, metre-level GPS pulled the estimate up to 4 m off (online ATE 1.34 m); with
    # 1e-4 (4x margin): 0.14 m
    min_rotation_sigma: float = 1e-4
    min_translation_sigma: float = 1e-2  # [m] floor of the factor's σ (LIO-SAM odometry 1e-2)
    degenerate_sigma_ratio: float = 100.0  # [-] σ of a degenerate direction ≥ this × floor
    # Prior on the first keyframe (pins the gauge; loosen it when GPS defines the ENU frame)
    prior_rotation_sigma: float = 1e-3  # [rad]
    prior_translation_sigma: float = 1e-2  # [m]
    # Attitude factor: the AHRS's gravity direction on every keyframe (roll, pitch). The lidar
    # alone leaves tilt to drift through the submap (each match levels itself to the previous,
    # slightly tilted keyframes): on canal_survey lidar-only pitch reached −3° in 120 s and,
    # at 1 m per keyframe, lifted the estimate 2.6 cm per keyframe. 3DM-GX5-25: ±0.25°
    # dynamic roll/pitch. ≤ 0: no attitude factor.
    attitude_sigma: float = float(np.deg2rad(0.25))  # [rad]
    # Water-level factor (our addition, for a surface vessel): every keyframe's body origin is
    # on the waterline, t_z = ``water_level`` ± ``water_level_sigma``. Amsterdam's canals are
    # held at NAP −0.40 m within centimetres; the lidar sees few horizontal surfaces from the
    # water, so without it z random-walks through the degenerate matches (canal_survey: ±0.3 m
    # at the finish, 1.9 m at worst with every loop closed). ≤ 0: none (Roboat II's graph).
    water_level: float = 0.0  # [m] world z of the waterline (the body origin's height)
    water_level_sigma: float = 0.0  # [m]
    # GPS factor (Roboat II §V-B)
    use_gps: bool = True  # [-] False: GPS fixes are counted as rejected ("disabled")
    # [m] reject a fix whose largest horizontal σ exceeds this (LIO-SAM gpsCovThreshold); the
    # vertical σ may be large (Roboat II §VI-A: altitude errors of ~100 m) — it only weakens z
    gps_max_sigma: float = 5.0
    gps_min_sigma: float = 1e-3  # [m] reject a fix whose smallest σ is below (not sane / non-PD)
    gps_gate_probability: float = 0.9999  # [-] χ²(3) gate on the innovation (21.1 for 0.9999)
    # GPS errors are correlated over tens of seconds (GpsConfig.noise_time_constant): a factor
    # on every keyframe would treat one wander as many independent fixes and bend the
    # trajectory towards it. LIO-SAM adds one at most every 5 m of travel, and only while the
    # estimate is uncertain (poseCovThreshold) — both rules here.
    gps_min_spacing: float = 5.0  # [m] from the last keyframe that got a GPS factor
    gps_pose_variance_threshold: float = 0.0  # [m²] only when the keyframe's horizontal
    #                                          marginal variance exceeds this (0: always)
    # [s] correlation time T of the receiver's position error (first-order Gauss-Markov; the
    # simulated receiver's ``noise_time_constant``). Fixes Δt apart have errors correlated by
    # ρ = e^{−Δt/T}; each factor's covariance is inflated by (1 + ρ)/(1 − ρ), the variance
    # factor of the mean of an AR(1) sequence (its effective sample size), so a run of factors
    # counts as the evidence it is. 0: fixes treated as independent (LIO-SAM).
    gps_correlation_time: float = 30.0
    # Loop closure (Roboat II §V-C)
    use_loop_closure: bool = True  # [-]
    loop_search_radius: float = 15.0  # [m] candidate distance (Roboat II §V-C)
    loop_min_index_gap: int = 50  # [keyframes] a candidate is at least this much older
    loop_submap_half_width: int = (
        12  # [keyframes] m: candidate map F_{i−m} … F_{i+m} (Roboat II §V-C)
    )
    loop_max_rms: float = 0.1  # [m] accepted match: RMS point distance below this
    loop_cooldown: int = 3  # [keyframes] no new loop search this soon after an accepted one
    # [-] Cauchy kernel scale of the loop factor, in whitened-error units; 0: Gaussian (LIO-SAM).
    # A loop exists to remove drift that is many of its σ (~1 cm) large: with k = 1 a 3 m
    # discrepancy is 300 σ and weighted ~1e-5, so loops never pulled a drifted estimate back
    # (canal_survey: 42 loops accepted, 11 m return error). Acceptance is by the match checks.
    loop_cauchy_k: float = 0.0
    loop_extra_updates: int = 3  # [-] further ISAM2.update() calls after a loop (LIO-SAM: 5)
    loop_registration: RegistrationParams = field(default_factory=_loop_registration)
    # iSAM2
    relinearize_threshold: float = 0.01  # [-] on the tangent-space delta (Kaess 2012 §V)
    relinearize_skip: int = 1  # [-]


def rotation_angle(R: np.ndarray) -> float:
    """Angle [rad] of a rotation matrix, ∈ [0, π], well conditioned for small angles too."""
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    return float(np.arctan2(0.5 * np.linalg.norm(w), 0.5 * (np.trace(R) - 1.0)))


class KeyframeSelector:
    """Roboat II §V-A: a frame is a keyframe when its pose differs from the last keyframe's by more
    than ``translation`` [m] or ``rotation`` [rad] (strictly: a change of exactly 1 m is not
    enough). The first frame is always a keyframe."""

    def __init__(self, translation: float = 1.0, rotation: float = float(np.deg2rad(10.0))):
        self.translation = translation
        self.rotation = rotation
        self.last: np.ndarray | None = None  # T_odom_lastkeyframe (4 × 4)

    def is_keyframe(self, T: np.ndarray) -> bool:
        """Whether T (4 × 4, odometry frame) is a keyframe; if so it becomes the reference."""
        if self.last is not None:
            D = np.linalg.inv(self.last) @ T
            moved = np.linalg.norm(D[:3, 3]) > self.translation
            if not moved and rotation_angle(D[:3, :3]) <= self.rotation:
                return False
        self.last = np.array(T, dtype=float)
        return True


def lidar_noise_model(
    result: RegistrationResult,
    rotation_floor: float,
    translation_floor: float,
    degenerate_ratio: float,
    degeneracy_threshold: float,
) -> gtsam.noiseModel.Gaussian:
    """Gaussian noise of a registration's pose, in Pose3's tangent (ω [rad], v [m]).

    Model. At the optimum the Gauss-Newton (Laplace) approximation gives Σ = σ² (JᵀWJ)⁻¹, σ² the
    weighted residual variance (``result.information`` = JᵀWJ/σ²). It is the right *shape* —
    which directions the scene constrains — but badly over-confident in *size*: the thousands of
    point residuals are treated as independent, while the real error is dominated by correlated
    effects (map voxelisation, wrong associations, motion distortion), giving sub-millimetre σ.
    So, in coordinates scaled by the floors D = diag(σ_rot·1₃, σ_trans·1₃) (making the mixed
    units comparable), with Λ̃ = D Λ D = Ṽ diag(λ̃) Ṽᵀ:

    * every direction's variance is at least the floor: s̃ = max(1/λ̃, 1) (LIO-SAM uses these
      floors as its constant odometry noise, 1e-6 rad² and 1e-4 m²);
    * the d directions the matcher found degenerate (d = number of eigenvalues of JᵀWJ below
      ``degeneracy_threshold``, Zhang, Kaess & Singh, ICRA 2016 — there the matcher kept the
      initial guess, not a measurement) get s̃ ≥ ``degenerate_ratio``²; we take the d weakest
      directions of Λ̃ as those;
    * Σ = D Ṽ diag(s̃) Ṽᵀ D. A failed match (no finite information) is degenerate in all six.
    """
    D = np.r_[np.full(3, rotation_floor), np.full(3, translation_floor)]
    info = np.asarray(result.information, dtype=float)
    if not np.all(np.isfinite(info)) or not np.any(info):
        return gtsam.noiseModel.Diagonal.Sigmas(D * degenerate_ratio)
    lam, V = np.linalg.eigh(D[:, None] * info * D[None, :])
    s = 1.0 / np.maximum(lam, 1e-300)
    s = np.maximum(s, 1.0)
    raw = np.linalg.eigvalsh(info * result.sigma**2)
    n_deg = int(np.sum(raw < degeneracy_threshold))
    s[:n_deg] = np.maximum(s[:n_deg], degenerate_ratio**2)  # eigh: ascending λ̃
    cov = D[:, None] * (V @ np.diag(s) @ V.T) * D[None, :]
    return gtsam.noiseModel.Gaussian.Covariance(0.5 * (cov + cov.T))


def water_level_factor(key: int, level: float, sigma: float) -> gtsam.CustomFactor:
    """Unary factor t_z(X) = level [m] with σ = sigma [m] on a Pose3 (module doc)."""

    def error(this, values, H):
        T = values.atPose3(this.keys()[0])
        if H is not None:
            H[0] = np.r_[0.0, 0.0, 0.0, T.rotation().matrix()[2, :]].reshape(1, 6)
        return np.array([T.translation()[2] - level])

    return gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(1, sigma), [key], error)


@dataclass
class KeyframeTiming:
    """Wall-clock cost of one keyframe (Roboat II §VI-A reports 79.3 ms for registration +
    update)."""

    registration: float = 0.0  # [s] scan-to-submap match, incl. building the submap
    update: float = 0.0  # [s] ISAM2.update for the odometry (and GPS) factor
    loop: float = 0.0  # [s] loop search, match and extra updates

    @property
    def total(self) -> float:  # [s]
        return self.registration + self.update + self.loop


@dataclass
class FactorGraphCounts:
    """Counts reported by :meth:`FactorGraph3D.counts`."""

    keyframes: int = 0
    gps_accepted: int = 0
    gps_rejected: dict[str, int] = field(default_factory=dict)  # reason → count
    loop_candidates: int = 0  # matches attempted
    loop_closures: int = 0  # accepted and added


class FactorGraph3D:
    """Keyframe pose graph of Roboat II §V on ``gtsam.ISAM2``: lidar odometry, GPS and loop factors.

    Usage per keyframe (the caller selects keyframes with :class:`KeyframeSelector` and predicts
    the pose by IMU integration)::

        k = graph.add_keyframe(T_world_guess, features, gps=(enu_xyz, covariance))

    adds, in LIO-SAM's order, the odometry factor (then ``isam.update``), the gated GPS factor
    (:meth:`add_gps`, also callable alone, e.g. for a fix that arrives later) and a loop factor
    (:meth:`close_loops`). ``config.use_gps`` and ``config.use_loop_closure`` switch the factor
    types off (Roboat II §VI-A ablation: lidar only; lidar + GPS; lidar + GPS + loop).
    """

    def __init__(self, config: FactorGraph3DConfig | None = None):
        self.config = config or FactorGraph3DConfig()
        c = self.config
        params = gtsam.ISAM2Params()
        params.setRelinearizeThreshold(c.relinearize_threshold)
        params.relinearizeSkip = c.relinearize_skip
        self._isam = gtsam.ISAM2(params)
        self._prior_noise = gtsam.noiseModel.Diagonal.Sigmas(
            np.r_[np.full(3, c.prior_rotation_sigma), np.full(3, c.prior_translation_sigma)]
        )
        self._gate = float(chi2.ppf(c.gps_gate_probability, 3))
        self._attitude_noise = gtsam.noiseModel.Isotropic.Sigma(2, max(c.attitude_sigma, 1e-9))
        # the odometry match on features already down-sampled by add_keyframe
        self._registration_ds = replace(
            c.registration, source_edge_voxel=0.0, source_planar_voxel=0.0
        )
        self._edges: list[np.ndarray] = []  # per keyframe F^e (N × 3) [m], sensor frame
        self._planes: list[np.ndarray] = []  # per keyframe F^p
        self._poses = np.zeros((0, 4, 4))  # current estimates T_world_keyframe (n × 4 × 4)
        # M_t of the odometry match, edited in place as the window slides (no rebuild)
        self._local_map = VoxelMap(c.submap_edge_voxel, c.submap_planar_voxel)
        self._last_loop = -(10**9)
        self._last_gps: np.ndarray | None = None  # position of the last keyframe with GPS
        self._last_gps_time: float | None = None  # [s] time of its fix
        self.counts = FactorGraphCounts()
        self.timings: list[KeyframeTiming] = []
        self.loops: list[tuple[int, int]] = []  # (old i, new k) of accepted loop factors
        self.registrations: list[RegistrationResult | None] = []  # odometry match per keyframe

    # --- keyframes and lidar odometry (Roboat II §V-A) -------------------------------------------

    def _local_submap(self, indices: range) -> VoxelMap:
        """M_t over ``indices``, edited in place (:meth:`VoxelMap.slide`), not rebuilt."""
        self._local_map.slide(indices, self._poses, self._edges, self._planes)
        return self._local_map

    def _submap(self, indices: range):
        """A loop candidate's map, built for the one search (the odometry's is the voxel map)."""
        c = self.config
        T = self._poses
        return build_feature_map(
            [transform_points(T[i], self._edges[i]) for i in indices],
            [transform_points(T[i], self._planes[i]) for i in indices],
            None,
            c.submap_edge_voxel,
            c.submap_planar_voxel,
        )

    def _noise(self, res: RegistrationResult, params: RegistrationParams):
        c = self.config
        return lidar_noise_model(
            res,
            c.min_rotation_sigma,
            c.min_translation_sigma,
            c.degenerate_sigma_ratio,
            params.degeneracy_threshold,
        )

    def add_keyframe(
        self,
        T_guess: np.ndarray,
        features: LidarFeatures,
        gps: tuple[np.ndarray, np.ndarray] | None = None,
        up: np.ndarray | None = None,
    ) -> int:
        """Add keyframe k with its features (sensor frame) and return k.

        T_guess: predicted T_world_keyframe (4 × 4; Roboat II: from IMU integration since the last
        keyframe). The first keyframe gets a prior at T_guess; later ones an odometry factor from
        registering against the previous ``submap_keyframes`` keyframes. gps: optional
        (ENU position (3,) [m], covariance (3 × 3) [m²]) added with :meth:`add_gps`; then
        :meth:`close_loops` runs when enabled. up: the world's up direction measured in the
        keyframe's frame (3,) (AHRS gravity), for the attitude factor; None: none."""
        c = self.config
        k = len(self._poses)
        T_guess = np.asarray(T_guess, dtype=float)
        timing = KeyframeTiming()
        graph = gtsam.NonlinearFactorGraph()
        values = gtsam.Values()
        t0 = time.perf_counter()
        # kept down-sampled as registered (LIO-SAM stores its keyframes' "DS" clouds): the
        # submaps merge 25 of them per keyframe; register_scan is told not to filter again
        # (a centroid stays in its voxel, so a second pass would only re-sort the points)
        r = c.registration
        edges = voxel_filter(features.edge_points, r.source_edge_voxel)  # a hash, not a sort
        planes = voxel_filter(features.planar_points, r.source_planar_voxel)
        features = LidarFeatures(edge_points=edges, planar_points=planes)
        if k == 0:
            T_k, res = T_guess, None
            graph.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(T_k), self._prior_noise))
        else:
            fmap = self._local_submap(range(max(0, k - c.submap_keyframes), k))
            res = register_scan(features, fmap, T_guess, self._registration_ds)
            T_k = res.T if np.all(np.isfinite(res.T)) else T_guess
            delta = np.linalg.inv(self._poses[k - 1]) @ T_k
            noise = self._noise(res, c.registration)
            graph.add(gtsam.BetweenFactorPose3(X(k - 1), X(k), gtsam.Pose3(delta), noise))
        timing.registration = time.perf_counter() - t0
        if up is not None and c.attitude_sigma > 0:
            graph.add(
                gtsam.AttitudeFactorPose3(
                    X(k), gtsam.Unit3(np.array([0.0, 0.0, 1.0])), self._attitude_noise,
                    gtsam.Unit3(np.asarray(up, dtype=float)),
                )
            )  # fmt: skip
        if c.water_level_sigma > 0:
            graph.add(water_level_factor(X(k), c.water_level, c.water_level_sigma))
        values.insert(X(k), gtsam.Pose3(T_k))
        self._edges.append(edges)
        self._planes.append(planes)
        self._poses = np.concatenate([self._poses, T_k[None]])
        self.registrations.append(res)
        t0 = time.perf_counter()
        self._isam.update(graph, values)
        self._refresh()
        timing.update = time.perf_counter() - t0
        self.counts.keyframes += 1
        self.timings.append(timing)
        if gps is not None:
            t0 = time.perf_counter()
            self.add_gps(k, gps[0], gps[1])
            timing.update += time.perf_counter() - t0
        if c.use_loop_closure:
            t0 = time.perf_counter()
            self.close_loops(k)
            timing.loop = time.perf_counter() - t0
        return k

    def track(self, features: LidarFeatures, T_guess: np.ndarray, degeneracy: float):
        """Register a sweep's features (sensor frame, down-sampled as a keyframe's) against the
        odometry submap, adding nothing (lidar-only tracking), with this degeneracy threshold."""
        k, prm = len(self._poses), replace(self._registration_ds, degeneracy_threshold=degeneracy)
        fmap = self._local_submap(range(max(0, k - self.config.submap_keyframes), k))
        return register_scan(features, fmap, T_guess, prm)

    def _refresh(self) -> None:
        # one C++ call for all poses (rows: R row-major, t), in key order = keyframe order;
        # 4x faster than reading 2000 Pose3 one by one
        A = gtsam.utilities.extractPose3(self._isam.calculateEstimate())
        P = np.zeros((len(A), 4, 4))
        P[:, :3, :3] = A[:, :9].reshape(-1, 3, 3)
        P[:, :3, 3] = A[:, 9:]
        P[:, 3, 3] = 1.0
        self._poses = P

    # --- GPS factor (Roboat II §V-B) -------------------------------------------------------------

    def _reject(self, reason: str) -> bool:
        self.counts.gps_rejected[reason] = self.counts.gps_rejected.get(reason, 0) + 1
        return False

    def gps_innovation(self, k: int, enu_xyz: np.ndarray, covariance: np.ndarray) -> float:
        """Squared Mahalanobis distance [-] of a fix from keyframe k's position estimate:
        r = z − t̂_k, S = R Σ_vv Rᵀ + Σ_gps (Σ_vv: the marginal of the body-frame translation
        part of Pose3's tangent, rotated to the world), d² = rᵀ S⁻¹ r ~ χ²(3)."""
        return self._innovation(k, enu_xyz, covariance, self.position_covariance(k))

    def _innovation(self, k: int, enu_xyz, covariance, P: np.ndarray) -> float:
        r = np.asarray(enu_xyz, dtype=float) - self._poses[k][:3, 3]
        return float(r @ np.linalg.solve(P + covariance, r))

    def position_covariance(self, k: int) -> np.ndarray:
        """Covariance (3 × 3) [m²] of keyframe k's position in the world frame: R Σ_vv Rᵀ of
        the iSAM2 marginal (Pose3's translation tangent is in the body frame)."""
        R = self._poses[k][:3, :3]
        return R @ self._isam.marginalCovariance(X(k))[3:, 3:] @ R.T

    def add_gps(
        self,
        k: int,
        enu_xyz: np.ndarray,
        covariance: np.ndarray,
        valid: bool = True,
        time: float | None = None,
    ) -> bool:
        """Add a ``GPSFactor`` on keyframe k if the fix passes the checks; returns acceptance.

        enu_xyz: fix in the world (local ENU) frame (3,) [m]; covariance: (3 × 3) [m²] E, N, U.
        Rejected (counted per reason in ``counts.gps_rejected``): GPS disabled; fix not valid or
        not finite; covariance not symmetric positive definite, with a σ below ``gps_min_sigma``
        or a horizontal σ above ``gps_max_sigma``; within ``gps_min_spacing`` of the last GPS
        factor; estimate already confident (``gps_pose_variance_threshold``); innovation beyond
        the χ²(3) gate of ``gps_gate_probability`` (:meth:`gps_innovation`). The gate trusts the
        graph's marginal: if drift outgrows it (an over-confident odometry model), correct fixes
        are refused too. time [s]: the fix's time, for ``gps_correlation_time`` (None: no
        inflation)."""
        if not self.config.use_gps:
            return self._reject("disabled")
        z = np.asarray(enu_xyz, dtype=float).reshape(-1)
        cov = np.asarray(covariance, dtype=float)
        if not valid or z.shape != (3,) or not np.all(np.isfinite(z)):
            return self._reject("invalid")
        if (
            cov.shape != (3, 3)
            or not np.all(np.isfinite(cov))
            or not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-12)
        ):
            return self._reject("covariance")
        ev = np.linalg.eigvalsh(cov)
        horizontal = np.linalg.eigvalsh(cov[:2, :2])[-1]
        if ev[0] < self.config.gps_min_sigma**2 or horizontal > self.config.gps_max_sigma**2:
            return self._reject("covariance")
        c = self.config
        p = self._poses[k][:3, 3]
        if self._last_gps is not None and np.linalg.norm(p[:2] - self._last_gps[:2]) < (
            c.gps_min_spacing
        ):
            return self._reject("spacing")
        P = self.position_covariance(k)
        if c.gps_pose_variance_threshold > 0 and max(P[0, 0], P[1, 1]) < (
            c.gps_pose_variance_threshold
        ):
            return self._reject("confident")
        if self._innovation(k, z, cov, P) > self._gate:
            return self._reject("gate")
        if time is not None and c.gps_correlation_time > 0 and self._last_gps_time is not None:
            rho = np.exp(-max(time - self._last_gps_time, 0.0) / c.gps_correlation_time)
            cov = cov * (1.0 + rho) / max(1.0 - rho, 1e-9)
        self._last_gps = p.copy()
        self._last_gps_time = time
        graph = gtsam.NonlinearFactorGraph()
        graph.add(gtsam.GPSFactor(X(k), z, gtsam.noiseModel.Gaussian.Covariance(cov)))
        self._isam.update(graph, gtsam.Values())
        self._refresh()
        self.counts.gps_accepted += 1
        return True

    def add_gps_fix(
        self, k: int, fix: GpsFix, frame: LocalFrame, antenna_height: float = 0.0
    ) -> bool:
        """:meth:`add_gps` for a geodetic :class:`GpsFix`, converted to ``frame``'s ENU
        (Roboat II §V-B, ref. [27]); the antenna ``antenna_height`` [m] above the keyframe's origin
        (the pose's roll and pitch are small: the offset is taken as vertical)."""
        e, n, u = frame.to_local(fix.latitude, fix.longitude, fix.altitude)
        z = np.array([e, n, u - antenna_height])
        return self.add_gps(k, z, fix.covariance_enu, fix.valid, float(fix.time))

    # --- loop closure (Roboat II §V-C) -----------------------------------------------------------

    def loop_candidate(self, k: int) -> int | None:
        """Nearest keyframe i ≤ k − ``loop_min_index_gap`` within ``loop_search_radius`` of
        keyframe k on the current estimate (Roboat II §V-C's Euclidean search), or None."""
        c = self.config
        last_old = k - c.loop_min_index_gap
        if last_old < 0:
            return None
        p = self._poses[: last_old + 1, :3, 3]
        d = np.linalg.norm(p - self._poses[k][:3, 3], axis=1)
        i = int(np.argmin(d))
        return i if d[i] <= c.loop_search_radius else None

    def close_loops(self, k: int) -> bool:
        """Search, match and (if accepted) add a loop factor X(i)⁻¹X(k) for keyframe k.

        The new keyframe is registered against keyframes i−m … i+m (world frame, current
        estimates) from its current estimate. Accepted when the match converged, is not
        degenerate and its RMS point distance is below ``loop_max_rms`` — a false loop is far
        costlier than a missed one (``loop_cauchy_k`` > 0 adds a Cauchy kernel)."""
        c = self.config
        if not c.use_loop_closure or k - self._last_loop < c.loop_cooldown:
            return False
        i = self.loop_candidate(k)
        if i is None:
            return False
        self.counts.loop_candidates += 1
        m = c.loop_submap_half_width
        fmap = self._submap(range(max(0, i - m), min(k - c.loop_min_index_gap, i + m) + 1))
        features = LidarFeatures(edge_points=self._edges[k], planar_points=self._planes[k])
        res = register_scan(features, fmap, self._poses[k], c.loop_registration)
        if not (res.converged and not res.degenerate and res.rms < c.loop_max_rms):
            return False
        delta = np.linalg.inv(self._poses[i]) @ res.T
        noise = self._noise(res, c.loop_registration)
        if c.loop_cauchy_k > 0:
            noise = gtsam.noiseModel.Robust.Create(
                gtsam.noiseModel.mEstimator.Cauchy.Create(c.loop_cauchy_k), noise
            )
        graph = gtsam.NonlinearFactorGraph()
        graph.add(gtsam.BetweenFactorPose3(X(i), X(k), gtsam.Pose3(delta), noise))
        self._isam.update(graph, gtsam.Values())
        for _ in range(c.loop_extra_updates):
            self._isam.update()
        self._refresh()
        self.counts.loop_closures += 1
        self.loops.append((i, k))
        self._last_loop = k
        return True

    # --- results ---------------------------------------------------------------------------------

    def estimate(self) -> list[np.ndarray]:
        """Current estimates T_world_keyframe (4 × 4 each), one per keyframe."""
        return list(self.poses())

    def poses(self) -> np.ndarray:
        """Current estimates T_world_keyframe as one array (n × 4 × 4), a copy."""
        return self._poses.copy()

    def estimate_of(self, k: int) -> np.ndarray:
        """Current estimate T_world_keyframe (4 × 4) of keyframe k (negative: from the end)."""
        return self._poses[k].copy()

    @property
    def edge_clouds(self) -> list[np.ndarray]:
        """Per keyframe its edge features F^e (N × 3) [m], keyframe frame, down-sampled by
        ``registration.source_edge_voxel`` (read only)."""
        return self._edges

    @property
    def planar_clouds(self) -> list[np.ndarray]:
        """Per keyframe its planar features F^p (N × 3) [m], keyframe frame, down-sampled by
        ``registration.source_planar_voxel`` (read only)."""
        return self._planes

    def marginal_covariance(self, k: int) -> np.ndarray:
        """iSAM2 marginal covariance (6 × 6) of X(k) in Pose3's tangent (ω [rad], v [m]),
        body frame (gtsam's right perturbation)."""
        return np.asarray(self._isam.marginalCovariance(X(k)))

    def median_timing(self) -> KeyframeTiming:
        """Median over keyframes of each timing component [s]."""
        if not self.timings:
            return KeyframeTiming()
        a = np.array([[t.registration, t.update, t.loop] for t in self.timings])
        return KeyframeTiming(*np.median(a, axis=0))
