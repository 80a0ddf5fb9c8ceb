"""Roboat II's lidar-IMU-GPS SLAM front end (Roboat II §V), numerical core of ``FactorGraphSlam``.

Per sensor message, in time order (:class:`LidarInertialSlam`):

* **IMU** (Roboat II §V-A: "initial guess from IMU integration since the last keyframe"):
  :class:`ImuPropagator` integrates the gyro and the specific force from the last keyframe's
  estimate, R ← R Exp(ω̃ Δt), v ← v + (R f̃ − g e_z) Δt, p ← p + v Δt + ½ (R f̃ − g e_z) Δt²
  (strapdown navigation on SO(3) × R³, Forster et al., T-RO 2017, eq. (31) with the biases left
  out: over the ≤ 1 s between keyframes a 3DM-GX5-25's biases move the guess by millimetres).
  The velocity at a keyframe is the propagated one corrected by the registration,
  v_k = v̂_k + (p_k − p̂_k)/Δt (the position error of one interval is a velocity error over it),
  kept in the body frame so that a later correction of the pose turns it too.
* **Lidar**: the predicted pose at the sweep's end decides whether the sweep is a keyframe
  (Roboat II §V-A, > 1 m or > 10° from the last keyframe's *estimate*); other sweeps are dropped.
  A keyframe's points are de-skewed to the sweep's end with the constant body twist of the IMU
  (LIO-SAM's ``deskewPoint``; each point is measured in the sensor frame of its firing time),
  LOAM features are extracted (:func:`lidar_features.extract_features`), moved to the body
  frame through the lidar mount, and added to :class:`FactorGraph3D`, whose registration
  against the previous 25 keyframes starts from the IMU guess.
* **Lidar only** (``use_imu`` False, or no IMU in the recording): :class:`ConstantTwistPredictor`
  stands in for the IMU, as in KISS-ICP (Vizzo et al., RA-L 2023, §III-A): every sweep is
  de-skewed with the twist of the last step ξ = Log(T_{j−1}⁻¹ T_j)/Δt and its per-point times,
  and registered against the odometry submap (:meth:`FactorGraph3D.track`) from the guess
  T_{j−1} Exp(Δt ξ); its pose (x, y, heading: a hull's height and tilt change only at the
  keyframes, :func:`hold_vertical`) decides the keyframe, which the graph then refines, and
  gives the next twist. Gravity is not measured, so the attitude factor takes the world's up along
  the body's z with ``level_sigma`` (a floating hull is level on average; the AHRS's 0.25° is
  not claimed).
* **GPS** (Roboat II §V-B): the fixes are kept for ``gps_window`` s; a keyframe takes the valid fix
  nearest in time within ``gps_max_offset`` (LIO-SAM: 0.2 s), converted to the local ENU frame
  with pyproj (:class:`usvdrake.sensors.geodesy.LocalFrame`) and gated by the graph.

The state is the full 3D body pose T_world_body (gtsam ``Pose3``): the controllers only use
[x y ψ] (Roboat II §V), but a 3D graph keeps roll, pitch and height apart from the plane's errors,
so a wrong height from GPS altitude or a tilted registration does not leak into x, y, ψ — and the
vertical drift is observable for the ablation (Roboat II §VI-A).
"""

import time
from collections import deque
from dataclasses import dataclass, field, replace

import gtsam
import numpy as np

from usvdrake.sensors.geodesy import LocalFrame
from usvdrake.sensors.imu_model import STANDARD_GRAVITY
from usvdrake.sensors.messages import GpsFix, ImuSample, PointCloud
from usvdrake.systems.slam.factor_graph3d import (
    FactorGraph3D,
    FactorGraph3DConfig,
    KeyframeSelector,
)
from usvdrake.systems.slam.lidar_features import FeatureParams, LidarFeatures, extract_features
from usvdrake.systems.slam.scan_registration3d import (
    deskew,
    so3_exp,
    transform_points,
    voxel_downsample,
)
from usvdrake.systems.slam.voxel_map import voxel_filter


@dataclass
class LidarInertialConfig:
    """Parameters of :class:`LidarInertialSlam` (scenario ``slam.factor_graph``)."""

    graph: FactorGraph3DConfig = field(default_factory=FactorGraph3DConfig)
    features: FeatureParams = field(default_factory=FeatureParams)
    deskew: bool = True  # [-] move each point to the sweep's end with the IMU's twist
    gravity: float = STANDARD_GRAVITY  # [m/s²] subtracted from the rotated specific force
    # A surface vessel does not heave (Roboat II eq. (1) is 3-DOF): the IMU prediction keeps the
    # vertical velocity at 0. Without it the accelerometer's z bias (3DM-GX5-25: ±0.02 m/s²)
    # integrates into a vertical velocity that no degenerate (wall-only) match can correct,
    # and the guess climbs metres per minute.
    surface_vessel: bool = True
    gps_max_offset: float = 0.2  # [s] a keyframe takes a fix at most this far in time (LIO-SAM)
    gps_window: float = 2.0  # [s] fixes kept for association
    gps_antenna_height: float = 0.0  # [m] antenna above the body origin (``GpsConfig``)
    map_voxel: float = 0.5  # [m] voxel of the map drawn / returned by ``map_points``
    # False: lidar only — IMU samples are ignored and ConstantTwistPredictor predicts (module
    # doc); ``usvdrake slam3d`` sets it when a recording has no IMU or with --no-imu
    use_imu: bool = True
    # [rad] lidar only: σ of the attitude factor that takes the body's z as the world's up (a
    # hull floating on calm canal water rolls and pitches by ~1°; without gravity the tilt
    # would drift through the submaps and a 1° pitch climbs 1.7 cm per metre). ≤ 0: none
    level_sigma: float = float(np.deg2rad(1.0))
    # [s] lidar only: the twist is the motion over the sweeps of this last stretch (one sweep's
    # step is noisy: ±5 mm, ±0.05 m/s at 10 Hz; 0.1, 0.5 and 1 s scored alike on canal_survey)
    twist_window: float = 0.5
    # [-] lidar only: map neighbours per correspondence (LOAM: 5). Registered from the true
    # pose against a submap at the true poses (canal_survey, 114 sweeps), the past-only submap
    # pulled every match 8 mm forward with 5 neighbours (−16 mm with a future-only submap,
    # −1 mm with both) and 1.2 mm with 8: 0.8 % of the distance travelled that the IMU's guess
    # hides and the constant twist keeps. 10 find too few pairs in the first sweep's map.
    lidar_only_neighbours: int = 8
    # [-] lidar only: degeneracy threshold of the per-sweep match (Zhang 2016; the keyframes'
    # keep the graph's, so their weak directions stay loose for the water-level and level
    # priors). The graph's 10 keeps the guess along a canal's walls, which the IMU makes good
    # and the constant twist does not: from rest it stayed 0.6 m behind in 2 s (seed 1)
    lidar_only_degeneracy: float = 0.1


def pose_matrix(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    """T (4 × 4) of a pose with the given position [m] and yaw [rad] (roll = pitch = 0)."""
    c, s = np.cos(yaw), np.sin(yaw)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[:3, 3] = [x, y, z]
    return T


def planar_pose(T: np.ndarray) -> np.ndarray:
    """[x y ψ] of a 3D pose: its position and the heading of its x axis in the x-y plane."""
    return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])


def quaternion_matrix(q_xyzw) -> np.ndarray:
    """Rotation matrix of a unit quaternion [x y z w] (normalised first)."""
    x, y, z, w = np.asarray(q_xyzw, dtype=float) / np.linalg.norm(q_xyzw)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def level_rotation(R: np.ndarray, q_ahrs) -> np.ndarray:
    """The body-to-world rotation for gravity compensation: the AHRS's roll and pitch (gravity
    referenced, as LIO-SAM takes them from the IMU's orientation) under the estimate's yaw.

    A tilt error δ of the estimate would leak g sin δ into the horizontal acceleration
    (0.17 m/s² per degree: metres within seconds); the AHRS heading (magnetic, ±0.8°) is not
    used, the graph's yaw is better. Also the attitude of the IMU guess (``ImuPropagator``)."""
    Ra = quaternion_matrix(q_ahrs)
    yaw_a = np.arctan2(Ra[1, 0], Ra[0, 0])
    c, s = np.cos(yaw_a), np.sin(yaw_a)
    Rz_a = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    yaw = np.arctan2(R[1, 0], R[0, 0])
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Rz_a.T @ Ra


class ImuPropagator:
    """Strapdown integration of IMU samples from a known pose and velocity (see module doc).

    Each sample's ω̃ and f̃ are held over the interval since the previous sample (zero-order
    hold); before the first sample, nothing moves."""

    def __init__(self, gravity: float = STANDARD_GRAVITY, surface: bool = True):
        self.g = np.array([0.0, 0.0, gravity])
        self.surface = surface  # no vertical velocity (see LidarInertialConfig.surface_vessel)
        self.T = np.eye(4)  # T_world_body [m]
        self.v = np.zeros(3)  # world-frame velocity [m/s]
        self.t = 0.0  # [s] time of T, v
        self.omega = np.zeros(3)  # [rad/s] last gyro sample, body frame
        self.up: np.ndarray | None = None  # world up in the body frame, last AHRS sample
        self.steps = 0  # samples integrated since the last reset

    def reset(self, T: np.ndarray, v_body: np.ndarray, t: float) -> None:
        """Restart from pose T (4 × 4) with body-frame velocity v_body [m/s] at time t [s]."""
        self.T = np.array(T, dtype=float)
        self.v = self.T[:3, :3] @ np.asarray(v_body, dtype=float)
        if self.surface:
            self.v[2] = 0.0
        self.t = float(t)
        self.steps = 0

    def add(self, sample: ImuSample) -> None:
        """Integrate one sample over (t, sample.time]; older samples are ignored."""
        dt = float(sample.time) - self.t
        if dt <= 0:
            return
        w = np.asarray(sample.angular_velocity, dtype=float)
        f = np.asarray(sample.linear_acceleration, dtype=float)
        R = self.T[:3, :3]
        a = level_rotation(R, sample.orientation) @ f - self.g
        if self.surface:
            a[2] = 0.0
        self.T[:3, 3] += self.v * dt + 0.5 * a * dt * dt
        self.v = self.v + a * dt
        # gyro for the heading; roll and pitch from the AHRS (gravity referenced, as LIO-SAM's
        # initial guess takes them): integrated x/y gyro bias (3DM-GX5-25: ±0.04 °/s) would
        # tilt the guess by degrees within minutes, and a weakly constrained match keeps it —
        # a 1° pitch lifts the estimate 1.7 cm per metre travelled
        self.T[:3, :3] = level_rotation(R @ so3_exp(w * dt), sample.orientation)
        self.t = float(sample.time)
        self.omega = w
        self.up = quaternion_matrix(sample.orientation)[2, :].copy()  # R_ahrsᵀ e_z
        self.steps += 1

    def predict(self, t: float) -> np.ndarray:
        """The pose at time t ≥ self.t [s], extrapolated with the last rates (≤ one IMU period
        beyond the last sample in use)."""
        dt = max(0.0, float(t) - self.t)
        T = self.T.copy()
        T[:3, 3] += self.v * dt
        T[:3, :3] = T[:3, :3] @ so3_exp(self.omega * dt)
        return T

    @property
    def v_body(self) -> np.ndarray:
        """Velocity in the body frame [m/s]."""
        return self.T[:3, :3].T @ self.v


class ConstantTwistPredictor:
    """The lidar-only motion prior (KISS-ICP's constant velocity model, Vizzo et al., RA-L 2023,
    §III-A, on SE(3)): T(t) = T_j Exp((t − t_j) ξ) from the last sweep's pose T_j at t_j
    with the body twist ξ = (ω [rad/s], v [m/s]) (gtsam's Pose3 tangent order). Along T(t) the
    body-frame angular and linear velocities are ξ itself, so ``omega`` / ``v_body`` de-skew a
    sweep as the IMU's rates do. ``surface``: the twist keeps only the yaw rate and the
    horizontal velocity in the world frame (Roboat II eq. (1) is 3-DOF: a hull does not climb or
    keep turning about a horizontal axis).

    The same interface as :class:`ImuPropagator` where :class:`LidarInertialSlam` uses it:
    ``reset``, ``predict``, ``T``, ``t``, ``v``, ``v_body``, ``omega``, ``up`` (None: gravity
    is not measured)."""

    def __init__(self, surface: bool = True):
        self.surface = surface
        self.T_ref = np.eye(4)  # T_world_body at t_ref [m]
        self.t_ref = 0.0  # [s] time of the last keyframe
        self.t = 0.0  # [s] latest time seen (a sweep's end)
        self.xi = np.zeros(6)  # body twist (ω, v)
        self.up: np.ndarray | None = None
        self.steps = 0

    def reset(self, T: np.ndarray, xi: np.ndarray, t: float) -> None:
        """Restart from pose T (4 × 4) at time t [s] with body twist ξ (6,)."""
        self.T_ref = np.array(T, dtype=float)
        self.xi = self.level_twist(self.T_ref[:3, :3], np.asarray(xi, dtype=float))
        self.t_ref = self.t = float(t)

    def level_twist(self, R: np.ndarray, xi: np.ndarray) -> np.ndarray:
        """ξ with, for a surface vessel (``surface``), the world-frame roll / pitch rates and
        vertical velocity removed; R: the body's rotation."""
        if not self.surface:
            return xi.copy()
        w, v = R @ xi[:3], R @ xi[3:]
        w[:2] = 0.0
        v[2] = 0.0
        return np.r_[R.T @ w, R.T @ v]

    def advance(self, t: float) -> None:
        """Note that time t [s] has been reached (``pose()`` predicts to it)."""
        self.t = max(self.t, float(t))

    def predict(self, t: float) -> np.ndarray:
        """T(t) (4 × 4), extrapolated with the twist from the last reset."""
        return self.T_ref @ gtsam.Pose3.Expmap(self.xi * (float(t) - self.t_ref)).matrix()

    @property
    def T(self) -> np.ndarray:
        """The pose at the latest time seen (4 × 4)."""
        return self.predict(self.t)

    @property
    def omega(self) -> np.ndarray:
        """Body angular velocity [rad/s]."""
        return self.xi[:3]

    @property
    def v_body(self) -> np.ndarray:
        """Body-frame velocity [m/s]."""
        return self.xi[3:]

    @property
    def v(self) -> np.ndarray:
        """World-frame velocity [m/s] at the latest time seen."""
        return self.T[:3, :3] @ self.xi[3:]


def hold_vertical(T: np.ndarray, T_ref: np.ndarray) -> np.ndarray:
    """T's position in x-y and heading with T_ref's height and tilt (roll, pitch): T_ref's
    rotation turned about the world's z to T's heading."""
    d = planar_pose(T)[2] - planar_pose(T_ref)[2]
    c, s = np.cos(d), np.sin(d)
    out = T_ref.copy()
    out[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ T_ref[:3, :3]
    out[:2, 3] = T[:2, 3]
    return out


def twist_between(T_a: np.ndarray, T_b: np.ndarray, dt: float) -> np.ndarray:
    """The constant body twist ξ (ω [rad/s], v [m/s]) that moves T_a to T_b in dt [s]:
    Log(T_a⁻¹ T_b)/dt (SE(3) logarithm; zero for dt ≤ 0)."""
    if dt <= 0:
        return np.zeros(6)
    return np.asarray(gtsam.Pose3.Logmap(gtsam.Pose3(np.linalg.inv(T_a) @ T_b))) / dt


@dataclass
class KeyframeRecord:
    """What the front end knows about one keyframe (for metrics and the offline runner)."""

    time: float  # [s] sweep end
    features_ms: float  # [ms] de-skew + feature extraction
    total_ms: float  # [ms] features + registration + iSAM2 update(s) (with the GPS factor)
    loop_ms: float  # [ms] loop search, match and its extra updates
    degenerate: bool  # the odometry registration found a degenerate direction
    gps: bool  # a GPS factor was added
    gps_valid: bool  # a valid fix was there to try (False: outage, e.g. under a bridge)
    n_edge: int
    n_planar: int
    online: np.ndarray  # [x y z ψ] estimate right after the keyframe was added (online)


class KeyframeMap:
    """The SLAM's map as keyframes: ``poses`` (n × 4 × 4) T_world_keyframe at the current
    estimates and ``clouds``, per keyframe its features (edges and planes) in its own frame,
    voxel-filtered for display. The clouds never change once made, so copies share them (Drake
    copies output values): a copy costs the poses only, and a drawing that keeps one geometry per
    keyframe only moves it when a loop or GPS factor moves the keyframe."""

    def __init__(self, poses: np.ndarray | None = None, clouds: list | None = None):
        self.poses = np.zeros((0, 4, 4)) if poses is None else np.asarray(poses, dtype=float)
        self.clouds: list[np.ndarray] = [] if clouds is None else clouds

    def __len__(self) -> int:
        return len(self.poses)

    def points(self, voxel: float = 0.0) -> np.ndarray:
        """All keyframes' points in the world frame (N × 3) [m], voxel-filtered (voxel > 0)."""
        if not len(self):
            return np.zeros((0, 3))
        clouds = [transform_points(T, c) for T, c in zip(self.poses, self.clouds, strict=False)]
        return voxel_downsample(np.vstack(clouds), voxel)

    def __deepcopy__(self, memo) -> "KeyframeMap":
        return KeyframeMap(self.poses.copy(), self.clouds)


class LidarInertialSlam:
    """Roboat II §V's SLAM over :class:`FactorGraph3D`, fed one message at a time (module doc).

    initial_pose: T_world_body (4 × 4) at t0 (the vessel starts at a known pose, as Roboat II
    starts at its dock); mount: T_body_lidar (4 × 4); frame: the ENU frame of the world (GPS
    fixes are converted into it). Keyframe poses are the body's."""

    def __init__(
        self,
        config: LidarInertialConfig,
        initial_pose: np.ndarray,
        mount: np.ndarray,
        frame: LocalFrame | None = None,
        t0: float = 0.0,
    ):
        self.config = config
        graph = config.graph
        if not config.use_imu:  # lidar only: the level hull's σ for the attitude factor
            reg = replace(graph.registration, k_neighbours=config.lidar_only_neighbours)
            graph = replace(graph, registration=reg, attitude_sigma=config.level_sigma)
        self.graph = FactorGraph3D(graph)
        self.mount = np.array(mount, dtype=float)
        self.frame = frame
        self.imu: ImuPropagator | ConstantTwistPredictor
        if config.use_imu:
            self.imu = ImuPropagator(config.gravity, config.surface_vessel)
            self.imu.reset(initial_pose, np.zeros(3), t0)
        else:  # lidar only (module doc)
            self.imu = ConstantTwistPredictor(config.surface_vessel)
            self.imu.reset(initial_pose, np.zeros(6), t0)
        self.selector = KeyframeSelector(
            config.graph.keyframe_translation, config.graph.keyframe_rotation
        )
        self._fixes: deque[GpsFix] = deque()
        self.keyframes: list[KeyframeRecord] = []
        self.sweeps = 0  # lidar sweeps seen
        self.imu_samples = 0
        self._covariance: tuple[int, np.ndarray] = (-1, np.zeros((3, 3)))  # (keyframe, Σ)
        self._map_clouds: list[np.ndarray] = []  # per keyframe its display cloud (map_voxel)
        self.tracking_ms: list[float] = []  # lidar only: [ms] features + match, per sweep
        self._tracked: deque[tuple[float, np.ndarray]] = deque()  # lidar only (twist_window)

    # --- inputs ----------------------------------------------------------------------------------

    @property
    def lidar_only(self) -> bool:
        """Predicting with the constant twist, not the IMU (``config.use_imu`` False)."""
        return isinstance(self.imu, ConstantTwistPredictor)

    def add_imu(self, sample: ImuSample) -> None:
        """Integrate an IMU sample (counted but ignored when lidar only)."""
        self.imu_samples += 1
        if not self.lidar_only:
            self.imu.add(sample)

    def add_gps(self, fix: GpsFix) -> None:
        """Keep a fix for association with the next keyframes (invalid fixes are kept too: the
        graph counts them as rejected)."""
        self._fixes.append(fix)
        while self._fixes and self._fixes[0].time < fix.time - self.config.gps_window:
            self._fixes.popleft()

    def _fix_near(self, t: float) -> GpsFix | None:
        best = min(self._fixes, key=lambda f: abs(f.time - t), default=None)
        if best is None or abs(best.time - t) > self.config.gps_max_offset:
            return None
        return best

    def add_cloud(self, cloud: PointCloud) -> bool:
        """Process one sweep; True when it became keyframe (then the pose estimate is
        corrected)."""
        self.sweeps += 1
        if isinstance(self.imu, ConstantTwistPredictor):
            return self._add_cloud_lidar_only(cloud, self.imu)
        T_pred = self.imu.predict(cloud.time)
        if not self.selector.is_keyframe(T_pred):
            return False
        t0 = time.perf_counter()
        features = self.features(cloud)
        T_k = self._add_keyframe(cloud, T_pred, features, time.perf_counter() - t0, self.imu.up)
        self._restart_imu(cloud.time, T_pred, T_k)
        return True

    def _add_cloud_lidar_only(self, cloud: PointCloud, p: ConstantTwistPredictor) -> bool:
        """Lidar only, every sweep is registered against the odometry submap from the constant
        twist's guess (KISS-ICP registers every sweep: a guess 0.1 s ahead stays good when a
        turn starts, where one a keyframe (0.7 s) ahead was 10° off), and its pose gives the
        next twist; a keyframe's is then refined in the graph."""
        t0 = time.perf_counter()
        T_pred = p.predict(cloud.time)
        features = self.features(cloud)
        features_s = time.perf_counter() - t0
        T = T_pred
        if self.keyframes:
            r = self.graph.config.registration  # down-sampled as the keyframes are
            e = voxel_filter(features.edge_points, r.source_edge_voxel)
            f = LidarFeatures(e, voxel_filter(features.planar_points, r.source_planar_voxel))
            res = self.graph.track(f, T_pred, self.config.lidar_only_degeneracy)
            if np.all(np.isfinite(res.T)):
                # a hull's height and tilt change only at keyframes, where the graph has the
                # water-level and level factors (as the IMU guess holds them between keyframes):
                # the sweep's weak vertical constraints moved its height by up to 0.9 m
                T = hold_vertical(res.T, T_pred) if self.config.surface_vessel else res.T
        self.tracking_ms.append(1e3 * (time.perf_counter() - t0))
        c = self.config
        if self.selector.is_keyframe(T):
            up = np.array([0.0, 0.0, 1.0]) if c.level_sigma > 0 else None
            T = self._add_keyframe(cloud, T, features, features_s, up)
            self.selector.last = T.copy()
        past = self._tracked  # (time, pose) of the sweeps of the last twist_window
        past.append((float(cloud.time), T))
        while len(past) > 2 and past[1][0] <= cloud.time - c.twist_window + 1e-9:
            past.popleft()
        p.reset(T, twist_between(past[0][1], T, cloud.time - past[0][0]), cloud.time)
        return len(self.keyframes) > 0 and self.keyframes[-1].time == cloud.time

    def _add_keyframe(
        self,
        cloud: PointCloud,
        T_guess: np.ndarray,
        features: LidarFeatures,
        features_s: float,
        up: np.ndarray | None,
    ) -> np.ndarray:
        """Add the sweep's features as a keyframe (graph, GPS factor, record; features_s [s]:
        their de-skew and extraction) and return its estimate T_k."""
        g = self.graph
        fix = self._fix_near(cloud.time)
        k = g.add_keyframe(T_guess, features, up=up)
        self._map_clouds.append(
            voxel_downsample(
                np.vstack([g.edge_clouds[k], g.planar_clouds[k]]), self.config.map_voxel
            )
        )
        gps = False
        if fix is not None and self.frame is not None:
            t1 = time.perf_counter()
            gps = g.add_gps_fix(k, fix, self.frame, self.config.gps_antenna_height)
            g.timings[-1].update += time.perf_counter() - t1
        T_k = g.estimate_of(k)
        timing = g.timings[-1]
        res = g.registrations[-1]
        self.keyframes.append(
            KeyframeRecord(
                time=float(cloud.time),
                features_ms=1e3 * features_s,
                total_ms=1e3 * (features_s + timing.registration + timing.update),
                loop_ms=1e3 * timing.loop,
                degenerate=bool(res.degenerate) if res is not None else False,
                gps=gps,
                gps_valid=fix is not None and bool(fix.valid),
                n_edge=len(features.edge_points),
                n_planar=len(features.planar_points),
                online=np.r_[T_k[:3, 3], planar_pose(T_k)[2]],
            )
        )
        return T_k

    def _restart_imu(self, t: float, T_pred: np.ndarray, T_k: np.ndarray) -> None:
        """Restart the IMU from the keyframe's estimate. The velocity is corrected with the lidar
        odometry alone (the registered pose, before GPS and loop factors move the keyframe): a
        GPS fix's metre of noise divided by the 0.7 s between keyframes would be a 1 m/s error
        in the next guess."""
        res = self.graph.registrations[-1]
        T_reg = res.T if res is not None and np.all(np.isfinite(res.T)) else T_pred
        dt = t - self.keyframes[-2].time if len(self.keyframes) > 1 else 0.0
        v_world = self.imu.v
        if dt > 0:
            v_world = v_world + (T_reg[:3, 3] - T_pred[:3, 3]) / dt
        self.imu.reset(T_k, T_reg[:3, :3].T @ v_world, t)
        self.selector.last = T_k.copy()

    def features(self, cloud: PointCloud) -> LidarFeatures:
        """De-skewed LOAM features of a sweep in the body frame."""
        c = self.config
        if c.deskew and cloud.motion_applied and len(cloud.points):
            R_bl, t_bl = self.mount[:3, :3], self.mount[:3, 3]
            w_body = self.imu.omega
            v_lidar = R_bl.T @ (self.imu.v_body + np.cross(w_body, t_bl))
            age = cloud.sweep_time - np.asarray(cloud.point_time, dtype=float)
            pts = deskew(cloud.points, age, R_bl.T @ w_body, v_lidar)
            cloud = replace(cloud, points=pts)
        f = extract_features(cloud, c.features)
        return replace(
            f,
            edge_points=transform_points(self.mount, f.edge_points),
            planar_points=transform_points(self.mount, f.planar_points),
        )

    # --- outputs ---------------------------------------------------------------------------------

    def pose(self, t: float | None = None) -> np.ndarray:
        """Current T_world_body (4 × 4): the last keyframe's estimate propagated by the IMU (lidar
        only: by the constant twist to the last sweep)."""
        return self.imu.predict(self.imu.t if t is None else t)

    def state(self) -> np.ndarray:
        """[x y ψ u v r] for the controllers (body velocities from the IMU propagation)."""
        T = self.imu.T
        vb = self.imu.v_body
        return np.r_[planar_pose(T), vb[0], vb[1], self.imu.omega[2]]

    def planar_covariance(self) -> np.ndarray:
        """Covariance (3 × 3) of [x y ψ] of the last keyframe in the world frame, from the
        iSAM2 marginal of its Pose3 (tangent (ω, v), body frame): Σ_xy = (R Σ_vv Rᵀ)[:2, :2],
        σ²_ψ = Σ_ωzωz (rotation about the vertical, roll and pitch small)."""
        if not self.keyframes:
            return np.diag([1e-4, 1e-4, 1e-6])
        k = len(self.keyframes) - 1
        if self._covariance[0] != k:  # the graph only changes when a keyframe is added
            P = self.graph.marginal_covariance(k)
            R = self.graph.estimate_of(k)[:3, :3]
            J = np.zeros((3, 6))
            J[:2, 3:] = R[:2, :]
            J[2, :3] = R[2, :]  # world z component of the body rotation vector
            self._covariance = (k, J @ P @ J.T)
        return self._covariance[1].copy()

    def keyframe_map(self) -> KeyframeMap:
        """The map: every keyframe's features (``map_voxel``) with its current estimate."""
        return KeyframeMap(self.graph.poses(), self._map_clouds)

    def map_points(self) -> np.ndarray:
        """All keyframes' features in the world frame at their current estimates, voxel
        down-sampled (``map_voxel``)."""
        return self.keyframe_map().points(self.config.map_voxel)

    def trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """(keyframe times (n,), current keyframe estimates (n × 4 × 4))."""
        return np.array([k.time for k in self.keyframes]), self.graph.poses()

    def __deepcopy__(self, memo) -> "LidarInertialSlam":
        """Shared, not copied: gtsam's iSAM2 Bayes tree cannot be copied, and Drake copies a
        Context's abstract state on every unrestricted update. Every copy is this object, so one
        simulation is exact; two Contexts of one ``FactorGraphSlam`` would share a SLAM (build a
        diagram per run)."""
        return self
