"""Benchmark: ray casting speed on the real code path (LidarModel.sweep → raycast.cast).

* ``lidar2d_ms_median``: a 1081-beam Hokuyo UTM-30LX scan (60 m, as Pham et al. simulates it) in
  ``valley``, from 20 free-water poses 10-30 m off the shore. Target ≤ 1 ms.
* ``lidar3d_ms_median``: a 16 × 1800 VLP-16 sweep (100 m) in ``amsterdam_canals``, from 20
  poses along the ring canals and the river. Target ≤ 15 ms.
Both with the sweep's own motion (vessel at 1.5 m/s turning at 0.1 rad/s) and noise, as the
simulated station runs them. Prints one JSON object.
"""

import argparse
import json
import statistics
import time

import numpy as np

from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, preset_by_name
from usvdrake.worlds import make_world


def poses_near_shore(world, n: int, lo: float, hi: float, seed: int = 0) -> np.ndarray:
    """n free-water points whose distance to the nearest solid is in [lo, hi] m."""
    rng = np.random.default_rng(seed)
    xmin, ymin, xmax, ymax = world.water.bounds
    out = []
    while len(out) < n:
        x, y = rng.uniform(xmin, xmax, 400), rng.uniform(ymin, ymax, 400)
        ok = world.in_water(x, y)
        c = world.clearance(x[ok], y[ok], cutoff=hi + 1.0)
        good = (c >= lo) & (c <= hi)
        out += list(
            zip(x[ok][good], y[ok][good], rng.uniform(-np.pi, np.pi, good.sum()), strict=True)
        )
    return np.array(out[:n])


def time_sweeps(model: LidarModel, poses: np.ndarray, repeats: int) -> list[float]:
    times = []
    for k in range(repeats):
        for i, (x, y, psi) in enumerate(poses):
            q = np.array([x, y, psi, 1.5, 0.0, 0.1])
            t0 = time.perf_counter()
            model.sweep(q, k * len(poses) + i)
            times.append((time.perf_counter() - t0) * 1e3)
    return times


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    valley = make_world("valley", 0)
    hokuyo = preset_by_name("hokuyo_utm30lx_sim60")
    m2 = LidarModel(
        hokuyo, LidarConfig(preset=hokuyo.name, mount=[0.0, 0.0, 0.5, 0.0]), valley.scene, 0, 20
    )
    t2 = time_sweeps(m2, poses_near_shore(valley, 20, 10.0, 30.0), args.repeats)

    canals = make_world("amsterdam_canals", 0)
    angles = np.deg2rad(np.linspace(205, 335, 8))
    ring = [(r * np.cos(a), r * np.sin(a), a + np.pi / 2) for r in (250.0, 330.0) for a in angles]
    river = [
        (d * np.cos(np.deg2rad(292)), d * np.sin(np.deg2rad(292)), np.deg2rad(292))
        for d in (400, 500, 600, 680)
    ]
    poses3 = np.array(ring + river)
    assert np.all(canals.is_free(poses3[:, 0], poses3[:, 1], margin=1.0)), (
        "benchmark poses must be in free water"
    )
    vlp = preset_by_name("vlp16")
    m3 = LidarModel(
        vlp, LidarConfig(preset="vlp16", mount=[0.0, 0.0, 1.0, 0.0]), canals.scene, 0, 30
    )
    t3 = time_sweeps(m3, poses3, args.repeats)

    med2, med3 = statistics.median(t2), statistics.median(t3)
    print(
        json.dumps(
            {
                "benchmark": "raycast",
                "lidar2d_ms_median": round(med2, 3),
                "lidar2d_ms_p90": round(float(np.percentile(t2, 90)), 3),
                "lidar2d_beams": hokuyo.columns,
                "lidar2d_world": "valley",
                "lidar2d_solids": len(valley.solids),
                "lidar3d_ms_median": round(med3, 3),
                "lidar3d_ms_p90": round(float(np.percentile(t3, 90)), 3),
                "lidar3d_beams": vlp.columns * len(vlp.elevations_deg),
                "lidar3d_world": "amsterdam_canals",
                "lidar3d_solids": len(canals.solids),
                "samples": len(t2) + len(t3),
                "target_lidar2d_ms": 1.0,
                "target_lidar3d_ms": 15.0,
                "targets_met": med2 <= 1.0 and med3 <= 15.0,
            }
        )
    )


if __name__ == "__main__":
    main()
