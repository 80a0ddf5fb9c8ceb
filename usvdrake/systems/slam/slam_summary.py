"""What a SLAM run leaves for its metrics: plain arrays and counts, no backend objects.

The SLAM systems export these on their ``slam_summary`` output port (evaluated once, when a run
ends), and the offline runners make them from the cores they drive, so
:mod:`usvdrake.analysis.metrics` scores a live mission, a HIL run and an offline replay with
the same functions and never reaches into a backend.
"""

import copy
from dataclasses import dataclass, field

import numpy as np

from usvdrake.systems.slam.graph_slam import body_pose


@dataclass(frozen=True)
class Slam2DSummary:
    """A 2D SLAM run (the graph SLAM or the Hector mapper)."""

    final_times: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [s]
    # (n × 3) body poses [x y ψ] after every optimisation; empty when the backend has none
    final_poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    nodes: int = 0  # graph nodes (keyframes)
    constraints: int = 0  # graph constraints (scan matches, loops, odometry)
    loops: int = 0  # loop closures accepted
    tracking_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [ms] per scan
    optimisation_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [ms] per window
    full_optimisation_ms: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [ms]
    rejected_scans: int = 0  # scans refused as insane (scan_checks.usable_scan)


def summarise_2d(backend, mount=None) -> Slam2DSummary:
    """The summary of a 2D backend at the end of a run. A full optimisation still running (or
    asked for when the run ended) is merged first, in a copy, so ``backend`` is unchanged.
    ``mount`` = [x y ψ] of the lidar in the body frame: the backend's poses are the lidar's."""
    if hasattr(backend, "optimise_pending"):
        backend = copy.deepcopy(backend)
        backend.optimise_pending()
    stats = getattr(backend, "stats", {})
    times, poses = np.zeros(0), np.zeros((0, 3))
    if hasattr(backend, "final_trajectory"):
        times, poses = backend.final_trajectory()
        times, poses = np.asarray(times, float), np.asarray(poses, float).reshape(-1, 3)
        if len(times) and mount is not None:
            poses = np.array([body_pose(p, mount) for p in poses])
    return Slam2DSummary(
        final_times=times,
        final_poses=poses,
        nodes=len(getattr(backend, "nodes", [])),
        constraints=len(getattr(backend, "constraints", [])),
        loops=int(stats.get("loops", 0)),
        tracking_ms=np.asarray(stats.get("tracking_ms") or [], float),
        optimisation_ms=np.asarray(stats.get("optimisation_ms") or [], float),
        full_optimisation_ms=np.asarray(stats.get("full_optimisation_ms") or [], float),
    )


@dataclass(frozen=True)
class Slam3DSummary:
    """A 3D factor-graph SLAM run: one row per keyframe, and the graph's counts."""

    times: np.ndarray  # [s] keyframe (sweep end) times
    online: np.ndarray  # (n × 4) [x y z ψ] right after each keyframe was added
    final: np.ndarray  # (n × 4 × 4) T_world_keyframe after every loop and GPS factor
    total_ms: np.ndarray  # [ms] features + registration + iSAM2 update(s), per keyframe
    loop_ms: np.ndarray  # [ms] loop search, match and its updates, per keyframe
    features_ms: np.ndarray  # [ms] de-skew + feature extraction, per keyframe
    degenerate: np.ndarray  # (bool) the registration found a degenerate direction
    gps_valid: np.ndarray  # (bool) a valid fix was there to try
    sweeps: int  # lidar sweeps seen
    gps_accepted: int
    gps_rejected: dict  # reason → count
    loop_candidates: int
    loop_closures: int


def summarise_3d(slam) -> Slam3DSummary:
    """The summary of a :class:`~usvdrake.systems.slam.lidar_inertial.LidarInertialSlam`."""
    recs = slam.keyframes
    c = slam.graph.counts
    final = slam.trajectory()[1] if recs else np.zeros((0, 4, 4))
    return Slam3DSummary(
        times=np.array([r.time for r in recs], float),
        online=np.array([r.online for r in recs], float).reshape(-1, 4),
        final=np.asarray(final, float).reshape(-1, 4, 4),
        total_ms=np.array([r.total_ms for r in recs], float),
        loop_ms=np.array([r.loop_ms for r in recs], float),
        features_ms=np.array([r.features_ms for r in recs], float),
        degenerate=np.array([r.degenerate for r in recs], bool),
        gps_valid=np.array([r.gps_valid for r in recs], bool),
        sweeps=int(slam.sweeps),
        gps_accepted=int(c.gps_accepted),
        gps_rejected=dict(c.gps_rejected),
        loop_candidates=int(c.loop_candidates),
        loop_closures=int(c.loop_closures),
    )
