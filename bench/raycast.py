"""Benchmark: ray casting speed on the real code path (LidarModel.sweep → raycast.cast), and
against Open3D's ``RaycastingScene`` (Embree; Wald et al. 2014) on the same world and rays.

* ``lidar2d_ms_median``: a 1081-beam Hokuyo UTM-30LX scan (60 m, as Pham et al. simulates it) in
  ``valley``, from 20 free-water poses 10-30 m off the shore. Target ≤ 1 ms.
* ``lidar3d_ms_median``: a 16 × 1800 VLP-16 sweep (100 m) in ``amsterdam_canals``, from 20
  poses along the ring canals and the river. Target ≤ 15 ms.
Both with the sweep's own motion (vessel at 1.5 m/s turning at 0.1 rad/s) and noise, as the
simulated station runs them.

Against Open3D, same run, same poses: the world's solids with cylinders as ``SEGMENTS``-gon
prisms (so both casters see the same geometry), triangulated for Open3D; each sweep's own rays
(per-column origins and headings of the moving sensor, every ring) are cast by our
``raycast.cast`` (noise-free) and by ``RaycastingScene.cast_rays``, both on one thread,
alternating. Open3D is timed on ``cast_rays`` alone (rays prebuilt as a float32 tensor; the
water, minimum- and maximum-range masks applied afterwards, untimed); ours is the whole
``cast`` call. Open3D works in float32, so its scene is built per pose in coordinates
re-centred on the sensor: its rounding then stays at ~10 µm and ``max_range_diff_m`` measures
the two casters, not float32 world coordinates. ``open3d_ratio_2d``/``_3d`` = our median /
Open3D's median (must be ≤ 1); ``*_cpu_per_wall`` ≈ 1 shows one thread each. Prints one JSON
object.
"""

import argparse
import json
import statistics
import time

import numpy as np
import open3d as o3d

from usvdrake.sensors.lidar_model import LidarConfig, LidarModel, preset_by_name
from usvdrake.viz.meshcat_world import solid_mesh
from usvdrake.worlds import make_world
from usvdrake.worlds.raycast import Scene, cast
from usvdrake.worlds.solids import Solid, prism

SEGMENTS = 24  # [-] sides of the prism that stands in for a cylinder in the comparison
WATER = 0.0  # [m] the water level cast() stops beams at


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


def state(pose) -> np.ndarray:
    x, y, psi = pose
    return np.array([x, y, psi, 1.5, 0.0, 0.1])


def time_sweeps(model: LidarModel, poses: np.ndarray, repeats: int) -> list[float]:
    times = []
    for k in range(repeats):
        for i, pose in enumerate(poses):
            t0 = time.perf_counter()
            model.sweep(state(pose), k * len(poses) + i)
            times.append((time.perf_counter() - t0) * 1e3)
    return times


def polygonized(solids: list[Solid]) -> list[Solid]:
    """The solids with every cylinder replaced by a SEGMENTS-gon prism (what a mesh holds)."""
    assert all(s.cut is None for s in solids), "cut prisms are not triangulated here"
    return [
        prism(s.kind, s.footprint(SEGMENTS), s.z_min, s.z_max) if s.is_cylinder else s
        for s in solids
    ]


def triangles(solids: list[Solid]) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V × 3) and triangles (T × 3) of all the solids, as the Meshcat world draws
    them (:func:`solid_mesh`; the cylinders are prisms already)."""
    verts, tris, base = [], [], 0
    for s in solids:
        v, t = solid_mesh(s)
        verts.append(v)
        tris.append(t + base)
        base += len(v)
    return np.concatenate(verts), np.concatenate(tris)


def sweep_rays(model: LidarModel, q: np.ndarray):
    """The rays one moving sweep casts: per-column origins (C × 2), height, headings (C), and
    unit directions (rings × C × 3), as LidarModel.sweep passes them to cast()."""
    dt = model.column_time - model.sweep_time
    pos, z, heading = model.sensor_poses(q, dt)
    az = model.layout.az0 + model.layout.daz * np.arange(model.layout.count) + heading
    cos_e = 1.0 / np.sqrt(1.0 + model.tan_e**2)
    d = np.stack(
        [
            cos_e[:, None] * np.cos(az)[None, :],
            cos_e[:, None] * np.sin(az)[None, :],
            np.broadcast_to((model.tan_e * cos_e)[:, None], (len(cos_e), len(az))),
        ],
        axis=-1,
    )
    return pos, z, heading, d


def compare(model: LidarModel, solids: list[Solid], poses: np.ndarray, repeats: int) -> dict:
    """Our cast and Open3D's on the same (polygonized) world and the same rays, one thread
    each, alternating; ranges compared per ray."""
    scene = Scene.from_solids(solids)
    verts, tris = triangles(solids)
    lay, pre = model.layout, model.preset
    ours, theirs, worst, mismatches, hits, rays = [], [], 0.0, 0, 0, 0
    cpu = {"ours": [0.0, 0.0], "open3d": [0.0, 0.0]}
    for pose in poses:
        pos, z, heading, d = sweep_rays(model, state(pose))
        ref = len(heading) // 2
        centre = np.array([pos[ref, 0], pos[ref, 1], 0.0])
        o3d_scene = o3d.t.geometry.RaycastingScene(nthreads=1)
        o3d_scene.add_triangles(
            o3d.core.Tensor((verts - centre).astype(np.float32)),
            o3d.core.Tensor(tris.astype(np.uint32)),
        )
        origin = np.column_stack([pos - centre[:2], np.full(len(pos), z)])
        ray_np = np.concatenate([np.broadcast_to(origin, d.shape), d], axis=-1)
        ray_t = o3d.core.Tensor(ray_np.astype(np.float32))
        o3d_scene.cast_rays(ray_t, nthreads=1)  # builds the BVH (Embree commits lazily)
        args = (lay, model.tan_e, pos[ref], z, float(heading[ref]), model.range_max)
        kw = {"min_range": pre.range_min, "column_origin_xy": pos, "column_heading": heading}
        for _ in range(repeats):
            w0, c0 = time.perf_counter(), time.process_time()
            mine = cast(scene, *args, **kw)
            w1, c1 = time.perf_counter(), time.process_time()
            t_hit = o3d_scene.cast_rays(ray_t, nthreads=1)["t_hit"].numpy()
            w2, c2 = time.perf_counter(), time.process_time()
            ours.append((w1 - w0) * 1e3)
            theirs.append((w2 - w1) * 1e3)
            cpu["ours"] = [cpu["ours"][0] + c1 - c0, cpu["ours"][1] + w1 - w0]
            cpu["open3d"] = [cpu["open3d"][0] + c2 - c1, cpu["open3d"][1] + w2 - w1]
        # Open3D has no water plane nor range limits: apply them as cast() does.
        t = t_hit.astype(float)
        with np.errstate(divide="ignore", invalid="ignore"):
            t_water = np.where(d[..., 2] < 0, (WATER - z) / d[..., 2], np.inf)
        t[(t > t_water) | (t > model.range_max) | (t <= pre.range_min)] = np.inf
        hit_a, hit_b = np.isfinite(mine), np.isfinite(t)
        mismatches += int(np.sum(hit_a != hit_b))
        both = hit_a & hit_b
        hits += int(both.sum())
        rays += mine.size
        if both.any():
            worst = max(worst, float(np.max(np.abs(mine[both] - t[both]))))
    return {
        "ours_ms": statistics.median(ours),
        "open3d_ms": statistics.median(theirs),
        "ratio": statistics.median(ours) / statistics.median(theirs),
        "max_diff": worst,
        "mismatches": mismatches,
        "hits": hits,
        "rays": rays,
        "cpu_per_wall": {k: v[0] / v[1] for k, v in cpu.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()

    valley = make_world("valley", 0)
    hokuyo = preset_by_name("hokuyo_utm30lx_sim60")
    m2 = LidarModel(
        hokuyo, LidarConfig(preset=hokuyo.name, mount=[0.0, 0.0, 0.5, 0.0]), valley.scene, 0, 20
    )
    poses2 = poses_near_shore(valley, 20, 10.0, 30.0)
    t2 = time_sweeps(m2, poses2, args.repeats)
    c2 = compare(m2, polygonized(valley.solids), poses2, args.repeats)

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
    c3 = compare(m3, polygonized(canals.solids), poses3, args.repeats)

    med2, med3 = statistics.median(t2), statistics.median(t3)
    max_diff = max(c2["max_diff"], c3["max_diff"])
    mismatches = c2["mismatches"] + c3["mismatches"]
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
                "cast2d_ms_median": round(c2["ours_ms"], 3),
                "open3d_2d_ms_median": round(c2["open3d_ms"], 3),
                "open3d_ratio_2d": round(c2["ratio"], 3),
                "cast3d_ms_median": round(c3["ours_ms"], 3),
                "open3d_3d_ms_median": round(c3["open3d_ms"], 3),
                "open3d_ratio_3d": round(c3["ratio"], 3),
                "max_range_diff_m": max_diff,
                "hit_mismatches": mismatches,
                "compared_rays": c2["rays"] + c3["rays"],
                "compared_hits": c2["hits"] + c3["hits"],
                "cylinder_segments": SEGMENTS,
                "ours_cpu_per_wall": round(
                    (c2["cpu_per_wall"]["ours"] + c3["cpu_per_wall"]["ours"]) / 2, 3
                ),
                "open3d_cpu_per_wall": round(
                    (c2["cpu_per_wall"]["open3d"] + c3["cpu_per_wall"]["open3d"]) / 2, 3
                ),
                "open3d_version": o3d.__version__,
                "open3d_targets_met": c2["ratio"] <= 1.0
                and c3["ratio"] <= 1.0
                and max_diff <= 2e-3
                and mismatches == 0,
            }
        )
    )


if __name__ == "__main__":
    main()
