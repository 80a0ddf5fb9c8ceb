"""Offline lidar-IMU-GPS SLAM (Roboat II §V) on recorded sensors, and the ablation of Roboat II
§VI-A.

:func:`run_slam3d` replays the lidar sweeps, IMU samples and GNSS fixes of a mission log
(``/lidar_points``, ``/imu``, ``/gps``) or a ROS bag (PointCloud2, Imu, NavSatFix; read by
:func:`usvdrake.logs.sensor_stream.read_sensor_stream`) through :class:`LidarInertialSlam`
exactly as the live :class:`~usvdrake.systems.slam.factor_graph_slam.FactorGraphSlam` feeds it:

* in time order; messages of one instant (within :data:`SAME_TIME` s, one tick of the live
  system) IMU first, then GPS, then lidar — so a sweep ending at t is predicted with the IMU up
  to t and can use the fix of t;
* per kind only a message newer than the last one taken, and only sweeps of at least
  :data:`MIN_CLOUD_POINTS` points (``FactorGraphSlam._update``);
* the online pose [x y ψ] is sampled at every ground-truth time t *before* the messages of t are
  taken (the live system ticks ``TICK_DELAY`` after the sensors, so its logged ``slam_pose`` at
  t has seen the messages before t), as ``slam.pose()`` — the last keyframe propagated to the
  last IMU sample, what the ``slam_pose`` port outputs — so :func:`slam3d_metrics` scores the
  offline run like the live one.

Which sensors it uses is decided from the recording and the switches: the IMU when the log has
IMU samples (before its first sweep or within :data:`DETECT_HORIZON` after) and the config's
``use_imu`` and the ``use_imu`` argument allow it — else lidar only, the constant-twist
prediction of :class:`~usvdrake.systems.slam.lidar_inertial.ConstantTwistPredictor` (KISS-ICP,
Vizzo et al. 2023); GPS when fixes are there and the graph's ``use_gps`` and a datum allow it;
loop closures by ``use_loop_closure``. ``metrics["mode"]`` says which (:func:`sensor_mode`).

:func:`ablation` runs the three variants of Roboat II §VI-A on one recording — lidar only, lidar +
GPS, lidar + GPS + loop closure — and :func:`format_table` / :func:`plot_ablation` show them.
"""

import itertools
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from tqdm import tqdm

from usvdrake.analysis.metrics import slam3d_counts, slam3d_metrics
from usvdrake.analysis.trajectory_metrics import write_tum, xyz_quat_from_se3
from usvdrake.logs.damage import ReadDamage
from usvdrake.logs.sensor_stream import SensorMessage, read_ground_truth, read_sensor_stream
from usvdrake.sensors.geodesy import LocalFrame
from usvdrake.systems.slam.factor_graph_slam import MIN_CLOUD_POINTS, mount_matrix
from usvdrake.systems.slam.lidar_inertial import (
    LidarInertialConfig,
    LidarInertialSlam,
    planar_pose,
    pose_matrix,
)
from usvdrake.systems.slam.slam_summary import summarise_3d

SAME_TIME = 1e-6  # [s] messages closer than this are of one instant (ordered IMU, GPS, lidar)
KIND_ORDER = {"imu": 0, "gps": 1, "lidar": 2}
DETECT_HORIZON = 1.0  # [s] after the first sweep: an IMU sample by then means the log has an IMU

# the variants of Roboat II §VI-A: (name, use_gps, use_loop_closure), run without our water-level
# factor (Roboat II's graph has none, and it would hide the vertical drift the ablation is about)
VARIANTS = (
    ("lidar", False, False),
    ("lidar+gps", True, False),
    ("lidar+gps+loop", True, True),
)
# the configured full graph, when it has the water-level factor (a fourth row)
WATER_VARIANT = "lidar+gps+loop+water"
# the columns of an ablation row (metrics of :func:`slam3d_metrics`)
ABLATION_KEYS = (
    "ate_m",
    "ate_final_m",
    "loop_return_error_m",
    "vertical_error_final_m",
    "vertical_error_max_m",
    "keyframe_ms_median",
    "keyframe_ms_p95",
    "loop_ms_p95",
    "gps_factors",
    "loop_closures",
    "degenerate_segments",
    "degenerate_max_error_m",
)


@dataclass
class Slam3DResult:
    """What :func:`run_slam3d` gives back.

    ``metrics``: :func:`slam3d_metrics` against ground truth (when the log has it) plus message
    counts and timings; ``keyframe_times`` (n,) [s] and ``keyframe_poses`` (n × 4 × 4)
    T_world_body: the final estimates; ``slam``: the :class:`LidarInertialSlam` after the run;
    ``initial_pose_source``: ``"given"``, ``"ground_truth"`` or ``"identity"``; ``truth``:
    (times, states n × 6) of the log's ``/ground_truth`` or None; ``online``: [x y ψ] online at
    the ground-truth times (n × 3, empty without ground truth)."""

    metrics: dict
    keyframe_times: np.ndarray
    keyframe_poses: np.ndarray
    slam: LidarInertialSlam
    initial_pose_source: str
    truth: tuple[np.ndarray, np.ndarray] | None = None
    online: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


def _mount(mount) -> np.ndarray:
    m = np.asarray(mount, dtype=float)
    if m.shape == (4, 4):
        return m.copy()
    if m.shape == (4,):
        return mount_matrix(m)
    raise ValueError(f"mount: expected [x y z yaw] or a 4 × 4 matrix, got shape {m.shape}")


def _ticks(stream: Iterator[SensorMessage]) -> Iterator[tuple[float, list[SensorMessage]]]:
    """Groups of messages of one instant (within SAME_TIME of the group's first), each group
    ordered IMU, GPS, lidar (stable within a kind)."""
    group: list[SensorMessage] = []
    for m in stream:
        if group and m.time > group[0].time + SAME_TIME:
            yield group[0].time, sorted(group, key=lambda g: KIND_ORDER[g.kind])
            group = []
        group.append(m)
    if group:
        yield group[0].time, sorted(group, key=lambda g: KIND_ORDER[g.kind])


def _peek(
    stream: Iterator[SensorMessage], horizon: float = DETECT_HORIZON
) -> tuple[list[SensorMessage], Iterator[SensorMessage]]:
    """(the messages up to ``horizon`` s after the first sweep, the whole stream again)."""
    head: list[SensorMessage] = []
    t_lidar = None
    for m in stream:
        head.append(m)
        if t_lidar is None and m.kind == "lidar":
            t_lidar = m.time
        if t_lidar is not None and m.time > t_lidar + horizon:
            break
    return head, itertools.chain(head, stream)


def sensor_mode(imu: bool, gps: bool, loops: bool) -> str:
    """The run's sensors in words: "lidar only", "lidar + IMU", "lidar + IMU + GPS", each
    with " + loops" when loop closure is on."""
    parts = ["lidar"] + ["IMU"] * imu + ["GPS"] * gps
    mode = "lidar only" if len(parts) == 1 else " + ".join(parts)
    return mode + " + loops" * loops


def run_slam3d(
    path: str | Path,
    config: LidarInertialConfig,
    initial_pose: np.ndarray | None = None,
    mount=(0.0, 0.0, 1.0, 0.0),
    datum: str | None = "amsterdam",
    progress: bool = False,
    lidar_topic: str | None = None,
    imu_topic: str | None = None,
    gps_topic: str | None = None,
    t0: float | None = None,
    description: str = "",
    use_imu: bool | None = None,
) -> Slam3DResult:
    """Run :class:`LidarInertialSlam` over a recording (module doc) and score it.

    Parameters
    ----------
    path
        A mission log (``.mcap`` or its run folder) or a ROS 1/2 bag.
    config
        The SLAM's parameters (not modified).
    initial_pose
        T_world_body (4 × 4) at the start; None: the log's first ground-truth state (x, y, ψ at
        height 0, as the live run starts from ``initial_state``), else the identity.
    mount
        T_body_lidar: [x y z yaw] [m, rad] (``LidarConfig.mount``) or 4 × 4.
    datum
        Origin of the world's ENU frame (:data:`usvdrake.sensors.geodesy.DATUMS`); None: GPS
        fixes are not used.
    progress
        A tqdm progress bar over the messages.
    lidar_topic, imu_topic, gps_topic
        Topics to read (:func:`read_sensor_stream`; None: the defaults).
    t0
        [s] time of the initial pose; None: the first ground-truth time with the ground-truth
        pose, else the first message's time.
    description
        A label stored as ``metrics["variant"]`` when given.
    use_imu
        False: withhold the IMU samples (lidar only); None / True: use them if the log has them
        and ``config.use_imu`` (module doc).

    Raises
    ------
    ConfigError
        The path is not a recording, a topic is missing, or there are no sensor messages.
    """
    path = Path(path)
    damage = ReadDamage()  # what a damaged log made the readers skip (metrics: skipped_records)
    stream = read_sensor_stream(path, lidar_topic, imu_topic, gps_topic, damage=damage)
    truth = read_ground_truth(path, damage=damage)
    head, stream = _peek(stream)
    first = head[0] if head else None
    imu_used = bool(config.use_imu and use_imu is not False and any(m.kind == "imu" for m in head))
    if imu_used != config.use_imu:
        config = replace(config, use_imu=imu_used)  # lidar only: constant-twist prediction
    source = "given"
    if initial_pose is None:
        if truth is not None and len(truth[0]):
            x, y, psi = truth[1][0, :3]
            initial_pose = pose_matrix(x, y, 0.0, psi)
            source = "ground_truth"
            t0 = float(truth[0][0]) if t0 is None else t0
        else:
            initial_pose = np.eye(4)
            source = "identity"
    if t0 is None:
        t0 = first.time if first is not None else 0.0
    frame = LocalFrame(datum) if datum else None
    slam = LidarInertialSlam(config, np.asarray(initial_pose, float), _mount(mount), frame, t0)

    it = stream
    bar = None
    if progress:
        bar = tqdm(unit="msg", desc=f"slam3d {description or path.name}")
    gt_t = truth[0] if truth is not None else np.zeros(0)
    online = np.zeros((len(gt_t), 3))
    i = 0  # next ground-truth time to sample
    seen = {"imu": -np.inf, "gps": -np.inf, "lidar": -np.inf}
    counts = {"imu": 0, "gps": 0, "lidar": 0}
    skipped_clouds = 0
    wall0 = time.perf_counter()
    t_first = t_last = None
    lidar_only = slam.lidar_only
    for t, group in _ticks(it):
        while i < len(gt_t) and gt_t[i] <= t + SAME_TIME:  # before the messages of gt_t[i]
            # lidar only, the constant twist predicts to the sample's time (there are no IMU
            # samples to carry the pose past the last sweep)
            online[i] = planar_pose(slam.pose(gt_t[i] if lidar_only else None))
            i += 1
        t_first = t if t_first is None else t_first
        t_last = t
        for m in group:
            counts[m.kind] += 1
            if m.time <= seen[m.kind]:
                continue
            if m.kind == "imu":
                slam.add_imu(m.msg)
            elif m.kind == "gps":
                slam.add_gps(m.msg)
            elif len(m.msg.points) >= MIN_CLOUD_POINTS:
                slam.add_cloud(m.msg)
            else:
                skipped_clouds += 1
                continue
            seen[m.kind] = m.time
        if bar is not None:
            bar.update(len(group))
    while i < len(gt_t):
        online[i] = planar_pose(slam.pose(gt_t[i] if lidar_only else None))
        i += 1
    wall = time.perf_counter() - wall0
    if bar is not None:
        bar.close()

    duration = float(t_last - t_first) if t_first is not None else 0.0
    metrics: dict = {"log": str(path)}
    if description:
        metrics["variant"] = description
    use_gps = bool(config.graph.use_gps and frame is not None)
    metrics |= {
        "mode": sensor_mode(imu_used, use_gps and counts["gps"] > 0, config.graph.use_loop_closure),
        "imu_used": imu_used,
        "use_gps": use_gps,
        "use_loop_closure": bool(config.graph.use_loop_closure),
        "water_level": bool(config.graph.water_level_sigma > 0),
        "initial_pose": source,
        "lidar_messages": counts["lidar"],
        "imu_messages": counts["imu"],
        "gps_messages": counts["gps"],
        "sparse_sweeps_skipped": skipped_clouds,
        **damage.metrics(),
        "wall_time_s": wall,
        "log_duration_s": duration,
        "realtime_factor": duration / wall if wall > 0 else 0.0,
    }
    if truth is not None and len(gt_t):
        metrics |= slam3d_metrics(gt_t, truth[1], online, summarise_3d(slam))
    else:
        metrics |= slam3d_counts(summarise_3d(slam))
    kt, poses = slam.trajectory()
    return Slam3DResult(metrics, kt, poses, slam, source, truth, online)


def variant_config(
    config: LidarInertialConfig, use_gps: bool, use_loop: bool, water: bool | None = None
):
    """A copy of ``config`` with the graph's GPS and loop-closure switches set; water: False
    drops the water-level factor, None keeps the config's."""
    graph = replace(config.graph, use_gps=use_gps, use_loop_closure=use_loop)
    if water is False:
        graph = replace(graph, water_level_sigma=0.0)
    return replace(config, graph=graph)


def run_ablation(path: str | Path, config: LidarInertialConfig, **kwargs) -> list[Slam3DResult]:
    """The runs of Roboat II §VI-A's ablation on one recording, one after the other
    (:data:`VARIANTS`:
    lidar only; lidar + GPS; lidar + GPS + loop closure — without the water-level factor), and,
    when ``config`` has the water-level factor, the full graph with it (:data:`WATER_VARIANT`);
    ``kwargs`` go to :func:`run_slam3d`. ``config`` is not modified."""
    runs = [(name, variant_config(config, gps, loop, False)) for name, gps, loop in VARIANTS]
    if config.graph.water_level_sigma > 0:
        runs.append((WATER_VARIANT, variant_config(config, True, True)))
    return [run_slam3d(path, cfg, description=name, **kwargs) for name, cfg in runs]


def ablation_rows(results: list[Slam3DResult]) -> list[dict]:
    """One row per variant: its name, switches and :data:`ABLATION_KEYS` (None if missing)."""
    rows = []
    for r in results:
        m = r.metrics
        row = {
            "variant": m.get("variant", ""),
            "use_gps": m["use_gps"],
            "use_loop_closure": m["use_loop_closure"],
            "water_level": m.get("water_level", False),
            "keyframes": m.get("slam_keyframes"),
        }
        rows.append(row | {k: m.get(k) for k in ABLATION_KEYS})
    return rows


def ablation(path: str | Path, config: LidarInertialConfig, **kwargs) -> list[dict]:
    """Roboat II §VI-A's ablation as rows (:func:`run_ablation`, :func:`ablation_rows`)."""
    return ablation_rows(run_ablation(path, config, **kwargs))


def format_table(rows: list[dict]) -> str:
    """A plain fixed-width table of ablation rows (one line per variant)."""
    if not rows:
        return "(no rows)"
    keys = list(rows[0])

    def cell(v) -> str:
        if v is None:
            return "-"
        if isinstance(v, bool):
            return "yes" if v else "no"
        if isinstance(v, float):
            return f"{v:.3f}"
        return str(v)

    cells = [[cell(r.get(k)) for k in keys] for r in rows]
    widths = [max(len(k), *(len(c[j]) for c in cells)) for j, k in enumerate(keys)]
    lines = [
        "  ".join(
            k.rjust(w) if j else k.ljust(w)
            for j, (k, w) in enumerate(zip(keys, widths, strict=True))
        )
    ]
    lines.append("  ".join("-" * w for w in widths))
    for c in cells:
        lines.append(
            "  ".join(
                v.rjust(w) if j else v.ljust(w)
                for j, (v, w) in enumerate(zip(c, widths, strict=True))
            )
        )
    return "\n".join(lines)


def plot_ablation(
    results: list[Slam3DResult],
    truth: tuple[np.ndarray, np.ndarray] | None,
    path: str | Path,
) -> Path:
    """PNG of the variants' keyframe trajectories (final estimates) over ground truth in x-y
    (left) and their height z over time (right; the truth is at 0). Returns ``path``."""
    fig = Figure(figsize=(13, 5.5))
    ax_xy, ax_z = fig.subplots(1, 2)
    if truth is not None and len(truth[0]):
        t, s = truth
        ax_xy.plot(s[:, 0], s[:, 1], color="0.6", lw=3, label="ground truth")
        ax_z.plot([t[0], t[-1]], [0.0, 0.0], color="0.6", lw=3, label="ground truth")
    for j, r in enumerate(results):
        name = r.metrics.get("variant", "")
        p = r.keyframe_poses
        if len(p) == 0:
            continue
        style = {"lw": 1.2, "ls": ("-", "--", ":")[j % 3], "label": name}
        ax_xy.plot(p[:, 0, 3], p[:, 1, 3], **style)
        ax_z.plot(r.keyframe_times, p[:, 2, 3], **style)
    ax_xy.set(xlabel="x [m]", ylabel="y [m]", title="keyframes (final estimates)")
    ax_xy.set_aspect("equal", adjustable="datalim")
    ax_z.set(xlabel="t [s]", ylabel="z [m]", title="height of the keyframes")
    for ax in (ax_xy, ax_z):
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle("Roboat II §VI-A ablation: lidar / + GPS / + GPS + loop closure")
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=120)
    return path


def write_keyframes_tum(path: str | Path, result: Slam3DResult) -> Path:
    """The keyframes' final estimates as a TUM file (``t x y z qx qy qz qw``)."""
    xyz, q = xyz_quat_from_se3(result.keyframe_poses)
    write_tum(path, result.keyframe_times, xyz, q)
    return Path(path)
