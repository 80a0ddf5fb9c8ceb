"""Benchmark: 3D lidar-only odometry on the canal survey, ours against KISS-ICP, one thread each.

Records ``--duration`` s of the ``canal_survey`` scenario (VLP-16 at 10 Hz along Amsterdam's inner
ring, a sharp turn near the end of the first 120 s) or takes a mission log (``--log``), reads its
``/lidar_points`` sweeps into memory once and gives the same sweeps, with the same per-point
firing times, to

* ours: :class:`~usvdrake.systems.slam.lidar_inertial.LidarInertialSlam` without IMU or GPS
  (``use_imu`` False: constant-twist prediction, de-skew from point times, every sweep
  registered against the keyframe submap; ``canal_survey``'s graph with its water-level factor
  and the level-hull attitude prior, no loop closure);
* KISS-ICP (Vizzo, Guadagnino, Mersch, Wiesmann, Behley, Stachniss, "KISS-ICP: In Defense of
  Point-to-Point ICP", RA-L 2023), ``kiss_icp.kiss_icp.KissICP`` with its defaults but a 1 m
  voxel, 100 m range (VLP-16), de-skew on (point times normalised to the sweep) and 1 thread.

Both start at the true pose of the first sweep (KISS-ICP's frame is its first sweep's lidar frame,
moved there through the lidar mount) and report one body pose per sweep, what an online user
gets. Scores, the same for both, against the simulation's ground truth (the hull at height 0,
level):

* ``*_ate_m``: RMSE of the position error after the least-squares SE(3) alignment of the whole
  trajectory (Sturm et al. 2012, :func:`usvdrake.analysis.trajectory_metrics.ate`);
* ``*_z_drift_m``: vertical drift, max over the sweeps of |z_est − z_true| *without* alignment
  (both trajectories start at the true pose, so this is the height gained since the start);
* ``*_ms_per_sweep``: wall time of the whole run over the number of sweeps (features or
  voxelisation, registration, graph updates); ``ms_ratio`` = ours / KISS-ICP.

Prints one JSON object. Run with nothing else heavy on the machine: the times are one run's.
"""

import os

# one thread for every library (BLAS, numba, KISS-ICP's TBB) before they load
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from kiss_icp.config import KISSConfig  # noqa: E402
from kiss_icp.kiss_icp import KissICP  # noqa: E402

from usvdrake.analysis.metrics import truth_at  # noqa: E402
from usvdrake.analysis.trajectory_metrics import Trajectory, ate, planar_to_se3  # noqa: E402
from usvdrake.diagrams import load_scenario, with_overrides  # noqa: E402
from usvdrake.diagrams.slam import settings_from_scenario  # noqa: E402
from usvdrake.logs.sensor_stream import read_ground_truth, read_sensor_stream  # noqa: E402
from usvdrake.run.mission import run_mission  # noqa: E402
from usvdrake.run.slam3d import variant_config  # noqa: E402
from usvdrake.systems.slam.factor_graph_slam import mount_matrix  # noqa: E402
from usvdrake.systems.slam.lidar_inertial import LidarInertialSlam, pose_matrix  # noqa: E402

KISS_VOXEL = 1.0  # [m] KISS-ICP's voxel (its default is max_range / 100 = 1 m for a VLP-16)
KISS_MAX_RANGE = 100.0  # [m] VLP-16


def read_sweeps(log: Path) -> tuple[list, tuple[np.ndarray, np.ndarray]]:
    """(the log's lidar sweeps in time order, its ground truth (times, states n × 6))."""
    clouds = [m.msg for m in read_sensor_stream(log) if m.kind == "lidar"]
    truth = read_ground_truth(log)
    if truth is None or not clouds:
        raise SystemExit(f"{log}: needs /lidar_points and /ground_truth (a simulated mission)")
    return clouds, truth


def run_ours(clouds, truth, config, mount: np.ndarray) -> tuple[np.ndarray, float, dict]:
    """Our lidar-only SLAM over the sweeps: (poses after each sweep n × 4 × 4, wall [s], counts)."""
    gt_t, gt_s = truth
    x, y, psi = gt_s[0, :3]
    slam = LidarInertialSlam(config, pose_matrix(x, y, 0.0, psi), mount, None, float(gt_t[0]))
    poses = np.zeros((len(clouds), 4, 4))
    t0 = time.perf_counter()
    for j, c in enumerate(clouds):
        slam.add_cloud(c)
        poses[j] = slam.pose()
    wall = time.perf_counter() - t0
    degenerate = sum(k.degenerate for k in slam.keyframes)
    return poses, wall, {"keyframes": len(slam.keyframes), "degenerate_keyframes": degenerate}


def run_kiss(clouds, T_world_body0: np.ndarray, mount: np.ndarray) -> tuple[np.ndarray, float]:
    """KISS-ICP over the same sweeps and point times: (body poses n × 4 × 4, wall [s])."""
    cfg = KISSConfig()
    cfg.data.max_range = KISS_MAX_RANGE
    cfg.data.deskew = True
    cfg.mapping.voxel_size = KISS_VOXEL
    cfg.registration.max_num_threads = 1
    odom = KissICP(cfg)
    T_w_l0 = T_world_body0 @ mount
    to_body = np.linalg.inv(mount)
    poses = np.zeros((len(clouds), 4, 4))
    t0 = time.perf_counter()
    for j, c in enumerate(clouds):
        stamps = np.asarray(c.point_time, float) / max(c.sweep_time, 1e-9)  # [0, 1] in the sweep
        odom.register_frame(np.asarray(c.points, np.float64), stamps)
        poses[j] = T_w_l0 @ odom.last_pose @ to_body
    return poses, time.perf_counter() - t0


def score(times: np.ndarray, poses: np.ndarray, ref: np.ndarray) -> dict:
    """SE(3)-aligned ATE [m], vertical drift [m] (unaligned max |Δz|), end error [m]."""
    a = ate(Trajectory(times, poses), Trajectory(times, ref), align="se3")
    dz = poses[:, 2, 3] - ref[:, 2, 3]
    return {
        "ate_m": a["ate_rmse_m"],
        "z_drift_m": float(np.max(np.abs(dz))),
        "z_end_m": float(dz[-1]),
        "end_error_m": float(np.linalg.norm(poses[-1, :3, 3] - ref[-1, :3, 3])),
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=120.0, help="[s] of canal_survey")
    parser.add_argument("--log", help="an existing canal_survey mission log instead of recording")
    args = parser.parse_args()
    scenario = with_overrides(load_scenario("canal_survey"), duration=args.duration)
    config, mount, _ = settings_from_scenario(scenario)
    config = replace(variant_config(config, False, False), use_imu=False)
    mount = mount_matrix(mount)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(args.log) if args.log else None
        if log is None:
            run_mission(scenario, out_dir=tmp, record=False)
            log = Path(tmp) / "log.mcap"
        clouds, truth = read_sweeps(log)
    times = np.array([c.time for c in clouds])
    ref = planar_to_se3(truth_at(truth[0], truth[1], times))
    ours, ours_wall, counts = run_ours(clouds, truth, config, mount)
    kiss, kiss_wall = run_kiss(clouds, ref[0], mount)
    o, k = score(times, ours, ref), score(times, kiss, ref)
    n = len(clouds)
    print(
        json.dumps(
            {
                "benchmark": "slam3d_lidar_only",
                "log": str(args.log) if args.log else f"canal_survey {args.duration:g} s",
                "sweeps": n,
                "ours_ate_m": o["ate_m"],
                "kiss_icp_ate_m": k["ate_m"],
                "ours_z_drift_m": o["z_drift_m"],
                "kiss_icp_z_drift_m": k["z_drift_m"],
                "ours_ms_per_sweep": 1e3 * ours_wall / n,
                "kiss_icp_ms_per_sweep": 1e3 * kiss_wall / n,
                "ms_ratio": ours_wall / kiss_wall,
                "ate_ratio": o["ate_m"] / k["ate_m"],
                "ours_z_end_m": o["z_end_m"],
                "kiss_icp_z_end_m": k["z_end_m"],
                "ours_end_error_m": o["end_error_m"],
                "kiss_icp_end_error_m": k["end_error_m"],
                "ours_keyframes": counts["keyframes"],
                "ours_degenerate_keyframes": counts["degenerate_keyframes"],
                "targets": {"ours_ate_m": 0.15, "ours_z_drift_m": 1.0},
                "kiss_icp": {"voxel_m": KISS_VOXEL, "max_range_m": KISS_MAX_RANGE, "threads": 1},
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
