"""Benchmark: 3D scan-pair registration, ours against small_gicp's GICP, one thread each, one run.

The real Velodyne HDL-32E pair shipped by fast_gicp and small_gicp (``../shared/data/lidar3d``,
README there; without it the 4 cm-thinned copy in ``tests/data/lidar3d/scans.npz``), raw points
in, transform out:

* ours: organise each sweep into a range image, LOAM features (``lidar_features``), the target's
  features into the voxel map (``voxel_map``), scan-to-map registration (``scan_registration3d``)
  with the test suite's parameters (``tests/test_registration3d.py``);
* small_gicp: ``small_gicp.align(target, source, 'GICP', num_threads=1)`` with its defaults
  (0.25 m voxel grid, covariances from 10 neighbours, k-d trees, GICP; Koide et al., "small_gicp:
  Efficient and parallel algorithms for point cloud registration", JOSS 2024).

Each is timed ``--repeats`` times (after one warm-up that compiles numba's kernels) and the
medians are compared: ``ratio`` = ours / small_gicp. Errors are against the two upstream
reference transforms T_target_source (which disagree by 1.9 cm / 0.23°): ``*_error_cm`` /
``*_error_deg`` are the larger of the two, ``*_vs`` lists both. Prints one JSON object.
"""

import os

# one thread for every library (BLAS, numba) before they load: the issue compares 1 thread each
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import small_gicp  # noqa: E402

from usvdrake.systems.slam.lidar_features import (  # noqa: E402
    extract_features,
    organise_cloud,
    uniform_elevations,
)
from usvdrake.systems.slam.scan_registration3d import (  # noqa: E402
    RegistrationParams,
    register_scan,
)
from usvdrake.systems.slam.voxel_map import VoxelMap  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data" / "lidar3d"
SUBSET = ROOT / "tests" / "data" / "lidar3d" / "scans.npz"
HDL32E = uniform_elevations(32, np.deg2rad(-30.67), np.deg2rad(10.67))
# The test suite's parameters (tests/test_registration3d.py): a 0.2 m source and a second,
# 0.5 m stage, tuned for accuracy on this pair
TEST_PARAMS = RegistrationParams(
    max_correspondence_distances=[1.0, 0.5],
    huber_delta=0.05,
    source_edge_voxel=0.2,
    source_planar_voxel=0.2,
)
# The benchmark's: the source's planar points at LIO-SAM's 0.4 m surface leaf and one 1 m stage,
# as the SLAM's odometry match runs (FactorGraph3DConfig: one 1 m stage, 0.6 m planar leaf)
PARAMS = replace(TEST_PARAMS, max_correspondence_distances=[1.0], source_planar_voxel=0.4)


def read_pcd_binary(path: Path) -> np.ndarray:
    """x y z of a PCD v0.7 file with ``DATA binary`` and float32 fields (N × 3)."""
    raw = path.read_bytes()
    end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = raw[:end].decode("ascii").splitlines()
    fields = next(h for h in header if h.startswith("FIELDS")).split()[1:]
    data = np.frombuffer(raw[end:], dtype="<f4").reshape(-1, len(fields))
    return data[:, [fields.index(c) for c in "xyz"]].astype(float)


def load_pair() -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray], str]:
    """(target, source, reference transforms, where from)."""
    if (SHARED / "fast_gicp" / "251370668.pcd").exists():
        fg, sg = SHARED / "fast_gicp", SHARED / "small_gicp"
        refs = {
            "fast_gicp": np.loadtxt(fg / "relative.txt"),
            "small_gicp": np.loadtxt(sg / "T_target_source.txt"),
        }
        target = read_pcd_binary(fg / "251370668.pcd")
        source = read_pcd_binary(fg / "251371071.pcd")
        return target, source, refs, str(SHARED)
    z = np.load(SUBSET)
    s = float(z["scale"])
    refs = {"fast_gicp": z["T_fast_gicp"], "small_gicp": z["T_small_gicp"]}
    return z["target"] * s, z["source"] * s, refs, str(SUBSET)


def ours(target: np.ndarray, source: np.ndarray, params: RegistrationParams = PARAMS) -> np.ndarray:
    """Raw points in, T_target_source out."""
    ft = extract_features(organise_cloud(target, HDL32E, 2048))
    fs = extract_features(organise_cloud(source, HDL32E, 2048))
    vmap = VoxelMap(edge_voxel=0.2, planar_voxel=0.2)
    vmap.add(0, ft.edge_points, ft.planar_points)
    return register_scan(fs, vmap, None, params).T


def ours_test_params(target: np.ndarray, source: np.ndarray) -> np.ndarray:
    return ours(target, source, TEST_PARAMS)


def theirs(target: np.ndarray, source: np.ndarray) -> np.ndarray:
    return small_gicp.align(target, source, registration_type="GICP", num_threads=1).T_target_source


def pose_error(T: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """([cm], [deg]) of T_ref⁻¹ T."""
    E = np.linalg.inv(T_ref) @ T
    angle = np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1.0, 1.0))
    return 100.0 * float(np.linalg.norm(E[:3, 3])), float(np.degrees(angle))


def timed(f, target, source) -> tuple[float, np.ndarray]:
    t0 = time.perf_counter()
    T = f(target, source)
    return 1e3 * (time.perf_counter() - t0), T


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    target, source, refs, where = load_pair()
    out: dict = {"benchmark": "registration3d", "data": where, "points": [len(target), len(source)]}
    # interleaved rounds so that load from other processes hits both alike
    methods = {"ours": ours, "small_gicp": theirs, "ours_test_params": ours_test_params}
    ms: dict[str, list[float]] = {name: [] for name in methods}
    Ts = {name: f(target, source) for name, f in methods.items()}  # warm-up: numba compiles
    for _ in range(args.repeats):
        for name, f in methods.items():
            t, Ts[name] = timed(f, target, source)
            ms[name].append(t)
    for name in methods:
        errs = {k: pose_error(Ts[name], T_ref) for k, T_ref in refs.items()}
        out[f"{name}_ms_median"] = round(float(np.median(ms[name])), 2)
        out[f"{name}_error_cm"] = round(max(e[0] for e in errs.values()), 3)
        out[f"{name}_error_deg"] = round(max(e[1] for e in errs.values()), 4)
        out[f"{name}_vs"] = {k: [round(e[0], 3), round(e[1], 4)] for k, e in errs.items()}
    out["ratio"] = round(out["ours_ms_median"] / out["small_gicp_ms_median"], 3)
    out["ratio_test_params"] = round(
        out["ours_test_params_ms_median"] / out["small_gicp_ms_median"], 3
    )
    out["references_disagree"] = [round(v, 4) for v in pose_error(*refs.values())]
    out["repeats"] = args.repeats
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
