"""Benchmark: 2D SLAM runs and their corrected references, scored on relations the scans settle.

Kümmerle et al. 2009 judge a SLAM trajectory by relations: relative poses between pairs of
scans, verified by hand, and the mean error of the trajectory's own relative poses on them
(Cartographer, Hess et al. 2016 Table I, reports Intel 0.0229 m, ACES 0.0375 m, MIT-CSAIL
0.0319 m, Freiburg 079 0.0452 m). Those relation files are not in ``../shared/data``; this
benchmark builds relations of the same kind from the scans alone and scores *both* our
trajectory and the corrected reference on them, so that neither is taken as the truth.

For every pair of a corrected log's scans that are consecutive ("local") or at least
``--loop-gap`` s apart and within 1 m and 0.5 rad of each other in either trajectory ("loop"),
open3d's point-to-point ICP (not our matchers) registers one scan to the other twice: started
from our relative pose and from the reference's. The pair becomes a relation only if both
starts end at the same pose (2 cm, 0.3°), with at least 80 % of the points paired within 10 cm
and an RMS of at most 5 cm: where the scans do not settle one answer (a corridor's length, a
partial overlap) there is no verdict. Each trajectory's relation error is then the mean
translational [m] and rotational [deg] error of its relative poses against them.

Reads the runs ``usvdrake bench slam2d_logs --raw --out DIR`` (or ``usvdrake slam2d RAW
--out DIR/NAME``) left: ``--runs DIR`` with ``NAME/trajectory.tum`` for NAME in intel, csail,
freiburg-079, aces. Prints one JSON object, per log: ``relations_local``,
``relations_loop``, ``ours_local_m``, ``reference_local_m``, ``ours_loop_m``,
``reference_loop_m`` (and ``_deg`` for rotation), ``cartographer_m`` (published, on
Kümmerle's relations). Needs ``open3d`` (``pip install -e ".[bench]"``).
"""

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from usvdrake.analysis.trajectory_metrics import (
    planar_to_se3,
    read_tum,
    se3_from_xyz_quat,
    se3_to_planar,
)
from usvdrake.logs.carmen import associate_scans, read_carmen
from usvdrake.systems.slam.graph_slam.poses import between

RAW = {
    "intel": "intel.clf.bz2",
    "csail": "mit-csail.clf.bz2",
    "freiburg-079": "fr079.clf.bz2",
    "aces": "aces.clf.bz2",
}
# Hess et al. 2016 Table I: Cartographer's mean translational relation error on Kümmerle's
# relations [m]
CARTOGRAPHER_M = {"intel": 0.0229, "csail": 0.0319, "freiburg-079": 0.0452, "aces": 0.0375}
AGREE = (0.02, np.deg2rad(0.3))  # [m, rad] both ICP starts must end this close
MIN_FITNESS = 0.8  # fraction of a scan's points paired within the last ICP distance
MAX_RMSE = 0.05  # [m] of those pairs
NEAR = (1.0, 0.5)  # [m, rad] a loop pair's scans in either trajectory
MAX_RANGE = 20.0  # [m] beams beyond are left out (sparse, and the ICP's weakest points)

# register(i, j, guess) -> (pose of scan j in scan i's frame, fitness, rmse)
Register = Callable[[int, int, np.ndarray], tuple[np.ndarray, float, float]]


def scan_points(rec) -> np.ndarray:
    """A CARMEN scan's returns (N × 2) [m] in the laser's frame, up to ``MAX_RANGE``."""
    p = rec.scan.points()
    return p[np.hypot(p[:, 0], p[:, 1]) < MAX_RANGE]


def open3d_icp(points: list[np.ndarray]) -> Register:
    """Point-to-point ICP (open3d), coarse to fine (pairing within 0.5, 0.2, 0.1 m)."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    clouds = []
    for p in points:
        c = o3d.geometry.PointCloud()
        c.points = o3d.utility.Vector3dVector(np.column_stack([p, np.zeros(len(p))]))
        clouds.append(c)
    criteria = reg.ICPConvergenceCriteria(max_iteration=60)
    method = reg.TransformationEstimationPointToPoint()

    def register(i: int, j: int, guess: np.ndarray):
        T = planar_to_se3(guess)[0]
        for d in (0.5, 0.2, 0.1):
            out = reg.registration_icp(clouds[j], clouds[i], d, T, method, criteria)
            T = np.asarray(out.transformation)
        return se3_to_planar(T[None])[0], float(out.fitness), float(out.inlier_rmse)

    return register


def candidate_pairs(times, ours, ref, loop_gap: float) -> tuple[list, list]:
    """(local, loop) index pairs: consecutive scans; scans ``loop_gap`` [s] apart within
    ``NEAR`` of each other in either trajectory."""
    n = len(times)
    local = [(i, i + 1) for i in range(n - 1)]
    loop = set()
    for poses in (ours, ref):
        for i in range(n):
            d = np.hypot(*(poses[i + 1 :, :2] - poses[i, :2]).T)
            turn = np.abs((poses[i + 1 :, 2] - poses[i, 2] + np.pi) % (2 * np.pi) - np.pi)
            for j in np.flatnonzero((d < NEAR[0]) & (turn < NEAR[1])) + i + 1:
                if abs(times[j] - times[i]) >= loop_gap:
                    loop.add((i, int(j)))
    return local, sorted(loop)


def relation_errors(pairs, ours, ref, register: Register) -> np.ndarray:
    """Rows (i, j, ours' translational error [m], its rotational [rad], the reference's
    likewise) for the pairs the scans settle (the module's rules)."""
    rows = []
    for i, j in pairs:
        z_ours, z_ref = between(ours[i], ours[j]), between(ref[i], ref[j])
        a, fit_a, rmse_a = register(i, j, z_ours)
        b, fit_b, rmse_b = register(i, j, z_ref)
        d = between(a, b)
        if np.hypot(d[0], d[1]) > AGREE[0] or abs(d[2]) > AGREE[1]:
            continue
        if min(fit_a, fit_b) < MIN_FITNESS or max(rmse_a, rmse_b) > MAX_RMSE:
            continue
        e_ours, e_ref = between(a, z_ours), between(a, z_ref)
        rows.append(
            (i, j, np.hypot(*e_ours[:2]), abs(e_ours[2]), np.hypot(*e_ref[:2]), abs(e_ref[2]))
        )
    return np.array(rows, float).reshape(-1, 6)


def summary(rows: np.ndarray, kind: str) -> dict:
    if not len(rows):
        return {f"relations_{kind}": 0}
    return {
        f"relations_{kind}": len(rows),
        f"ours_{kind}_m": float(rows[:, 2].mean()),
        f"reference_{kind}_m": float(rows[:, 4].mean()),
        f"ours_{kind}_deg": float(np.rad2deg(rows[:, 3].mean())),
        f"reference_{kind}_deg": float(np.rad2deg(rows[:, 5].mean())),
        # relations where one trajectory is off by 5 cm more than the other
        f"ours_worse_{kind}": int((rows[:, 2] - rows[:, 4] > 0.05).sum()),
        f"reference_worse_{kind}": int((rows[:, 4] - rows[:, 2] > 0.05).sum()),
    }


def score_log(raw_log: Path, corrected: Path, trajectory: Path, loop_gap: float) -> dict:
    raw = list(read_carmen(raw_log))
    ref_scans = list(read_carmen(corrected, pose="laser"))
    t, xyz, quat = read_tum(trajectory)
    t_raw = np.array([r.timestamp for r in raw])
    if len(t) != len(raw) or not np.allclose(t, t_raw):
        raise SystemExit(f"slam2d_relations: {trajectory} is not a run of {raw_log.name}")
    pairs = associate_scans(raw, ref_scans)
    keep = np.flatnonzero(pairs >= 0)
    ours = se3_to_planar(se3_from_xyz_quat(xyz, quat))[pairs[keep]]
    ref = np.array([ref_scans[k].odometry_pose for k in keep], float)
    register = open3d_icp([scan_points(ref_scans[k]) for k in keep])
    local, loop = candidate_pairs(t_raw[pairs[keep]], ours, ref, loop_gap)
    out = {"scans_scored": len(keep)}
    out |= summary(relation_errors(local, ours, ref, register), "local")
    out |= summary(relation_errors(loop, ours, ref, register), "loop")
    return out


def main() -> None:
    parser = argparse.ArgumentParser()
    here = Path(__file__).resolve().parent
    parser.add_argument("--data", default=str(here.parent.parent / "shared/data/carmen/corrected"))
    parser.add_argument("--runs", required=True, help="NAME/trajectory.tum of each raw run")
    parser.add_argument("--logs", nargs="*", default=list(RAW), help=f"some of {list(RAW)}")
    parser.add_argument("--loop-gap", type=float, default=30.0, help="[s] between loop scans")
    args = parser.parse_args()
    try:
        import open3d  # noqa: F401
    except ImportError:
        raise SystemExit('slam2d_relations needs open3d: pip install -e ".[bench]"') from None
    data, runs = Path(args.data), Path(args.runs)
    results = {}
    for name in args.logs:
        files = (data.parent / RAW[name], data / f"{name}-corrected.log.gz")
        trajectory = runs / name / "trajectory.tum"
        missing = [str(p) for p in (*files, trajectory) if not p.is_file()]
        if missing:
            results[name] = {"error": f"no {', '.join(missing)}"}
            continue
        results[name] = score_log(*files, trajectory, args.loop_gap)
        results[name]["cartographer_m"] = CARTOGRAPHER_M[name]
    print(json.dumps({"benchmark": "slam2d_relations", "logs": results}, indent=2))


if __name__ == "__main__":
    main()
