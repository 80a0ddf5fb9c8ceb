"""Mission metrics from logged signals (flat keys with units in the name)."""

import numpy as np
import shapely
from scipy import ndimage

from usvdrake.analysis.trajectory_metrics import rpe, trajectory_from_planar
from usvdrake.systems.guidance.map_processing import EIGHT, coarsen
from usvdrake.systems.slam.slam_summary import Slam2DSummary, Slam3DSummary
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World, hull_clearance


def path_length(xy: np.ndarray) -> float:
    """Length [m] of a polyline given as (n × 2)."""
    return float(np.sum(np.linalg.norm(np.diff(xy, axis=0), axis=1))) if len(xy) > 1 else 0.0


def vessel_clearance(world: World, states: np.ndarray, vessel: VesselParams) -> np.ndarray:
    """Per state, the distance [m] from the vessel's hull outline to the nearest solid."""
    hull = vessel.hull
    return hull_clearance(world, states, hull.length, hull.beam, hull.height, hull.shape)


def mission_metrics(
    times: np.ndarray,
    states: np.ndarray,
    reference: np.ndarray,
    thrust: np.ndarray,
    vessel: VesselParams,
    world: World,
    waypoints: np.ndarray,
    clearance: np.ndarray | None = None,
) -> dict:
    """Metrics of one run. ``states`` (n × 6), ``reference`` (n × 3: ψ_d, u_d, e), ``thrust``
    (n × command size), all sampled at ``times``; ``clearance`` (:func:`vessel_clearance` of
    ``states``) when the caller already has it."""
    xy = states[:, :2]
    speed = np.hypot(states[:, 3], states[:, 4])
    if clearance is None:
        clearance = vessel_clearance(world, states, vessel)
    limits = []
    for t in vessel.thrusters:
        limits += [t.max_force, np.inf] if t.azimuth else [max(t.max_force, -t.min_force)]
    saturated = np.any(np.abs(thrust) >= 0.99 * np.asarray(limits), axis=1)
    goals = np.asarray(waypoints, float).reshape(-1, 2)
    return {
        "path_length_m": path_length(xy),
        "mean_speed_mps": float(np.mean(speed)),
        "max_speed_mps": float(np.max(speed)),
        "cross_track_rmse_m": float(np.sqrt(np.mean(reference[:, 2] ** 2))),
        "cross_track_max_m": float(np.max(np.abs(reference[:, 2]))),
        # null without waypoints (exploration)
        "final_distance_to_goal_m": float(np.linalg.norm(xy[-1] - goals[-1]))
        if len(goals)
        else None,
        # null when the world has no obstacles at the waterline
        "min_clearance_m": float(np.min(clearance)) if np.isfinite(np.min(clearance)) else None,
        "collision_samples": int(np.sum(clearance < 0.0)),
        "thrust_saturated_fraction": float(np.mean(saturated)),
        "max_abs_thrust_n": float(np.max(np.abs(_forces(vessel, thrust)))) if len(thrust) else 0.0,
    }


def _forces(vessel: VesselParams, thrust: np.ndarray) -> np.ndarray:
    """The force columns of logged thruster commands (azimuth angles dropped)."""
    cols, k = [], 0
    for t in vessel.thrusters:
        cols.append(k)
        k += 2 if t.azimuth else 1
    return thrust[:, cols]


def tracking_metrics(times: np.ndarray, states: np.ndarray, reference) -> dict:
    """Position and heading RMSE [m, rad] of ground truth against a timed reference (Roboat II §VI-B
    reports 0.096 m and 0.149 rad for its NMPC on the Charles River)."""
    q_ref, _ = reference.sample(times)
    e_pos = np.hypot(states[:, 0] - q_ref[:, 0], states[:, 1] - q_ref[:, 1])
    e_psi = np.angle(np.exp(1j * (states[:, 2] - q_ref[:, 2])))
    return {
        "position_rmse_m": float(np.sqrt(np.mean(e_pos**2))),
        "position_error_max_m": float(np.max(e_pos)),
        "heading_rmse_rad": float(np.sqrt(np.mean(e_psi**2))),
        "reference_duration_s": float(reference.duration),
    }


def estimation_metrics(
    times: np.ndarray,
    states: np.ndarray,
    estimates: np.ndarray,
    pose=None,
    estimate_times: np.ndarray | None = None,
) -> dict:
    """How well the estimator knows the state (Roboat II §VI-B: NMHE velocities).
    ``estimate_times``:
    the instant each logged estimate refers to (the NMHE's ``estimate_time``); the truth is
    interpolated there (linearly: 10 Hz logs, waves at 0.5 Hz). Without it each estimate is
    compared with the truth logged with it. With ``pose`` (logged [x y ψ r] measurements) also
    the body-frame velocity from differentiating the measured positions, the baseline an
    estimator must beat. Samples from 1 s on."""
    if estimate_times is None:
        keep = times >= 1.0
        truth = states[keep]
    else:
        te = np.asarray(estimate_times, float).ravel()
        keep = (te >= 1.0) & (te <= times[-1])
        psi = np.unwrap(states[:, 2])
        truth = np.column_stack(
            [np.interp(te[keep], times, psi if i == 2 else states[:, i]) for i in range(6)]
        )
    err = estimates[keep] - truth
    out = {
        "estimate_position_rmse_m": float(np.sqrt(np.mean(err[:, 0] ** 2 + err[:, 1] ** 2))),
        "estimate_heading_rmse_rad": float(np.sqrt(np.mean(np.angle(np.exp(1j * err[:, 2])) ** 2))),
        "nmhe_velocity_rmse_u_mps": float(np.sqrt(np.mean(err[:, 3] ** 2))),
        "nmhe_velocity_rmse_v_mps": float(np.sqrt(np.mean(err[:, 4] ** 2))),
        "nmhe_yaw_rate_rmse_radps": float(np.sqrt(np.mean(err[:, 5] ** 2))),
    }
    out["nmhe_velocity_rmse_mps"] = max(
        out["nmhe_velocity_rmse_u_mps"], out["nmhe_velocity_rmse_v_mps"]
    )
    if pose is not None and len(pose) > 2:
        dt = np.diff(times)
        vw = np.diff(pose[:, :2], axis=0) / dt[:, None]
        psi = pose[1:, 2]
        u_fd = np.cos(psi) * vw[:, 0] + np.sin(psi) * vw[:, 1]
        v_fd = -np.sin(psi) * vw[:, 0] + np.cos(psi) * vw[:, 1]
        k = times[1:] >= 1.0
        out["fd_velocity_rmse_u_mps"] = float(np.sqrt(np.mean((u_fd[k] - states[1:, 3][k]) ** 2)))
        out["fd_velocity_rmse_v_mps"] = float(np.sqrt(np.mean((v_fd[k] - states[1:, 4][k]) ** 2)))
    return out


def slam_metrics(
    times: np.ndarray, states: np.ndarray, slam_poses: np.ndarray, summary: Slam2DSummary
) -> dict:
    """SLAM pose against ground truth at the logged times (the SLAM starts at the true initial
    pose, so no alignment): ATE RMSE [m] (Sturm et al. 2012, translational), heading RMSE, the
    final error, node and constraint counts (Pham et al. report 638 and 1952) and per-scan times.

    ``slam_poses`` are the vessel's (body) online poses; ``summary`` (the SLAM's
    ``slam_summary`` port, :func:`~usvdrake.systems.slam.slam_summary.summarise_2d`) carries the
    final estimate, already in the body frame, and the backend's counts and timings."""
    keep = times >= 1.0
    e = np.hypot(slam_poses[keep, 0] - states[keep, 0], slam_poses[keep, 1] - states[keep, 1])
    h = np.angle(np.exp(1j * (slam_poses[keep, 2] - states[keep, 2])))
    est = trajectory_from_planar(times[keep], slam_poses[keep])
    ref = trajectory_from_planar(times[keep], states[keep, :3])

    def rpe_or_none(delta: float):
        """RPE over ``delta`` metres of travel, None when the run is shorter than that."""
        try:
            return float(rpe(est, ref, delta, unit="meters")["rpe_trans_rmse_m"])
        except ValueError:
            return None

    track = summary.tracking_ms if len(summary.tracking_ms) else np.zeros(1)
    opt = summary.optimisation_ms if len(summary.optimisation_ms) else np.zeros(1)
    out = {}
    t_fin, p_fin = summary.final_times, summary.final_poses
    if len(t_fin):
        # the final estimate (poses re-expressed from their optimised nodes), at the logged times
        idx = np.clip(np.searchsorted(t_fin, times[keep], side="right") - 1, 0, len(t_fin) - 1)
        near = np.abs(t_fin[idx] - times[keep]) < 0.1
        ef = np.hypot(p_fin[idx, 0] - states[keep, 0], p_fin[idx, 1] - states[keep, 1])[near]
        if len(ef):
            out["ate_final_m"] = float(np.sqrt(np.mean(ef**2)))
    return out | {
        # the poses as estimated online, before later loop closures corrected them
        "ate_m": float(np.sqrt(np.mean(e**2))) if len(e) else 0.0,
        "slam_heading_rmse_rad": float(np.sqrt(np.mean(h**2))) if len(h) else 0.0,
        "slam_final_error_m": float(e[-1]) if len(e) else 0.0,
        # RPE (Sturm et al. 2012) over 1 m and 10 m of travel, translational RMSE [m]
        "rpe_m": rpe_or_none(1.0),
        "rpe_10m_m": rpe_or_none(10.0),
        "slam_nodes": summary.nodes,
        "slam_constraints": summary.constraints,
        "slam_loops": summary.loops,
        "tracking_ms_median": float(np.median(track)),
        "optimisation_ms_median": float(np.median(opt)),
        "optimisation_ms_max": float(np.max(opt)),
        "full_optimisation_ms_max": float(max(summary.full_optimisation_ms, default=0.0)),
        "slam_rejected_scans": summary.rejected_scans,
    }


# [m] open water for the speed metric: the centre at least this far from every solid, where
# Ueland 2017 eq. (2) gives a look-ahead of ≥ 1.8 m. (Its 3 m maximum needs 2.1 m all round, which
# the
# 6.45 m basin with its obstacles never offers.)
OPEN_WATER_CLEARANCE = 1.5
CONTACT_CLEARANCE = 0.1  # [m] the exploration issue counts a hull closer than this as a collision
MOVING_SPEED = 0.02  # [m/s] below this the vessel is holding position, not travelling


def explored_fraction(world: World, start_xy, final_map, resolution: float) -> dict:
    """How much of the water the vessel could reach the final map has seen.

    The reference is the ground-truth grid at ``resolution`` [m] (:meth:`World.occupancy`):
    its free cells 8-connected to the start cell are the reachable free area. A cell counts as
    explored when the map (an :class:`OccupancyGrid` in the world frame, coarsened to the same
    resolution) marks it free or occupied at that position.
    """
    truth = world.occupancy(resolution, bounds=world.water.bounds)
    free = truth.data == truth.FREE
    r0, c0 = truth.to_cell(*np.asarray(start_xy, float)[:2])
    labels, _ = ndimage.label(free, structure=EIGHT)
    reachable = labels == labels[int(r0), int(c0)]
    xs, ys = truth.cell_centres()
    gx, gy = np.meshgrid(xs, ys)
    known = np.zeros_like(reachable)
    if final_map is not None and final_map.data.size:
        grid = coarsen(final_map, resolution) if final_map.resolution < resolution else final_map
        rows, cols = grid.to_cell(gx, gy)
        inside = (rows >= 0) & (rows < grid.shape[0]) & (cols >= 0) & (cols < grid.shape[1])
        known[inside] = grid.data[rows[inside], cols[inside]] != grid.UNKNOWN
    n = int(reachable.sum())
    return {
        "reachable_free_area_m2": float(n * resolution**2),
        "explored_area_m2": float((reachable & known).sum() * resolution**2),
        "explored_fraction": float((reachable & known).sum() / n) if n else 0.0,
    }


def exploration_metrics(
    times: np.ndarray,
    states: np.ndarray,
    vessel: VesselParams,
    world: World,
    final_map,
    resolution: float,
    finished_time: float | None,
    clearance: np.ndarray | None = None,
) -> dict:
    """Ueland 2017's exploration run: coverage (:func:`explored_fraction`), safety (collisions =
    episodes with the hull within 0.1 m of a solid) and the speeds of Ueland 2017 Fig. 17: median
    speed inside the world's ``narrow_passage`` region and median speed while travelling
    (≥ 0.02 m/s) in open water, where the centre is ≥ 1.5 m from every solid
    (``OPEN_WATER_CLEARANCE``). ``clearance``: :func:`vessel_clearance` of ``states`` if known."""
    hull = vessel.hull
    if clearance is None:
        clearance = vessel_clearance(world, states, vessel)
    contact = clearance < CONTACT_CLEARANCE
    episodes = int(np.sum(contact[1:] & ~contact[:-1]) + (contact[0] if len(contact) else 0))
    speed = np.hypot(states[:, 3], states[:, 4])
    centre = world.clearance(states[:, 0], states[:, 1], hull.height)
    open_water = (centre >= OPEN_WATER_CLEARANCE) & (speed >= MOVING_SPEED)
    out = explored_fraction(world, states[0, :2], final_map, resolution)
    out.update(
        collisions=episodes,
        min_clearance_m=float(np.min(clearance)),
        speed_open_mps=float(np.median(speed[open_water])) if open_water.any() else None,
        open_water_samples=int(open_water.sum()),
        exploration_finished=finished_time is not None,
        exploration_time_s=float(finished_time) if finished_time is not None else None,
    )
    region = world.regions.get("narrow_passage")
    if region is not None:
        inside = shapely.contains_xy(region, states[:, 0], states[:, 1])
        out.update(
            speed_narrow_mps=float(np.median(speed[inside])) if inside.any() else None,
            narrow_passage_samples=int(inside.sum()),
        )
    return out


def _runs(flags: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges of the runs of True in ``flags``."""
    f = np.r_[False, np.asarray(flags, bool), False]
    d = np.diff(f.astype(int))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1), strict=True))


def truth_at(times: np.ndarray, states: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Ground truth [x y ψ] interpolated at times t (heading unwrapped first)."""
    psi = np.unwrap(states[:, 2])
    return np.column_stack(
        [
            np.interp(t, times, states[:, 0]),
            np.interp(t, times, states[:, 1]),
            np.interp(t, times, psi),
        ]
    )


def slam3d_counts(summary: Slam3DSummary) -> dict:
    """Counts and per-keyframe costs of a 3D SLAM run (no ground truth needed): keyframes,
    sweeps, keyframe and feature times [ms] (None before the first keyframe), GPS factors and
    rejections by reason, loop candidates and closures, degenerate keyframes.

    ``keyframe_ms_*`` is the per-keyframe cost of Roboat II §VI-A: feature extraction +
    registration + iSAM2 update (with the GPS factor); the loop search (match against an old
    submap and extra updates, LIO-SAM's separate 1 Hz thread) is ``loop_ms_*`` and the sum of
    both ``keyframe_with_loop_ms_*``."""
    ms, loop = summary.total_ms, summary.loop_ms

    def stat(f, values):
        return float(f(values)) if len(values) else None

    return {
        "slam_keyframes": len(summary.times),
        "slam_sweeps": summary.sweeps,
        "keyframe_ms_median": stat(np.median, ms),
        "keyframe_ms_p95": stat(lambda v: np.percentile(v, 95), ms),
        "keyframe_ms_max": stat(np.max, ms),
        "features_ms_median": stat(np.median, summary.features_ms),
        "loop_ms_median": stat(np.median, loop),
        "loop_ms_p95": stat(lambda v: np.percentile(v, 95), loop),
        "loop_ms_max": stat(np.max, loop),
        "keyframe_with_loop_ms_median": stat(np.median, ms + loop),
        "keyframe_with_loop_ms_p95": stat(lambda v: np.percentile(v, 95), ms + loop),
        "gps_factors": summary.gps_accepted,
        "gps_rejected": dict(summary.gps_rejected),
        "loop_candidates": summary.loop_candidates,
        "loop_closures": summary.loop_closures,
        "degenerate_keyframes": int(summary.degenerate.sum()),
    }


def slam3d_metrics(
    times: np.ndarray, states: np.ndarray, slam_poses: np.ndarray, summary: Slam3DSummary
) -> dict:
    """The 3D factor-graph SLAM (Roboat II §V) against ground truth.

    times, states: ground truth (n × 6); slam_poses: the online [x y ψ] output at ``times``;
    summary: the SLAM's :class:`~usvdrake.systems.slam.slam_summary.Slam3DSummary` after the run.
    The vessel moves in the plane at height 0 (the body origin on the water), so a keyframe's
    estimated z is its vertical error.

    * ``ate_m``: RMSE of the online planar position (what the controllers got), from t ≥ 1 s;
      ``ate_final_m``: RMSE of the keyframes' final estimates (after every loop and GPS factor);
    * ``loop_return_error_m``: 3D error of the final keyframe's estimated displacement from the
      first, ‖(p̂_N − p̂_0) − (p_N − p_0)‖ — for a loop that ends where it started, the distance
      between the estimated start and end (LIO-SAM's Amsterdam figure, 0.17 m); online, as it
      is when the vessel arrives;
    * ``vertical_error_final_m`` / ``vertical_error_max_m``: |z| of the last keyframe online and
      the largest |z| of all keyframes online — the vertical drift GPS altitude leaves;
    * ``keyframe_ms_median`` / ``keyframe_ms_p95``: features + registration + iSAM2 update(s)
      (incl. GPS and loop factors) per keyframe;
    * ``degenerate_segments``: runs of consecutive keyframes whose registration found a
      degenerate direction, with ``degenerate_max_error_m``, the largest online planar error in
      them; ``gps_outage_segments`` / ``gps_outage_max_error_m``: the same for runs of
      keyframes without a valid fix (bridges)."""
    keep = times >= 1.0
    e = np.hypot(slam_poses[keep, 0] - states[keep, 0], slam_poses[keep, 1] - states[keep, 1])
    out = {
        "ate_m": float(np.sqrt(np.mean(e**2))) if len(e) else 0.0,
        "slam_final_error_m": float(e[-1]) if len(e) else 0.0,
    } | slam3d_counts(summary)
    if not len(summary.times):
        return out
    kt = summary.times
    truth = truth_at(times, states, kt)
    online = summary.online
    err_online = np.hypot(online[:, 0] - truth[:, 0], online[:, 1] - truth[:, 1])
    final = summary.final
    err_final = np.hypot(final[:, 0, 3] - truth[:, 0], final[:, 1, 3] - truth[:, 1])
    p_true = np.column_stack([truth[:, :2], np.zeros(len(kt))])
    ret = (online[-1, :3] - online[0, :3]) - (p_true[-1] - p_true[0])

    def segments(flags: np.ndarray) -> tuple[int, float]:
        runs = _runs(flags)
        worst = max((float(err_online[a:b].max()) for a, b in runs), default=0.0)
        return len(runs), worst

    n_deg, deg_err = segments(summary.degenerate)
    n_out, out_err = segments(~summary.gps_valid)
    return out | {
        "ate_final_m": float(np.sqrt(np.mean(err_final**2))),
        "ate_keyframes_online_m": float(np.sqrt(np.mean(err_online**2))),
        "loop_return_error_m": float(np.linalg.norm(ret)),
        "loop_return_error_final_m": float(
            np.linalg.norm((final[-1, :3, 3] - final[0, :3, 3]) - (p_true[-1] - p_true[0]))
        ),
        "vertical_error_final_m": float(abs(online[-1, 2])),
        "vertical_error_max_m": float(np.max(np.abs(online[:, 2]))),
        "degenerate_segments": n_deg,
        "degenerate_max_error_m": deg_err,
        "gps_outage_segments": n_out,
        "gps_outage_max_error_m": out_err,
    }


def control_estimation_metrics(
    times, states, estimates, finals: dict, pose=None, nmhe_solve_ms=None, estimate_times=None
) -> dict:
    """NMPC tracking RMSE and solve statistics, NMHE estimation errors and solve times (empty
    if the vessel has neither). ``times``/``states``: ground truth samples; ``estimates``: the
    logged ``state_estimate`` at those times; ``finals``: the diagnostics ports' values at the
    end of the run (``nmpc_diagnostics`` = [solves, failures, median ms, p95 ms],
    ``reference_track``, ``nmhe_diagnostics`` = [failures, solves, last, max, total ms, events,
    screened]);
    ``pose``: the logged pose measurements; ``nmhe_solve_ms``: the logged ``nmhe_solve_ms``;
    ``estimate_times``: the logged ``estimate_time`` (the instant each estimate refers to)."""
    out = {}
    if "nmpc_diagnostics" in finals:
        solves, failures, median, p95 = finals["nmpc_diagnostics"]
        if finals.get("reference_track") is not None:
            out.update(tracking_metrics(times, states, finals["reference_track"]))
        out.update(
            nmpc_failures=int(failures),
            nmpc_solves=int(solves),
            nmpc_solve_ms_median=float(median),
            nmpc_solve_ms_p95=float(p95),
        )
    if "nmhe_diagnostics" in finals:
        out.update(estimation_metrics(times, states, estimates, pose, estimate_times))
        diag = finals["nmhe_diagnostics"]
        ms = np.zeros(0) if nmhe_solve_ms is None else np.asarray(nmhe_solve_ms)
        ms = ms[ms > 0]
        out.update(
            nmhe_failures=int(diag[0]),
            nmhe_screened_samples=int(diag[6]) if len(diag) > 6 else 0,
            nmhe_solve_ms_median=float(np.median(ms)) if len(ms) else 0.0,
            nmhe_solve_ms_max=float(diag[3]),
        )
    return out
