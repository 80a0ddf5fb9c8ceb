"""Trajectory accuracy: ATE, RPE and the relation-based error of SLAM / odometry estimates.

Two benchmarks define what we compute:

- Sturm, Engelhard, Endres, Burgard, Cremers, "A Benchmark for the Evaluation of RGB-D SLAM
  Systems", IROS 2012 (TUM RGB-D). *Relative pose error* (§VI-A, eqs. 1–2): with estimated poses
  P_i and ground truth Q_i in SE(3), E_i = (Q_i⁻¹ Q_{i+Δ})⁻¹ (P_i⁻¹ P_{i+Δ}) and
  RMSE(E, Δ) = (1/m Σ ‖trans(E_i)‖²)^½ over the m pairs. *Absolute trajectory error* (§VI-B):
  F_i = Q_i⁻¹ S P_i, with S the least-squares rigid transform mapping the estimated positions
  onto the true ones (Horn 1987; Umeyama 1991), summarised by RMSE(F) = (1/n Σ ‖trans(F_i)‖²)^½.
- Kümmerle, Steder, Dornhege, Ruhnke, Grisetti, Stachniss, Kleiner, "On measuring the accuracy
  of SLAM algorithms", Autonomous Robots 27(4), 2009. The error of a set of relative relations
  δ*_ij between timestamps (``*.relations`` files, one ``t_i t_j x y z roll pitch yaw`` per
  line: pose j in the frame of pose i) is ε(δ) = 1/N Σ trans(δ_ij ⊖ δ*_ij)² + rot(δ_ij ⊖ δ*_ij)²
  with δ_ij = x_j ⊖ x_i from the estimate; translational and rotational parts are reported
  separately as mean ± standard deviation of the absolute and the squared errors.

Poses are held as homogeneous SE(3) matrices (n × 4 × 4) in a :class:`Trajectory`; planar
SE(2) poses (x [m], y [m], ψ [rad]) — our vessel state, CARMEN logs — are lifted with a rotation
about z, so one code path serves both (a planar rotation angle is |ψ| wrapped to [0, π]).
TUM files are ``t x y z qx qy qz qw`` (quaternion scalar last), as ``mission._write_tum``
writes them. Units: metres, radians, seconds.
"""

from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from scipy.spatial.transform import Rotation

TUM_HEADER = "t x y z qx qy qz qw"


class Trajectory(NamedTuple):
    t: np.ndarray  # (n,) timestamps [s]
    poses: np.ndarray  # (n × 4 × 4) body poses in the world frame, SE(3)


class Relations(NamedTuple):
    t1: np.ndarray  # (m,) timestamp of the first pose [s]
    t2: np.ndarray  # (m,) timestamp of the second pose [s]
    delta: np.ndarray  # (m × 4 × 4) true pose at t2 in the frame of the pose at t1


# --- SE(2) / SE(3) helpers -------------------------------------------------------------------


def planar_to_se3(xy_yaw: np.ndarray) -> np.ndarray:
    """SE(3) matrices (n × 4 × 4) of planar poses (n × 3: x [m], y [m], ψ [rad])."""
    p = np.asarray(xy_yaw, float).reshape(-1, 3)
    c, s = np.cos(p[:, 2]), np.sin(p[:, 2])
    T = np.tile(np.eye(4), (len(p), 1, 1))
    T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
    T[:, :2, 3] = p[:, :2]
    return T


def se3_to_planar(T: np.ndarray) -> np.ndarray:
    """Planar poses (n × 3: x, y, ψ) of SE(3) matrices: ψ = atan2(R₂₁, R₁₁), z dropped."""
    return np.column_stack([T[:, 0, 3], T[:, 1, 3], np.arctan2(T[:, 1, 0], T[:, 0, 0])])


def se3_from_xyz_quat(xyz: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """SE(3) matrices (n × 4 × 4) from positions (n × 3) [m] and quaternions (n × 4, x y z w)."""
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    T = np.tile(np.eye(4), (len(xyz), 1, 1))
    if len(xyz):
        T[:, :3, :3] = Rotation.from_quat(np.asarray(quat, float).reshape(-1, 4)).as_matrix()
    T[:, :3, 3] = xyz
    return T


def xyz_quat_from_se3(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (n × 3) [m] and unit quaternions (n × 4, x y z w, w ≥ 0) of SE(3) matrices."""
    if len(T) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4))
    q = Rotation.from_matrix(T[:, :3, :3]).as_quat()
    return T[:, :3, 3].copy(), q * np.where(q[:, 3:] < 0.0, -1.0, 1.0)


def se3_from_xyz_rpy(xyz: np.ndarray, rpy: np.ndarray) -> np.ndarray:
    """SE(3) matrices from positions (n × 3) [m] and roll, pitch, yaw (n × 3) [rad] with
    R = R_z(yaw) R_y(pitch) R_x(roll) (Fossen's zyx convention, as in the relations files)."""
    xyz = np.asarray(xyz, float).reshape(-1, 3)
    rpy = np.asarray(rpy, float).reshape(-1, 3)
    T = np.tile(np.eye(4), (len(xyz), 1, 1))
    if len(xyz):
        T[:, :3, :3] = Rotation.from_euler("ZYX", rpy[:, ::-1]).as_matrix()
    T[:, :3, 3] = xyz
    return T


def se3_inverse(T: np.ndarray) -> np.ndarray:
    """Inverse of SE(3) matrices (… × 4 × 4): [Rᵀ, −Rᵀ t]."""
    Ti = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    Ti[..., :3, :3] = Rt
    Ti[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    Ti[..., 3, 3] = 1.0
    return Ti


def relative_poses(T_i: np.ndarray, T_j: np.ndarray) -> np.ndarray:
    """T_i⁻¹ T_j: pose j in the frame of pose i (the ⊖ of Kümmerle 2009, x_j ⊖ x_i)."""
    return se3_inverse(T_i) @ T_j


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Angle [rad] in [0, π] of rotation matrices (n × 3 × 3), ‖log R‖ — computed through the
    quaternion, which is accurate for small angles where arccos((tr R − 1)/2) is not."""
    if len(R) == 0:
        return np.zeros(0)
    return Rotation.from_matrix(R).magnitude()


def trajectory_from_tum(t: np.ndarray, xyz: np.ndarray, quat: np.ndarray) -> Trajectory:
    """A :class:`Trajectory` of TUM columns (see :func:`read_tum`)."""
    return Trajectory(np.asarray(t, float).reshape(-1), se3_from_xyz_quat(xyz, quat))


def trajectory_from_planar(t: np.ndarray, xy_yaw: np.ndarray) -> Trajectory:
    """A :class:`Trajectory` of planar poses (n × 3: x [m], y [m], ψ [rad]) at times t [s],
    e.g. ``trajectory_from_planar(*carmen.read_poses(path))``."""
    return Trajectory(np.asarray(t, float).reshape(-1), planar_to_se3(xy_yaw))


def as_trajectory(x) -> Trajectory:
    """A :class:`Trajectory` from a Trajectory, a ``(t, poses)`` tuple, or a pose array alone
    (then t = 0, 1, 2, … so time deltas count frames). Poses are (n × 3) planar x, y, ψ or
    (n × 4 × 4) SE(3) matrices."""
    if isinstance(x, Trajectory):
        return x
    if isinstance(x, tuple) and len(x) == 2:
        t, poses = x
    else:
        t, poses = None, x
    poses = np.asarray(poses, float)
    if poses.ndim == 2 and poses.shape[1] == 3:
        poses = planar_to_se3(poses)
    elif poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"poses must be (n, 3) planar or (n, 4, 4) SE(3), got {poses.shape}")
    t = np.arange(len(poses), dtype=float) if t is None else np.asarray(t, float).reshape(-1)
    if len(t) != len(poses):
        raise ValueError(f"{len(t)} timestamps for {len(poses)} poses")
    return Trajectory(t, poses)


# --- TUM files -------------------------------------------------------------------------------


def _read_columns(path, n: int) -> np.ndarray:
    """Rows of ``n`` numbers (space- or comma-separated; ``#`` comments and blank lines
    skipped) as an (m × n) array; a row with another count raises ValueError naming the file."""
    rows = []
    with open(path) as f:
        for line in f:
            line = line.split("#", 1)[0].replace(",", " ").strip()
            if line:
                values = line.split()
                if len(values) != n:
                    raise ValueError(f"{path}: expected {n} columns, got {len(values)}: {line!r}")
                rows.append([float(v) for v in values])
    return np.array(rows, dtype=float).reshape(-1, n)


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Timestamps (n,) [s], positions (n × 3) [m] and quaternions (n × 4, x y z w) of a TUM
    trajectory file (``t x y z qx qy qz qw`` per line; ``#`` comments and blank lines
    skipped; commas accepted as separators, as some tools write them)."""
    data = _read_columns(path, 8)
    return data[:, 0].copy(), data[:, 1:4].copy(), data[:, 4:8].copy()


def write_tum(path: str | Path, t: np.ndarray, xyz: np.ndarray, quat: np.ndarray) -> None:
    """Write a TUM trajectory file with a ``# t x y z qx qy qz qw`` header (9 decimals, enough
    to round-trip nanosecond stamps and sub-micrometre positions)."""
    rows = np.column_stack(
        [np.asarray(t, float).reshape(-1, 1), np.reshape(xyz, (-1, 3)), np.reshape(quat, (-1, 4))]
    )
    np.savetxt(path, rows, fmt="%.9f", header=TUM_HEADER)


def read_trajectory(path: str | Path) -> Trajectory:
    """A TUM file as a :class:`Trajectory`."""
    return trajectory_from_tum(*read_tum(path))


# --- association and alignment ---------------------------------------------------------------


def nearest_index(t: np.ndarray, query: np.ndarray, max_dt: float) -> np.ndarray:
    """Index into ``t`` of the stamp nearest each ``query`` stamp, or −1 where none lies within
    ``max_dt`` [s]. ``t`` need not be sorted (CARMEN logs step back in time)."""
    t = np.asarray(t, float)
    query = np.atleast_1d(np.asarray(query, float))
    if len(t) == 0:
        return np.full(len(query), -1)
    order = np.argsort(t, kind="stable")
    ts = t[order]
    hi = np.clip(np.searchsorted(ts, query), 0, len(ts) - 1)
    lo = np.maximum(hi - 1, 0)
    idx = order[np.where(np.abs(ts[lo] - query) <= np.abs(ts[hi] - query), lo, hi)]
    return np.where(np.abs(t[idx] - query) <= max_dt, idx, -1)


def associate(t_a: np.ndarray, t_b: np.ndarray, max_dt: float) -> tuple[np.ndarray, np.ndarray]:
    """One-to-one nearest-timestamp matching, as ``associate.py`` of the TUM RGB-D tools
    (Sturm et al. 2012): all pairs with |t_a − t_b| ≤ max_dt [s] are taken greedily in order of
    increasing time difference, each stamp used at most once. Returns index arrays (ia, ib),
    sorted by t_a."""
    t_a = np.asarray(t_a, float).reshape(-1)
    t_b = np.asarray(t_b, float).reshape(-1)
    order_b = np.argsort(t_b, kind="stable")
    tb = t_b[order_b]
    lo = np.searchsorted(tb, t_a - max_dt, side="left")
    hi = np.searchsorted(tb, t_a + max_dt, side="right")
    counts = hi - lo
    ia = np.repeat(np.arange(len(t_a)), counts)
    # offsets 0 … counts−1 within each a's window of candidate b's
    within = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    ib = order_b[np.repeat(lo, counts) + within]
    diff = np.abs(t_a[ia] - t_b[ib])
    keep = diff <= max_dt
    ia, ib, diff = ia[keep], ib[keep], diff[keep]
    used_a = np.zeros(len(t_a), bool)
    used_b = np.zeros(len(t_b), bool)
    out_a, out_b = [], []
    for k in np.argsort(diff, kind="stable"):
        a, b = ia[k], ib[k]
        if not used_a[a] and not used_b[b]:
            used_a[a] = used_b[b] = True
            out_a.append(a)
            out_b.append(b)
    out_a, out_b = np.array(out_a, dtype=int), np.array(out_b, dtype=int)
    order = np.lexsort((out_b, t_a[out_a])) if len(out_a) else np.zeros(0, dtype=int)
    return out_a[order], out_b[order]


def umeyama(
    a: np.ndarray, b: np.ndarray, with_scale: bool = False
) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares similarity (R, t, s) minimising (1/n) Σ ‖b_i − (s R a_i + t)‖² for point
    sets a, b (n × d, d = 2 or 3), R ∈ SO(d) (Umeyama, "Least-squares estimation of
    transformation parameters between two point patterns", IEEE PAMI 13(4) 1991, eqs. 38–42;
    the closed form Horn 1987 gives with quaternions, used by Sturm et al. 2012 for the ATE).

    With Σ_ab = (1/n) Σ (b_i − μ_b)(a_i − μ_a)ᵀ = U D Vᵀ: R = U S Vᵀ, S = diag(1, …, 1,
    det U det V) (a reflection is never returned), s = tr(D S) / σ_a² (1 without scale),
    t = μ_b − s R μ_a.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    if a.shape != b.shape or a.ndim != 2:
        raise ValueError(f"point sets must both be (n, d), got {a.shape} and {b.shape}")
    n, d = a.shape
    if n < 2:
        raise ValueError("umeyama needs at least 2 point pairs")
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    a0, b0 = a - mu_a, b - mu_b
    U, D, Vt = np.linalg.svd(b0.T @ a0 / n)
    S = np.ones(d)
    S[-1] = np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0
    R = (U * S) @ Vt
    s = float(D @ S / np.mean(np.sum(a0**2, axis=1))) if with_scale else 1.0
    return R, mu_b - s * R @ mu_a, s


def _associated(est, ref, max_dt: float) -> tuple[Trajectory, Trajectory]:
    est, ref = as_trajectory(est), as_trajectory(ref)
    ie, ir = associate(est.t, ref.t, max_dt)
    if len(ie) < 2:
        raise ValueError(f"only {len(ie)} poses associated within {max_dt} s")
    return Trajectory(est.t[ie], est.poses[ie]), Trajectory(ref.t[ir], ref.poses[ir])


def align_trajectory(
    est, ref, align: str = "se2", with_scale: bool = False
) -> tuple[Trajectory, np.ndarray, np.ndarray, float]:
    """``est`` moved by the least-squares transform S of its positions onto ``ref``'s (the
    two already associated pose for pose). align: ``"se3"`` (rotation and translation in 3D),
    ``"se2"`` (rotation about z and x-y translation, fitted on x-y: a planar vessel's
    estimate has no meaningful roll, pitch or z) or ``"none"``; with_scale adds a uniform
    scale (Sim(3)/Sim(2), for monocular estimates). Returns (aligned, R (3 × 3), t (3,) [m],
    s) with aligned positions s R p + t and orientations R R_i."""
    est, ref = as_trajectory(est), as_trajectory(ref)
    pe, pr = est.poses[:, :3, 3], ref.poses[:, :3, 3]
    R, t, s = np.eye(3), np.zeros(3), 1.0
    if align == "se3":
        R, t, s = umeyama(pe, pr, with_scale)
    elif align == "se2":
        R2, t2, s = umeyama(pe[:, :2], pr[:, :2], with_scale)
        R[:2, :2], t[:2] = R2, t2
    elif align != "none":
        raise ValueError(f"align must be 'se2', 'se3' or 'none', got {align!r}")
    poses = est.poses.copy()
    poses[:, :3, :3] = R @ est.poses[:, :3, :3]
    poses[:, :3, 3] = s * pe @ R.T + t
    return Trajectory(est.t, poses), R, t, s


# --- metrics ---------------------------------------------------------------------------------


def ate_errors(
    est, ref, align: str = "se2", with_scale: bool = False, max_dt: float = 0.02
) -> tuple[Trajectory, Trajectory, np.ndarray, float]:
    """The pose-by-pose absolute trajectory error (Sturm et al. 2012, §VI-B): ‖trans(Q_i⁻¹ S
    P_i)‖ [m] after associating ``est`` with ``ref`` by timestamp (within max_dt [s]) and
    aligning with S (:func:`align_trajectory`). est, ref: anything :func:`as_trajectory`
    accepts. Returns (the associated estimate aligned, the associated reference, the errors
    [m], the scale)."""
    est, ref = _associated(est, ref, max_dt)
    aligned, _, _, s = align_trajectory(est, ref, align, with_scale)
    e = np.linalg.norm(aligned.poses[:, :3, 3] - ref.poses[:, :3, 3], axis=1)
    return aligned, ref, e, s


def ate(est, ref, align: str = "se2", with_scale: bool = False, max_dt: float = 0.02) -> dict:
    """Absolute trajectory error (Sturm et al. 2012, §VI-B; :func:`ate_errors`). Returns RMSE,
    mean, median, standard deviation and maximum [m], the number of pairs and the scale."""
    _, _, e, s = ate_errors(est, ref, align, with_scale, max_dt)
    return ate_summary(e, s)


def ate_summary(e: np.ndarray, s: float = 1.0) -> dict:
    """:func:`ate`'s numbers from :func:`ate_errors`' errors ``e`` [m] and scale ``s``."""
    e = np.asarray(e, float)
    return {
        "ate_rmse_m": float(np.sqrt(np.mean(e**2))),
        "ate_mean_m": float(np.mean(e)),
        "ate_median_m": float(np.median(e)),
        "ate_std_m": float(np.std(e)),
        "ate_max_m": float(np.max(e)),
        "ate_pairs": len(e),
        "ate_scale": s,
    }


def plot_ate(
    aligned, ref, errors: np.ndarray, path: str | Path, title: str = "", index_label: str = "pose"
) -> Path:
    """PNG of where an estimate's absolute trajectory error lies (:func:`ate_errors`' output):
    left, the reference path in x-y (grey) with the aligned estimate's positions coloured by
    their error and a line from each to its reference position; right, the error pose by pose
    (``index_label`` names the axis) with its RMSE. Returns ``path``. Drawn on a bare
    :class:`~matplotlib.figure.Figure`: the caller's pyplot backend is left alone."""
    aligned, ref = as_trajectory(aligned), as_trajectory(ref)
    e = np.asarray(errors, float)
    pe, pr = aligned.poses[:, :2, 3], ref.poses[:, :2, 3]
    if not len(e) == len(pe) == len(pr):
        raise ValueError(
            f"plot_ate: {len(pe)} estimated and {len(pr)} reference poses, {len(e)} errors"
        )
    rmse = float(np.sqrt(np.mean(e**2))) if len(e) else float("nan")
    fig = Figure(figsize=(13, 5.5))
    ax_xy, ax_e = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.2, 1]})
    ax_xy.plot(pr[:, 0], pr[:, 1], color="0.6", lw=2, label="reference", zorder=1)
    ax_xy.add_collection(
        LineCollection(np.stack([pe, pr], axis=1), colors="0.3", linewidths=0.5, zorder=2)
    )
    dots = ax_xy.scatter(pe[:, 0], pe[:, 1], c=e, s=7, cmap="viridis", zorder=3, label="estimate")
    fig.colorbar(dots, ax=ax_xy, label="error [m]")
    ax_xy.set(xlabel="x [m]", ylabel="y [m]", title="estimate aligned to the reference")
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_xy.legend(loc="best", fontsize=8)
    ax_e.plot(np.arange(len(e)), e, lw=0.8, color="C0")
    ax_e.axhline(rmse, color="C3", ls="--", lw=1, label=f"RMSE {rmse:.3f} m")
    ax_e.set(xlabel=index_label, ylabel="error [m]", title="absolute trajectory error")
    ax_e.set_ylim(bottom=0.0)
    ax_e.legend(loc="upper right", fontsize=8)
    for ax in (ax_xy, ax_e):
        ax.grid(alpha=0.3)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    return path


def rpe_pairs(
    ref: Trajectory, delta: float, unit: str = "frames", rel_tol: float = 0.1
) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, j), j > i, Δ apart on the reference: ``"frames"`` j = i + Δ (Sturm eq. 1,
    all m = n − Δ pairs); ``"seconds"`` the stamp nearest t_i + Δ; ``"meters"`` the pose whose
    travelled path along the reference from i is nearest Δ. Seconds and metres keep a pair only
    when it is within rel_tol·Δ of Δ (as evo's ``all_pairs`` mode does for metres)."""
    n = len(ref.t)
    if unit == "frames":
        k = int(delta)
        if k != delta or k < 1:
            raise ValueError(f"a frame delta must be a positive integer, got {delta}")
        i = np.arange(max(n - k, 0))
        return i, i + k
    if delta <= 0:
        raise ValueError(f"delta must be positive, got {delta}")
    if unit == "seconds":
        along = ref.t
    elif unit == "meters":
        steps = np.linalg.norm(np.diff(ref.poses[:, :3, 3], axis=0), axis=1)
        along = np.concatenate([[0.0], np.cumsum(steps)])
    else:
        raise ValueError(f"unit must be 'frames', 'seconds' or 'meters', got {unit!r}")
    i = np.arange(n - 1)
    j = _nearest_ahead(along, delta)
    keep = np.abs(along[j] - along[i] - delta) <= rel_tol * delta
    return i[keep], j[keep]


def _nearest_ahead(along: np.ndarray, delta: float) -> np.ndarray:
    """For each i < n − 1 the first j > i minimising |along_j − along_i − Δ|."""
    n = len(along)
    if n < 2:
        return np.zeros(0, dtype=int)
    if np.all(np.diff(along) >= 0.0):
        i = np.arange(n - 1)
        target = along[i] + delta
        above = np.minimum(np.searchsorted(along, target, side="left"), n - 1)
        below = np.searchsorted(along, along[np.maximum(above - 1, 0)], side="left")
        below = np.maximum(below, i + 1)
        # the gap as (along_j − along_i) − Δ, rounded as evo rounds it, so ties break alike
        gap_below = np.abs(along[below] - along[i] - delta)
        gap_above = np.abs(along[above] - along[i] - delta)
        return np.where(gap_below <= gap_above, below, above)
    return np.array(
        [i + 1 + int(np.argmin(np.abs(along[i + 1 :] - along[i] - delta))) for i in range(n - 1)]
    )


def rpe(
    est,
    ref,
    delta: float,
    unit: str = "frames",
    max_dt: float = 0.02,
    rel_tol: float = 0.1,
) -> dict:
    """Relative pose error (Sturm et al. 2012, §VI-A, eqs. 1–2) over a fixed Δ
    (:func:`rpe_pairs`): E_i = (Q_i⁻¹ Q_{i+Δ})⁻¹ (P_i⁻¹ P_{i+Δ}), after associating ``est`` with
    ``ref`` by timestamp (within max_dt [s]). No alignment: a global rigid transform of the
    estimate cancels in P_i⁻¹ P_{i+Δ}. Returns RMSE, mean and maximum of ‖trans(E_i)‖ [m] and of
    the rotation angle ∠rot(E_i) [rad], and the number of pairs. Divide by Δ for drift per unit
    (e.g. per metre with ``unit="meters"``)."""
    est, ref = _associated(est, ref, max_dt)
    i, j = rpe_pairs(ref, delta, unit, rel_tol)
    if len(i) == 0:
        raise ValueError(f"no pose pairs {delta} {unit} apart")
    E = relative_poses(
        relative_poses(ref.poses[i], ref.poses[j]), relative_poses(est.poses[i], est.poses[j])
    )
    e_t = np.linalg.norm(E[:, :3, 3], axis=1)
    e_r = rotation_angle(E[:, :3, :3])
    return {
        "rpe_trans_rmse_m": float(np.sqrt(np.mean(e_t**2))),
        "rpe_trans_mean_m": float(np.mean(e_t)),
        "rpe_trans_max_m": float(np.max(e_t)),
        "rpe_rot_rmse_rad": float(np.sqrt(np.mean(e_r**2))),
        "rpe_rot_mean_rad": float(np.mean(e_r)),
        "rpe_rot_max_rad": float(np.max(e_r)),
        "rpe_pairs": len(e_t),
    }


# --- Kümmerle et al. 2009 relations ----------------------------------------------------------


def read_relations(path: str | Path) -> Relations:
    """A ``*.relations`` file (Kümmerle et al. 2009): one ``t1 t2 x y z roll pitch yaw`` line per
    relation, the true pose at t2 in the frame of the pose at t1 [s, m, rad]; ``#`` comments
    and blank lines skipped."""
    data = _read_columns(path, 8)
    return Relations(
        data[:, 0].copy(), data[:, 1].copy(), se3_from_xyz_rpy(data[:, 2:5], data[:, 5:8])
    )


def relation_error(est, relations: Relations, max_dt: float = 1e-3) -> dict:
    """Relation-based error (Kümmerle et al. 2009): for each relation δ*_ij whose two stamps
    both have an estimated pose within max_dt [s], the error transform δ*_ij⁻¹ δ_ij with
    δ_ij = P_i⁻¹ P_j from the estimate; its translation norm [m] and rotation angle [rad].
    ``est``: a :class:`Trajectory` or ``(t, poses)`` (e.g. :func:`carmen.read_poses`).
    Returns, as the paper's tables, mean and standard deviation (population) of the absolute
    and the squared errors, the maxima, ε(δ) = mean(trans² + rot²) of its metric, and how many
    relations were used and how many had no estimated pose."""
    est = as_trajectory(est)
    k1 = nearest_index(est.t, relations.t1, max_dt)
    k2 = nearest_index(est.t, relations.t2, max_dt)
    ok = (k1 >= 0) & (k2 >= 0)
    if not np.any(ok):
        raise ValueError(f"no relation has estimated poses within {max_dt} s")
    delta_est = relative_poses(est.poses[k1[ok]], est.poses[k2[ok]])
    E = relative_poses(relations.delta[ok], delta_est)
    e_t = np.linalg.norm(E[:, :3, 3], axis=1)
    e_r = rotation_angle(E[:, :3, :3])
    return {
        "rel_trans_mean_m": float(np.mean(e_t)),
        "rel_trans_std_m": float(np.std(e_t)),
        "rel_trans_sq_mean_m2": float(np.mean(e_t**2)),
        "rel_trans_sq_std_m2": float(np.std(e_t**2)),
        "rel_trans_max_m": float(np.max(e_t)),
        "rel_rot_mean_rad": float(np.mean(e_r)),
        "rel_rot_std_rad": float(np.std(e_r)),
        "rel_rot_sq_mean_rad2": float(np.mean(e_r**2)),
        "rel_rot_sq_std_rad2": float(np.std(e_r**2)),
        "rel_rot_max_rad": float(np.max(e_r)),
        "rel_epsilon": float(np.mean(e_t**2 + e_r**2)),
        "rel_relations": int(np.sum(ok)),
        "rel_unmatched": int(np.sum(~ok)),
    }
