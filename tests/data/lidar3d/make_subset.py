"""Make ``scans.npz`` from the upstream fast_gicp / small_gicp scan pairs (run once, by hand).

    python tests/data/lidar3d/make_subset.py /path/to/lidar3d  # holds fast_gicp/ and small_gicp/

Reads the binary PCD (fast_gicp) and binary little-endian PLY (small_gicp) files, checks that the
two repositories ship the same two scans, keeps the returns with 1 m < r < 80 m, thins them with a
VOXEL-side voxel filter that keeps the first return (in file order) of each voxel — so the kept
points are measured points on their original beams, not centroids — and stores x, y, z as int16
in units of SCALE metres.
"""

import sys
from pathlib import Path

import numpy as np

VOXEL = 0.04  # [m]
SCALE = 0.0025  # [m] per int16 unit: ±81.9 m, quantisation error ≤ 1.25 mm


def read_pcd_binary(path: Path) -> np.ndarray:
    """x y z of a PCD v0.7 file with ``DATA binary`` and float32 fields (N × 3)."""
    raw = path.read_bytes()
    end = raw.index(b"DATA binary\n") + len(b"DATA binary\n")
    header = raw[:end].decode("ascii").splitlines()
    fields = next(h for h in header if h.startswith("FIELDS")).split()[1:]
    types = next(h for h in header if h.startswith("TYPE")).split()[1:]
    sizes = next(h for h in header if h.startswith("SIZE")).split()[1:]
    assert all(t == "F" and s == "4" for t, s in zip(types, sizes, strict=True))
    data = np.frombuffer(raw[end:], dtype="<f4").reshape(-1, len(fields))
    return data[:, [fields.index(c) for c in "xyz"]].astype(float)


def read_ply_binary(path: Path) -> np.ndarray:
    """x y z of a binary little-endian PLY whose vertex properties are all float32 (N × 3)."""
    raw = path.read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    header = raw[:end].decode("ascii").splitlines()
    assert "format binary_little_endian 1.0" in header
    props = [h.split()[2] for h in header if h.startswith("property float")]
    data = np.frombuffer(raw[end:], dtype="<f4").reshape(-1, len(props))
    return data[:, [props.index(c) for c in "xyz"]].astype(float)


def thin(points: np.ndarray) -> np.ndarray:
    r = np.linalg.norm(points, axis=1)
    points = points[(r > 1.0) & (r < 80.0)]
    key = np.floor(points / VOXEL).astype(np.int64)
    _, first = np.unique(key, axis=0, return_index=True)
    return points[np.sort(first)]


def main(root: Path) -> None:
    fg, sg = root / "fast_gicp", root / "small_gicp"
    target, source = read_pcd_binary(fg / "251370668.pcd"), read_pcd_binary(fg / "251371071.pcd")
    assert np.array_equal(target, read_ply_binary(sg / "target.ply"))
    assert np.array_equal(source, read_ply_binary(sg / "source.ply"))
    out = Path(__file__).with_name("scans.npz")
    np.savez_compressed(
        out,
        target=np.round(thin(target) / SCALE).astype(np.int16),
        source=np.round(thin(source) / SCALE).astype(np.int16),
        scale=SCALE,
        T_fast_gicp=np.loadtxt(fg / "relative.txt"),
        T_small_gicp=np.loadtxt(sg / "T_target_source.txt"),
    )


if __name__ == "__main__":
    main(Path(sys.argv[1]))
