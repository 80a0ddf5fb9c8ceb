"""Benchmark: per-keyframe cost of Roboat II §V's lidar-IMU-GPS SLAM on the canal survey's sensors.

Records ``--duration`` s of the ``canal_survey`` scenario (VLP-16 at 10 Hz, IMU at 50 Hz, GPS at
5 Hz, along Amsterdam's inner ring), or takes an existing mission log (``--log``), and replays
it offline through :class:`usvdrake.systems.slam.lidar_inertial.LidarInertialSlam` with the
scenario's configuration (:func:`usvdrake.run.slam3d.run_slam3d`, the same order of messages as the
live ``FactorGraphSlam``). Per keyframe: de-skew + feature extraction + scan-to-submap
registration + iSAM2 update(s) with the GPS factor — the issue's definition; the loop search
(Roboat II §V-C, LIO-SAM's separate thread) is timed on its own (``loop_ms_*``) and with the rest
(``keyframe_with_loop_ms_*``).

Prints one JSON object: ``keyframe_ms_median`` / ``keyframe_ms_p95`` (targets 15 ms, the
SLAM issue's, and 80 ms; Roboat II §VI-A: 79.3 ms average on a NUC i7), ``numba_threads`` (the
k-NN search runs its query points on that many threads; ``NUMBA_NUM_THREADS=1`` for one),
``features_ms_median``, the split of the median keyframe into registration / update / loop,
keyframes, ``ate_m`` and ``realtime_factor`` of the replay. The replay only measures the SLAM
(no simulation in the loop).
"""

import argparse
import json
import tempfile
from pathlib import Path

import numba
import numpy as np

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.diagrams.slam import settings_from_scenario
from usvdrake.run.mission import run_mission
from usvdrake.run.slam3d import run_slam3d


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=120.0, help="[s] of canal_survey")
    parser.add_argument("--log", help="an existing mission log instead of recording one")
    parser.add_argument("--save-log", help="directory to keep the recorded log in (for --log)")
    args = parser.parse_args()
    scenario = with_overrides(load_scenario("canal_survey"), duration=args.duration)
    config, mount, datum = settings_from_scenario(scenario)
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(args.log) if args.log else None
        if log is None:
            out = Path(args.save_log) if args.save_log else Path(tmp)
            out.mkdir(parents=True, exist_ok=True)
            run_mission(scenario, out_dir=out, record=False)
            log = out / "log.mcap"
        result = run_slam3d(log, config, mount=mount, datum=datum)
    m = result.metrics
    timings = np.array([[t.registration, t.update, t.loop] for t in result.slam.graph.timings])
    split = np.median(timings, axis=0) * 1e3 if len(timings) else np.zeros(3)
    print(
        json.dumps(
            {
                "benchmark": "slam3d_keyframe",
                "log": str(args.log) if args.log else f"canal_survey {args.duration:g} s",
                "keyframes": m.get("slam_keyframes", 0),
                "keyframe_ms_median": m.get("keyframe_ms_median"),
                "keyframe_ms_p95": m.get("keyframe_ms_p95"),
                "keyframe_ms_max": m.get("keyframe_ms_max"),
                "features_ms_median": m.get("features_ms_median"),
                "registration_ms_median": float(split[0]),
                "update_ms_median": float(split[1]),
                "loop_ms_median": float(split[2]),
                "loop_ms_p95": m.get("loop_ms_p95"),
                "keyframe_with_loop_ms_median": m.get("keyframe_with_loop_ms_median"),
                "keyframe_with_loop_ms_p95": m.get("keyframe_with_loop_ms_p95"),
                "numba_threads": numba.get_num_threads(),
                "target_median_ms": 15.0,
                "target_p95_ms": 80.0,
                "ate_m": m.get("ate_m"),
                "replay_realtime_factor": m.get("realtime_factor"),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
