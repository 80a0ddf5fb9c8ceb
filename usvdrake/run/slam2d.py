"""Offline 2D SLAM on recorded scans (``usvdrake slam2d``): CARMEN logs and ROS 1/2 bags.

Wheel odometry where the log has it (a raw CARMEN log's FLASER pose fields, a ROS bag's
``/odom``), calibrated by the scans and gated against them, as a motion prior between the
scans; scan-only (Pham et al.'s system) where it has none, on a "corrected" CARMEN log (whose
pose fields are the reference) or when asked (``odometry=False``, ``--scan-only``). Every
scan goes through :class:`GraphSlam`; the
output trajectory is every scan's pose re-expressed from its node after the last optimisation,
stamped with the log's own timestamps. With a reference trajectory (e.g. a "corrected" log) the
ATE is computed after an SE(2) alignment (Sturm et al. 2012).
"""

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from matplotlib.image import imsave
from tqdm import tqdm

from usvdrake.analysis.trajectory_metrics import (
    ate_errors,
    ate_summary,
    plot_ate,
    trajectory_from_planar,
    write_tum,
)
from usvdrake.logs.carmen import associate_scans, has_odometry, is_corrected, read_carmen
from usvdrake.logs.damage import ReadDamage
from usvdrake.logs.mission_log import read_log_scans, read_log_states
from usvdrake.logs.rosbag import is_bag, read_bag_scans
from usvdrake.systems.slam.graph_slam import GraphSlam, GraphSlamConfig, compose
from usvdrake.typed_yaml import ConfigError

GARBAGE_KINDS = ("random", "half_empty", "nan")

# The graph SLAM for scan streams at the sensor's rate (ROS bags, mission logs): Pham et al.'s, a
# poor match re-seeded by the correlative search.
STREAM_CONFIG = GraphSlamConfig(correlative_trigger=1.0)

# The graph SLAM for CARMEN building logs, which may be subsampled (the "corrected" CARMEN logs step
# ~0.7 m and ~22° between scans, far outside PLICP's basin) and have no odometry. Measured on
# intel-corrected (910 scans; bench/slam2d_logs.py):
# * every scan is also searched from rest by the correlative matcher (±1.5 m, ±92°: MIT-CSAIL
#   turns up to 78° between scans), the search replacing PLICP's constant-velocity match when
# its likelihood is 0.05 higher; PLICP refines a searched pose pairing points within 0.5 m only
# (from 1 m it wandered off a good seed: steps off by > 0.2 m or 3° went from 42 to 24 of 909, loops
# off);
# * a candidate of that search or that choice scores 0.25 /m² × its sideways motion² less (the
#   step off the arc through both poses, ``correlative.lateral_motion``): a wheeled robot cannot
#   slide, and corridors had matched 30° turns on the spot as turns plus sideways jumps of up
#   to 1 m. Intel 0.287 -> 0.153 m (30 -> 16 steps off by > 0.2 m or 3°), MIT-CSAIL 1.84 ->
#   0.41 m, ACES 4.41 -> 3.70 m, Freiburg 079 0.085 -> 0.082 m; weights 0.1 / 0.5 / 1 / 2:
#   Intel - / 0.172 / 0.201 / 0.186, MIT-CSAIL 0.36 / 4.92 (one 106° wrong turn) / - / -,
#   ACES 3.37 / 3.70 / - / -;
# * no dense links (a wrong one, Gaussian, bent the chain) and a node needs 20 matched points
#   (open halls leave fewer than 40 returns);
# * loops: one candidate per earlier pass within 4 m, searched within ±1.5 m / ±20°, the new
#   node's last 4 scans against the candidate's 7; refused when the best pose elsewhere
#   (≥ 0.5 m away) scores 70 % of it (corridors, rows of doors; on the first 500 scans 5 of 303
#   accepted were wrong, 106 of 552 without this test); Gaussian, rejected by GNC when
#   inconsistent;
# * every scan is a node (5 cm / 0.03 rad thresholds): the logs are already subsampled, and a
#   scan that did not make a node left the next one to match a node two steps (~2 m) back
#   (on Intel the lost corridor steps followed such scans). With the submap refinement
#   below: Intel 1.13 -> 0.26 m, ACES 3.55 -> 4.41 m, MIT-CSAIL unchanged at 1.84 m; both
#   together took Freiburg 079 from 0.103 to 0.084 m (not measured apart);
# * a searched loop is refined by PLICP against the candidate's 7-scan submap, not its one
#   scan: in isolation (every Intel scan at its reference pose, the guess 0.3 m off) 207 of
#   911 candidates accepted instead of 94, none off by more than 0.3 m (Intel 1.26 -> 1.13 m).
LOG_CONFIG = GraphSlamConfig(
    node_translation=0.05,
    node_rotation=0.03,
    correlative_trigger=0.0,
    search_linear_window=1.5,
    search_angular_window=1.6,
    search_from_rest=True,
    # MIT-CSAIL's corrected log stamps every scan alike: there the search's higher score wins
    # (GraphSlamConfig.search_prior_margin), 0.35 -> 0.24 m; Intel 0.079 -> 0.080 m
    search_prior_margin=0.05,
    lateral_weight=0.25,
    refine_max_distance=0.5,
    # a refinement PLICP does not converge in 50 iterations is set against a Gauss-Newton ascent
    # of the search's likelihood field: at MIT-CSAIL's scan 117 PLICP slid from the search's
    # 1.10 m step (score 0.911; the reference 1.145 m) down the corridor to 0.86 m (0.871), the
    # field's ascent stops at 1.13 m (0.914). On 83 of its 406 scans PLICP did not converge, 32
    # took the field's pose: MIT-CSAIL 0.232 -> 0.135 m, Intel 0.083 -> 0.095 m, Freiburg 079
    # 0.081 -> 0.081 m (landscape temperature 1 / 3: MIT-CSAIL 0.165 / 0.128 m)
    field_refine_unconverged=True,
    min_link_points=20,
    # raw ACES's scan 2945 (after a 3 s gap in the log) shows little of its node's scene:
    # `--fast`'s small search put it 0.39 m sideways at a likelihood of 0.10 with a residual
    # under max_track_residual, and the node made there bent the whole map (ATE 16.9 m). No
    # other tracked scan of raw MIT-CSAIL or of raw ACES's first 2950 scored below 0.4
    min_track_score=0.3,
    link_radius=0.0,
    loop_index_gap=15,
    loop_radius=4.0,
    loop_per_chain=True,
    loop_linear_window=1.5,
    loop_angular_window=0.35,
    min_loop_score=0.5,
    max_loop_ambiguity=0.7,
    loop_robust=False,
    loop_gnc=True,
    loop_confirm_nodes=10,
    # loops as tight as a scan match (the 3 cm floor let the chain's drift win: Freiburg 079
    # 0.118 -> 0.103 m)
    loop_min_sigma=[0.01, 0.01, 0.005],
    loop_refine_submap=True,
    # the searched loop's pose searched again for the new scan alone (±0.6 m, ±0.1 rad): at
    # MIT-CSAIL's scan 326 a wrong tracking step had put the query's other scans 0.4 m off and
    # its loop with them (0.49 m off the reference; again: 0.10 m). Intel 0.095 -> 0.087 m,
    # MIT-CSAIL 0.135 -> 0.132 m, Freiburg 079 0.081 -> 0.078 m
    loop_rematch_window=0.6,
    # consecutive constraints as uncertain as the tracking field says (a corridor's length
    # free), not Censi's centimetres: loops then stretch the corridor steps the scans could not
    # measure instead of bending the whole chain. Intel 0.153 -> 0.079 m (temperature 1: 0.099,
    # 3: 0.096), MIT-CSAIL 0.41 -> 0.35 m (3: 0.32)
    landscape_temperature=2.0,
    # with wheel odometry, its step seeds a second tracking match (GraphSlamConfig.odometry_seed):
    # raw ACES's first corridor had tracked 0.2 m of the 2.1 m driven, and the odometry's span
    # over it was gated out. With the spans' recalibration (GraphSlam._measurement): raw Intel
    # 0.106 -> 0.0935 m, ACES 0.303 -> 0.198 m, MIT-CSAIL 0.156 -> 0.158 m, Freiburg 079 0.104 ->
    # 0.106 m (docs/experiments/slam2d-odometry.md)
    odometry_seed=True,
    # no relinking of the final estimate (GraphSlam.relink): within 10 m it took MIT-CSAIL from
    # 0.135 to 0.0998 m (67 s more) but Intel from 0.095 to 0.109 m (30 links per node); it is
    # `usvdrake slam2d --relink RADIUS`
)


# `slam2d --fast`: LOG_CONFIG made to keep up with a log that has wheel odometry (the raw
# CARMEN logs: every scan the robot recorded, 5-8 a second; docs/experiments/slam2d-realtime.md,
# 2026-11-27). The odometry says roughly where each scan is, so tracking searches ±0.3 m /
# ±0.35 rad about its guess, not ±1.5 m / ±92° about rest; a node every 0.15 m / 0.05 rad, not
# 5 cm; loops looked for every 0.3 m of the graph, not at every node. Raw ACES's first 800
# scans: 79 -> 36 ms of CPU a scan, 2.98x -> 6.84x real time. It costs accuracy (raw MIT-CSAIL
# 0.156 -> 0.219 m ATE, Freiburg 079 0.104 -> 0.109 m), so the default stays LOG_CONFIG.
LOG_ODOMETRY_CONFIG = replace(
    LOG_CONFIG,
    odometry_search_window=[0.3, 0.35],
    node_translation=0.15,
    node_rotation=0.05,
    loop_spacing=0.3,
)

# [s] of log time between the full-graph optimisations loops ask for, offline (the LeafSystem
# runs them in a 1 s event). Freiburg 079, where almost every scan closes a loop: 1 s gave
# 0.082 m ATE in 1374 s wall for 1061 s of log (676 full GNC solves, 890 s of them), 3 s 0.085 m
# in 790 s (286 solves, 285 s): 1.34x real time. Intel (scans ~3 s apart): 0.258 m after every
# scan, 0.414 m at 2 s, 0.287 m at 3 s: which loops are found depends on when the graph was
# last optimised, and Intel's error is that sensitive.
FULL_PERIOD = 3.0

# [ms per graph node] of log time a full optimisation in the worker process may take before
# the scans wait for it (at least FULL_PERIOD). A GNC solve's cost grows with the graph: on
# Intel's raw log (10 733 nodes, up to 16 s a solve) a fixed 3 s left the scans waiting 692 s
# in all and up to 423 s behind the recording (1.31x real time); 2 ms per node (21 s at the
# end): 3.6 s of waiting, 16 s behind at most, 2.42x real time, ATE 0.180 -> 0.192 m (fewer,
# later merges: 567 -> 276 full optimisations).
FULL_BUDGET_MS_PER_NODE = 2.0


def corrupt_scans(scans: list, fraction: float, seed: int = 0) -> tuple[list, np.ndarray]:
    """A copy of ``scans`` (records with ``.scan``) where a ``fraction`` of them, chosen at
    random, is replaced by garbage, the kinds in turn (:data:`GARBAGE_KINDS`): uniformly random
    ranges over the sensor's span; half the beams (a contiguous half) without return; every
    range NaN while flagged valid (a broken driver). Returns (scans, indices replaced)."""
    if not 0.0 <= fraction <= 1.0:
        raise ValueError(f"corrupt_scans: fraction must be in [0, 1], got {fraction}")
    rng = np.random.default_rng(seed)
    n = len(scans)
    picked = np.sort(rng.choice(n, size=int(round(fraction * n)), replace=False))
    out = list(scans)
    for j, i in enumerate(picked):
        scan = scans[i].scan
        r = np.asarray(scan.ranges, float).copy()
        kind = GARBAGE_KINDS[j % len(GARBAGE_KINDS)]
        if kind == "random":
            hi = float(scan.range_max) if np.isfinite(scan.range_max) and scan.range_max else 30.0
            r = rng.uniform(max(float(scan.range_min), 0.1), hi, len(r))
            valid = np.ones(len(r), bool)
        elif kind == "half_empty":
            start = int(rng.integers(len(r)))
            gone = (np.arange(len(r)) - start) % len(r) < len(r) // 2
            r[gone] = np.inf
            valid = np.asarray(scan.valid, bool) & ~gone
        else:
            r[:] = np.nan
            valid = np.ones(len(r), bool)
        out[i] = scans[i]._replace(scan=replace(scan, ranges=r, valid=valid))
    return out, picked


def _stamps_advance(scans) -> bool:
    """Whether the records' time stamps measure time: the median step between them is > 0
    (MIT-CSAIL's corrected log stamps every scan alike but one, 10000 s later)."""
    t = np.array([rec.timestamp for rec in scans], float)
    return len(t) > 1 and bool(np.median(np.diff(t)) > 0)


def run_graph_slam(
    scans,
    cfg: GraphSlamConfig,
    progress: bool = False,
    full_period: float = FULL_PERIOD,
    full_budget_ms_per_node: float = FULL_BUDGET_MS_PER_NODE,
    odometry: bool = False,
):
    """(timestamps, poses (n × 3), slam) for a sequence of CarmenScan-like records;
    ``odometry``: with each record's ``odometry_pose`` (:meth:`GraphSlam.process`).

    The full-graph optimisation a loop closure asks for starts at most once per
    ``full_period`` [s] of the log's time (0, or stamps that do not advance: at any scan), as
    the LeafSystem's own slower event starts it. With ``cfg.full_in_worker`` it runs in the
    worker process while the next scans are tracked and is merged at the first scan its
    budget after it started, waiting for it there if it is not done, so the result does not
    depend on the machine's speed. The budget [s of log time] is ``full_period`` or
    ``full_budget_ms_per_node`` [ms] × the graph's nodes, whichever is longer (a full solve's cost
    grows with the graph: Intel's raw log reaches 16 s over 10 700 nodes); without a clock,
    the next scan. Without the worker it is solved and merged at once. Whatever is pending
    is merged after the last scan; the poses are every scan's, re-expressed from its node
    after that. ``stats["offline_step_ms"]``: each scan's wall time, waits and merges
    included."""
    if not full_period >= 0.0:
        raise ValueError(f"run_graph_slam: full_period must be >= 0 s, got {full_period}")
    if not full_budget_ms_per_node >= 0.0:
        raise ValueError(
            f"run_graph_slam: full_budget_ms_per_node must be >= 0, got {full_budget_ms_per_node}"
        )
    if not _stamps_advance(scans):
        full_period = full_budget_ms_per_node = 0.0  # no clock to pace it by: at any scan
    slam = GraphSlam(cfg)
    stamps, anchors = [], []
    iterator = scans
    if progress:
        iterator = tqdm(scans, unit="scan")
    now = started = due = -np.inf
    steps = slam.stats.setdefault("offline_step_ms", [])
    for rec in iterator:
        t0 = time.perf_counter()
        slam.process_scan(
            replace(rec.scan, time=rec.timestamp),
            odometry=rec.odometry_pose if odometry else None,
        )
        now = max(now, rec.timestamp)  # (corrected CARMEN logs' stamps may step back)
        if now >= due:
            slam.finish_full()
        if not slam.full_running and now - started >= full_period and slam.start_full():
            started = now
            due = now + max(full_period, full_budget_ms_per_node * len(slam.nodes) / 1e3)
            if not cfg.full_in_worker:
                slam.finish_full()  # solved already
        steps.append((time.perf_counter() - t0) * 1e3)
        stamps.append(rec.timestamp)
        anchors.append((max(len(slam.nodes) - 1, 0), slam._rel.copy()))
    slam.optimise_pending()
    slam.relink(progress)  # (cfg.relink_radius > 0) the final estimate relinked, re-optimised
    if not cfg.live_map:
        slam.render_map()  # every scan once, at its final pose (in the wall time)
    poses = np.array(
        [compose(slam.nodes[i].pose, rel) if slam.nodes else rel for i, rel in anchors]
    )
    return np.asarray(stamps), poses, slam


def replay_lag(stamps, step_s) -> np.ndarray:
    """[s] how far behind each scan's arrival its processing ends when a log is played back at
    its own pace: scan i arrives at ``stamps[i]`` (made non-decreasing), waits for the scans
    before it and takes ``step_s[i]``, so it ends at e_i = max(stamps[i], e_{i−1}) + step_s[i]
    and lags e_i − stamps[i]. A run keeps up when the lags stay bounded (a full optimisation
    can be caught up on while the sensor is quiet); a real-time factor above 1 alone can hide
    a backlog that only clears at the log's end."""
    t = np.maximum.accumulate(np.asarray(stamps, float))
    cost = np.asarray(step_s, float)
    if t.shape != cost.shape:
        raise ValueError(f"replay_lag: {len(t)} stamps but {len(cost)} step times")
    end, lag = -np.inf, np.empty(len(t))
    for i, (ti, ci) in enumerate(zip(t, cost, strict=True)):
        end = max(ti, end) + ci
        lag[i] = end - ti
    return lag


def run_slam2d(
    log: str | Path,
    out: str | Path,
    reference: str | Path | None = None,
    resolution: float = 0.1,
    max_scans: int | None = None,
    progress: bool = True,
    garbage: float = 0.0,
    seed: int = 0,
    config: GraphSlamConfig | None = None,
    full_period: float = FULL_PERIOD,
    full_in_worker: bool | None = None,
    full_budget_ms_per_node: float = FULL_BUDGET_MS_PER_NODE,
    relink_radius: float | None = None,
    odometry: bool | None = None,
    fast: bool = False,
) -> dict:
    """Run the graph SLAM on a CARMEN log, a ROS bag or a mission log; write trajectory.tum,
    map.png, metrics.json and, scored against a ``reference``, ate.png (where the error lies:
    :func:`~usvdrake.analysis.trajectory_metrics.plot_ate`). ``garbage``: the fraction of
    scans replaced by garbage first (:func:`corrupt_scans`, seeded by ``seed``), to test
    robustness. ``config``: the SLAM's (its map fields are set here); by default
    :data:`LOG_CONFIG` for CARMEN logs and :data:`STREAM_CONFIG` for bags and mission logs.
    ``full_period``: log time [s] between the
    full-graph optimisations loops ask for (:func:`run_graph_slam`); ``full_in_worker``: solve
    them in the worker process (True) or here (False) instead of as ``config`` says;
    ``full_budget_ms_per_node``: the worker's time per node (:func:`run_graph_slam`);
    ``relink_radius`` [m]: relink the final estimate (:meth:`GraphSlam.relink`) instead of as
    ``config`` says. ``odometry``: None (default) or True: the log's wheel odometry where it
    has it (a raw CARMEN log's FLASER pose fields, a bag's ``/odom``; :meth:`GraphSlam.process`),
    scan-only where it has none or on a "corrected" CARMEN log, whose pose fields are the
    reference; False: scan-only. ``metrics["motion_prior"]`` says which was used and why.
    ``fast``: with odometry on a CARMEN log, :data:`LOG_ODOMETRY_CONFIG` (keeps up with the
    robot, less accurate)."""
    log = Path(log)
    base = STREAM_CONFIG
    damage = ReadDamage()  # what a damaged log made the reader skip (metrics: skipped_records)
    messages: set[str] = set()  # a CARMEN log's message names (is_corrected)
    if log.suffix == ".mcap":
        scans = read_log_scans(log, damage=damage)
    elif is_bag(log):
        scans = list(read_bag_scans(log, damage=damage))
    elif log.is_file():
        # the laser's pose fields: the odometry's pose of the laser itself (in fr079 0.04 m ahead
        # of the robot's odom fields)
        scans = list(read_carmen(log, pose="laser", damage=damage, messages=messages))
        base = LOG_CONFIG
    else:
        raise ConfigError(
            log, "", "a CARMEN log, a ROS 1/2 bag or a usvdrake .mcap", "no such file"
        )
    if max_scans:
        scans = scans[:max_scans]
    if not scans:
        raise ConfigError(log, "", "laser scans", "none" + damage.note())
    if odometry is False:
        without = "--scan-only"
    elif base is LOG_CONFIG and (is_corrected(messages) or _same_file(log, reference)):
        without = "a corrected log: its poses are the reference"
    elif not any(getattr(rec, "odometry_pose", None) is not None for rec in scans) or (
        base is LOG_CONFIG and not has_odometry(scans)
    ):
        without = "log has no odometry"
    else:
        without = None
    odometry = without is None
    if odometry and fast and base is LOG_CONFIG:
        base = LOG_ODOMETRY_CONFIG
    clean = scans  # the reference names scans by their ranges, garbage or not
    corrupted = np.zeros(0, int)
    if garbage > 0:
        scans, corrupted = corrupt_scans(scans, garbage, seed)
    # the sensor's own range (CARMEN logs: 50 m; no-returns are beyond it)
    max_range = min(50.0, max(float(rec.scan.range_max) or 50.0 for rec in scans))
    cfg = replace(
        base if config is None else config,
        map_resolution=resolution,
        map_origin=[-100.0, -100.0],
        map_size=[200.0, 200.0],
        max_range=max_range,
        live_map=False,  # nothing reads the map before the end: drawn once at the final poses
    )
    if full_in_worker is not None:
        cfg = replace(cfg, full_in_worker=full_in_worker)
    if relink_radius is not None:
        if not relink_radius >= 0.0:
            raise ValueError(f"run_slam2d: relink_radius must be >= 0 m, got {relink_radius}")
        cfg = replace(cfg, relink_radius=relink_radius)
    wall0 = time.perf_counter()
    stamps, poses, slam = run_graph_slam(
        scans, cfg, progress, full_period, full_budget_ms_per_node, odometry
    )
    wall = time.perf_counter() - wall0
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    half = poses[:, 2] / 2
    write_tum(
        out / "trajectory.tum",
        stamps,
        np.column_stack([poses[:, :2], np.zeros(len(poses))]),
        np.column_stack([np.zeros((len(poses), 2)), np.sin(half), np.cos(half)]),
    )
    grid = slam.map.to_occupancy_grid()
    _write_map_png(out / "map.png", grid)
    track = np.asarray(slam.stats["tracking_ms"])
    duration = float(stamps.max() - stamps.min()) if len(stamps) > 1 else 0.0
    timed = _stamps_advance(scans)
    metrics = {
        "log": str(log),
        # wheel odometry or scan-only, and why
        "motion_prior": _motion_prior(slam, without),
        "scans": len(scans),
        "garbage_scans": len(corrupted),
        # records of a damaged log left out, bytes it could not read, and why (ReadDamage)
        **damage.metrics(),
        "odometry": odometry,  # False: scan-only
        # (distance, turn) factors the scans calibrated the odometry by (GraphSlam.odometry_scale)
        "odometry_scale": [float(k) for k in slam.odometry_scale] if odometry else None,
        # odometry constraints added, and left out for disagreeing with the scans (odometry_gate)
        "odometry_constraints": sum(c.kind == "odometry" for c in slam.constraints),
        "odometry_rejected": int(slam.stats["odometry_rejected"]),
        "slam_nodes": len(slam.nodes),
        "slam_constraints": len(slam.constraints),
        "slam_loops": int(slam.stats["loops"]),
        "rejected_loops": int(slam.stats.get("rejected_loops", 0)),
        # loops dropped because no second loop confirmed them (GraphSlamConfig.loop_confirm_nodes)
        "unconfirmed_loops": int(slam.stats.get("unconfirmed_loops", 0)),
        # loop searches whose candidate's field was kept from an earlier search (exact)
        "loop_fields_reused": int(slam.stats.get("loop_fields_reused", 0)),
        # links of the final estimate's passes (GraphSlamConfig.relink_radius) and [s] of wall
        # time they and their optimisation took after the last scan (in wall_time_s)
        "relinks": int(slam.stats.get("relinks", 0)),
        "relink_s": float(slam.stats.get("relink_ms", 0.0) / 1e3),
        # None: no scan was tracked (every one without enough returns to match)
        "tracking_ms_median": float(np.median(track)) if len(track) else None,
        "tracking_ms_p95": float(np.percentile(track, 95)) if len(track) else None,
        "full_optimisations": len(slam.stats["full_optimisation_ms"]),
        "full_period_s": full_period,
        "full_optimisation_ms_max": float(max(slam.stats["full_optimisation_ms"], default=0.0)),
        # [s] they took, solves and merges (inline: of the wall time; in the worker: alongside)
        "full_optimisation_s": float(sum(slam.stats["full_optimisation_ms"]) / 1e3),
        # in a worker process (the scans tracked meanwhile), and [s] the scans waited for them
        "full_in_worker": cfg.full_in_worker,
        "full_wait_s": float(sum(slam.stats["full_wait_ms"]) / 1e3),
        "full_budget_ms_per_node": full_budget_ms_per_node,
        "wall_time_s": wall,
        "log_duration_s": duration,
        # None: the log's stamps do not measure time (no duration to keep up with)
        "realtime_factor": duration / wall if wall > 0 and timed else None,
    }
    if timed:  # played back at the log's pace: how far behind it falls
        lag = replay_lag(stamps, np.asarray(slam.stats["offline_step_ms"]) / 1e3)
        metrics["lag_max_s"] = float(lag.max())
        metrics["lag_p95_s"] = float(np.percentile(lag, 95))
    if reference is not None:
        t_est, p_est, t_ref, p_ref, how = _reference_pairs(clean, stamps, poses, reference)
        est_traj = trajectory_from_planar(t_est, p_est)
        ref_traj = trajectory_from_planar(t_ref, p_ref)
        aligned, matched, errors, _ = ate_errors(est_traj, ref_traj, align="se2", max_dt=0.05)
        summary = ate_summary(errors)
        metrics["ate_m"] = summary["ate_rmse_m"]
        metrics["ate_max_m"] = summary["ate_max_m"]
        metrics["ate_pairs"] = summary["ate_pairs"]
        metrics["ate_association"] = how
        # a diagnosis, not the score: the similarity that best fits the estimate to the
        # reference. ate_scale > 1: the estimate came out smaller (steps along corridors
        # under-measured, which loop closures cannot see: a uniformly shrunk loop still
        # closes); ate_sim2_m: the error left once that scale is taken out
        _, _, sim_errors, scale = ate_errors(
            est_traj, ref_traj, align="se2", with_scale=True, max_dt=0.05
        )
        metrics["ate_scale"] = scale
        metrics["ate_sim2_m"] = ate_summary(sim_errors)["ate_rmse_m"]
        # where the error lies: a person would rather look than read 400 numbers
        plot_ate(
            aligned,
            matched,
            errors,
            out / "ate.png",
            title=f"{log.name} against {Path(reference).name}",
            index_label="reference scan" if how == "scan" else "pose",
        )
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
    return metrics


def _same_file(log: Path, reference) -> bool:
    """Whether ``reference`` names the log itself (a log scored against its own poses)."""
    try:
        return reference is not None and Path(reference).resolve() == log.resolve()
    except OSError:
        return False


def _motion_prior(slam: GraphSlam, without: str | None) -> str:
    """What moved the SLAM between scans besides them, in words: ``wheel odometry (617
    constraints, 2 gated out)`` or ``scan-only (why)``."""
    if without is not None:
        return f"scan-only ({without})"
    added = sum(c.kind == "odometry" for c in slam.constraints)
    return f"wheel odometry ({added} constraints, {slam.stats['odometry_rejected']} gated out)"


def _reference_pairs(scans, stamps, poses, reference):
    """(est. stamps, est. poses, ref. stamps, ref. poses, how) to score a run against
    ``reference``. A CARMEN reference whose scans are (at least half) the run's own, by their
    ranges (:func:`associate_scans`: a corrected log against its raw log, whose stamps differ),
    pairs scan by scan (how = "scan", stamped by the reference's order); otherwise (a mission
    log, another recording) the ATE associates by time stamp (how = "time")."""
    if Path(reference).suffix == ".mcap":
        t_ref, states = read_log_states(reference)
        return stamps, poses, t_ref, states[:, :3], "time"
    ref = list(read_carmen(reference, pose="laser"))
    t_ref = np.array([rec.timestamp for rec in ref], float)
    p_ref = np.array([rec.odometry_pose for rec in ref], float).reshape(-1, 3)
    pairs = associate_scans(scans, ref)
    hit = pairs >= 0
    if hit.sum() < max(3, len(ref) / 2):
        return stamps, poses, t_ref, p_ref, "time"
    order = np.arange(hit.sum(), dtype=float)
    return order, poses[pairs[hit]], order, p_ref[hit], "scan"


def _write_map_png(path: Path, grid) -> None:
    img = np.full(grid.data.shape, 0.75)
    img[grid.data == 0] = 1.0
    img[grid.data == 100] = 0.0
    # cropped to the walls (with a 2 m margin): beams without a return clear free space out to
    # the sensor's range, far beyond a building's walls
    rows, cols = np.nonzero(grid.data == 100)
    if not len(rows):
        rows, cols = np.nonzero(grid.data != -1)
    if len(rows):
        m = int(np.ceil(2.0 / grid.resolution))
        r0, c0 = max(rows.min() - m, 0), max(cols.min() - m, 0)
        img = img[r0 : rows.max() + m + 1, c0 : cols.max() + m + 1]
    imsave(path, img[::-1], cmap="gray", vmin=0.0, vmax=1.0)
