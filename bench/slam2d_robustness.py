"""Benchmark: the 2D graph SLAM (Pham et al.) with 5 % of its scans replaced by garbage (issue 6).

Records ``--duration`` s of ``valley_survey`` (USV2000 + Hokuyo at 40 Hz around the valley lake)
or takes an existing mission log (``--log``), then runs ``usvdrake slam2d``'s offline runner
(:func:`usvdrake.run.slam2d.run_slam2d`, scan only) twice on its scans: clean, and
with ``--garbage`` of them replaced (:func:`corrupt_scans`: random ranges, half-empty, NaN in
turn), both scored by ATE against the log's ground truth. Prints one JSON object:
``ate_clean_m``, ``ate_garbage_m``, ``ate_ratio`` (target ≤ 1.5) and the runs' counts.
"""

import argparse
import json
import tempfile
from pathlib import Path

from usvdrake.diagrams import load_scenario, with_overrides
from usvdrake.run.slam2d import run_slam2d


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--duration", type=float, default=200.0, help="[s] of valley_survey")
    parser.add_argument("--log", help="an existing mission log instead of recording one")
    parser.add_argument("--garbage", type=float, default=0.05, help="fraction of scans replaced")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(args.log) if args.log else None
        if log is None:
            from usvdrake.run.mission import run_mission

            scenario = with_overrides(load_scenario("valley_survey"), duration=args.duration)
            run_mission(scenario, out_dir=tmp, record=False)
            log = Path(tmp) / "log.mcap"
        runs = {}
        for name, fraction in (("clean", 0.0), ("garbage", args.garbage)):
            runs[name] = run_slam2d(
                log, Path(tmp) / name, reference=log, resolution=0.4, progress=False,
                garbage=fraction, seed=args.seed,
            )  # fmt: skip
    clean, bad = runs["clean"], runs["garbage"]
    print(
        json.dumps(
            {
                "benchmark": "slam2d_robustness",
                "log": str(args.log) if args.log else f"valley_survey {args.duration:g} s",
                "scans": clean["scans"],
                "garbage_fraction": args.garbage,
                "garbage_scans": bad["garbage_scans"],
                "ate_clean_m": clean["ate_m"],
                "ate_garbage_m": bad["ate_m"],
                "ate_ratio": bad["ate_m"] / clean["ate_m"] if clean["ate_m"] > 0 else None,
                "target_ratio": 1.5,
                "slam_nodes_clean": clean["slam_nodes"],
                "slam_nodes_garbage": bad["slam_nodes"],
                "tracking_ms_median_garbage": bad["tracking_ms_median"],
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
