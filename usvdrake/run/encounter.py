"""Traffic situations: ``run_encounter`` simulates one DNV situation's closed loop
(:func:`usvdrake.diagrams.encounter_diagram.build_encounter_diagram`), evaluates it and writes
its files; ``run_encounters`` runs a set on Dask (as :mod:`usvdrake.run.campaign` does) and
writes the set's summary.

Per situation (``DIR``): ``encounter.json`` (the evaluation: per target the encounter type, CPA,
collision and COLREG verdict with reasons; arrival and path length), ``track.csv`` (own ship:
``t_s,lat_deg,lon_deg,heading_deg,sog_kn``), ``targets.csv`` (``id,t_s,...``) and
``encounter.png`` (:func:`usvdrake.viz.encounter_plot.plot_encounter`). The tracks are the
diagram's own and target states logged at 1 Hz; nothing is read from a system's private state.
The set: ``OUT/<situation file stem>/`` each, ``OUT/summary.json``
(:func:`usvdrake.systems.colav.evaluation.summarize` plus wall time and the SB-MPC decision
times).
"""

from __future__ import annotations

import dataclasses
import time
import traceback
import uuid
from pathlib import Path

import numpy as np
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput
from tqdm import tqdm

from usvdrake.diagrams.encounter_diagram import (
    SHIP,
    EncounterConfig,
    build_encounter_diagram,
    route_time,
)
from usvdrake.errors import ConfigError
from usvdrake.run.campaign import dask_client
from usvdrake.run.simulate import make_meshcat, simulate
from usvdrake.scenario import SimulationConfig
from usvdrake.systems.colav.evaluation import (
    ColregParams,
    ShipTrack,
    evaluate_traffic_situation,
    summarize,
    write_json,
    write_situation_outputs,
)
from usvdrake.systems.colav.sbmpc import NMI, SbmpcParams
from usvdrake.systems.colav.scaling import froude_scaled
from usvdrake.systems.colav.situation import (
    CANAL_DIR,
    DATA_DIR,
    REFERENCE_LENGTH_M,
    TrafficSituation,
    load_encounter_settings,
    load_situation,
    resolve_situation,
    settings_path_for,
    situation_files,
)
from usvdrake.vessel import load_vessel
from usvdrake.viz.encounter_plot import plot_encounter
from usvdrake.viz.encounter_replay import encounter_replay_html

LOG_PERIOD_S = 1.0
STANDARD = "standard"  # the keyword for DNV's standard encounter set shipped in the package
CANAL = "canal"  # the keyword for the canal-scale set (Roboat II, trafficgen, data/canal/)
# Error-controlled RK3 as the missions use; steps up to 1 s (the autopilot's sample period).
INTEGRATION = SimulationConfig(integrator="runge_kutta3", accuracy=1e-4, max_step=1.0)


def default_duration(situation: TrafficSituation, config: EncounterConfig) -> float:
    """2.5 × the route's planned time + 10 min (× √k when Froude-scaled): room for the
    detours and for giving way by slowing down (an overtaking ship may follow at half speed for
    a long while), a stop for arrival."""
    return 2.5 * route_time(situation) + 600.0 * np.sqrt(config.length_scale)


def colreg_params(config: EncounterConfig) -> ColregParams:
    """The evaluation's thresholds at the run's scale: distances with the safety distance,
    times × √k of a Froude-scaled situation."""
    p = ColregParams().scaled(config.safety_distance_m / (0.5 * NMI))
    tk = np.sqrt(config.length_scale)
    return dataclasses.replace(
        p,
        tcpa_horizon_s=p.tcpa_horizon_s * tk,
        early_time_s=p.early_time_s * tk,
        standon_release_tcpa_s=p.standon_release_tcpa_s * tk,
    )


def prepare(situation_path, own: str = SHIP, config: EncounterConfig | None = None):
    """(situation, config) for ``own``. ``config`` is given at ship scale (DNV's 122 m own ship,
    ``REFERENCE_LENGTH_M``); a situation written for a smaller own ship (the canal set's 2 m
    Roboat II) gets it Froude-scaled to that length (safety distance 0.5 nmi × L / 122 m, the
    same 7.6 own-ship lengths). For a usvdrake vessel the situation is then Froude-scaled to the
    vessel's hull length (``scaling.froude_scaled``), the config with it."""
    situation = load_situation(situation_path)
    cfg = config or EncounterConfig()
    k0 = situation.own_ship.length / REFERENCE_LENGTH_M
    if abs(k0 - 1.0) > 1e-9:
        cfg = cfg.froude_scaled(k0)
    if own == SHIP:
        return situation, cfg
    hull = load_vessel(own).hull
    k = hull.length / situation.own_ship.length
    return froude_scaled(situation, k, hull.length, hull.beam), cfg.froude_scaled(k)


def shipped_situation(name) -> Path | None:
    """The shipped situation file of a bare name (``traffic_situation_01``,
    ``canal_situation_01``), or None."""
    if Path(str(name)).name != str(name) or Path(str(name)).exists():
        return None
    try:
        return resolve_situation(str(name))
    except ConfigError:
        return None


def situation_paths(items) -> list[Path]:
    """Situation files from files, folders (their ``*.json`` but ``encounter_settings.json``),
    the keywords ``standard`` (DNV's 40) and ``canal`` (the canal-scale set) or a shipped
    situation's name (``traffic_situation_01``, ``canal_situation_01``); none means
    ``standard``."""
    items = list(items) or [STANDARD]
    paths: list[Path] = []
    for item in items:
        p = {STANDARD: DATA_DIR, CANAL: CANAL_DIR}.get(str(item), Path(item))
        shipped = shipped_situation(item)
        if not p.exists() and shipped is not None:
            p = shipped  # a bare name: one of the shipped situations
        if p.is_dir():
            found = situation_files(p)
            if not found:
                raise ConfigError(p, "", "a folder with traffic-situation JSON files", "none")
            paths.extend(found)
        elif p.is_file():
            paths.append(p)
        else:
            raise ConfigError(
                p,
                "",
                "a situation file, a folder, 'standard', 'canal' or a shipped name",
                "no such path",
            )
    return paths


def _distinct_times(times: np.ndarray) -> np.ndarray:
    """Indices of strictly increasing times (the final forced log sample can repeat the last)."""
    keep = np.concatenate([[True], np.diff(times) > 1e-9])
    return np.flatnonzero(keep)


def _tracks(situation, own_log, target_log):
    t = own_log.sample_times()
    k = _distinct_times(t)
    q = own_log.data().T[k]
    own = ShipTrack(t[k], q[:, 0], q[:, 1], q[:, 2], np.hypot(q[:, 3], q[:, 4]))
    tt = target_log.sample_times()
    j = _distinct_times(tt)
    rows = target_log.data().T[j]
    targets = {}
    for i, ship in enumerate(situation.targets):
        x, y, psi, speed = rows[:, 4 * i : 4 * i + 4].T
        targets[ship.id] = ShipTrack(tt[j], x, y, psi, speed)
    return own, targets


def _decision_times(diag_log) -> np.ndarray:
    """decide_ms of every SB-MPC decision in the 1 Hz log (one sample per decision count)."""
    d = diag_log.data().T
    if not len(d):
        return np.zeros(0)
    count = d[:, 6]
    new = np.concatenate([[count[0] > 0], np.diff(count) > 0])
    return d[new, 5]


def run_encounter(
    situation_path,
    out_dir=None,
    config: EncounterConfig | None = None,
    duration: float | None = None,
    plot: bool = True,
    progress: bool = False,
    own: str = SHIP,
    replay: bool = False,
    sbmpc: SbmpcParams | None = None,
) -> dict:
    """Simulate one traffic situation until the own ship arrives or ``duration`` (default
    :func:`default_duration`) elapses, evaluate it, and write its files to ``out_dir`` (if
    given). ``own``: ``"ship"`` or a usvdrake vessel (the situation is then Froude-scaled to
    it, :func:`prepare`; ``config`` stays at ship scale). Returns ``evaluation`` (a
    SituationEvaluation), ``sim_time_s``, ``wall_s``, ``done`` (arrived before the time limit),
    ``decide_ms`` (every SB-MPC decision's time), ``decisions``, ``own``, ``length_scale``,
    ``safety_distance_m`` (at the run's scale) and ``files``. ``replay``: also write
    ``replay.html``, a Meshcat replay with every ship to scale (``viz.encounter_replay``).
    ``sbmpc``: SB-MPC parameters instead of the own ship's defaults (at the run's scale)."""
    situation, cfg = prepare(situation_path, own, config)
    settings = load_encounter_settings(settings_path_for(situation_path))
    name = Path(situation_path).stem
    limit = default_duration(situation, cfg) if duration is None else float(duration)
    if not limit > 0.0:
        raise ConfigError("encounter", "duration", "a positive number of seconds", limit)
    builder = DiagramBuilder()
    encounter = builder.AddNamedSystem(
        "encounter", build_encounter_diagram(situation, own, config=cfg, sbmpc=sbmpc)
    )
    logs = {
        port: LogVectorOutput(encounter.GetOutputPort(port), builder, LOG_PERIOD_S)
        for port in ("own_state", "target_states", "colav_diagnostics")
    }
    diagram = builder.Build()
    outcome = simulate(
        diagram, limit, encounter, settings=INTEGRATION, progress=progress, step=60.0
    )
    context = outcome.simulator.get_mutable_context()
    diagram.ForcedPublish(context)  # the loggers' last sample at the stop time
    own_log, target_log, diag_log = (logs[p].FindLog(context) for p in logs)
    own_track, targets = _tracks(situation, own_log, target_log)
    evaluation = evaluate_traffic_situation(
        situation, own_track, targets, settings, colreg_params(cfg), name
    )
    decide_ms = _decision_times(diag_log)
    result = {
        "situation": name,
        "evaluation": evaluation,
        "sim_time_s": outcome.sim_time,
        "wall_s": outcome.wall_time,
        "done": outcome.done,
        "interrupted": outcome.interrupted,
        "decide_ms": decide_ms.tolist(),
        "decisions": int(decide_ms.size),
        "own": own,
        "length_scale": cfg.length_scale,
        "safety_distance_m": cfg.safety_distance_m,
        "files": {},
    }
    if out_dir is not None:
        out = write_situation_outputs(out_dir, situation, own_track, targets, evaluation)
        result["files"] = {n: out / n for n in ("encounter.json", "track.csv", "targets.csv")}
        if plot:
            png = plot_encounter(
                out / "encounter.png",
                situation,
                own_track,
                targets,
                evaluation,
                cfg.safety_distance_m,
                mark_every_s=180.0 * np.sqrt(cfg.length_scale),  # 3 min at ship scale
            )
            result["files"]["encounter.png"] = png
        if replay:
            html = encounter_replay_html(
                make_meshcat(announce=False), situation, own_track, targets,
                cfg.safety_distance_m,
            )  # fmt: skip
            (out / "replay.html").write_text(html)
            result["files"]["replay.html"] = out / "replay.html"
    return result


def encounter_task(path: str, out_dir: str | None, config: EncounterConfig, own=SHIP) -> dict:
    """The Dask task: one situation; never raises (an error is the result)."""
    t0 = time.perf_counter()
    try:
        result = run_encounter(path, out_dir, config, own=own)
        return {"status": "completed", "error": None, **result}
    except Exception as e:  # noqa: BLE001 — a failing situation must not stop the set
        first = (str(e).strip().splitlines() or [""])[0]
        return {
            "status": "failed",
            "situation": Path(path).stem,
            "error": f"{type(e).__name__}: {first}".rstrip(": "),
            "traceback": traceback.format_exc(),
            "wall_s": time.perf_counter() - t0,
        }


def run_encounters(
    paths,
    out_dir,
    workers: int = 2,
    scheduler: str | None = None,
    config: EncounterConfig | None = None,
    progress: bool = True,
    own: str = SHIP,
) -> dict:
    """Every situation of ``paths`` (see :func:`situation_paths`) on Dask: ``OUT/<stem>/`` each
    and ``OUT/summary.json``. Returns the summary (``summarize`` of the completed situations,
    plus ``failed``, ``wall_s``, ``workers``, ``colav_ms_median`` and per entry its wall time)."""
    if scheduler is None and not (isinstance(workers, int) and workers >= 1):
        raise ConfigError("encounters", "workers", "an integer >= 1", repr(workers))
    files = situation_paths(paths)
    stems = [p.stem for p in files]
    if len(set(stems)) != len(stems):
        raise ConfigError("encounters", "paths", "situation files with distinct names", stems)
    cfg = config or EncounterConfig()
    if own != SHIP:
        load_vessel(own)  # a wrong name is refused here, not in every worker
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()
    try:
        results, n_workers = _run_on_dask(files, out, cfg, own, workers, scheduler, progress)
    except ConfigError as e:  # the Dask helper is the campaign's: name this command instead
        raise ConfigError("encounters", e.key, e.expected, e.got) from e
    done = [r for r in results.values() if r["status"] == "completed"]
    summary = summarize([r["evaluation"] for r in done])
    for entry, r in zip(summary["entries"], done, strict=True):
        entry.update(wall_s=r["wall_s"], sim_time_s=r["sim_time_s"], arrived_in_time=r["done"])
    decide = [ms for r in done for ms in r["decide_ms"]]
    failed = [r for r in results.values() if r["status"] != "completed"]
    summary.update(
        failed=[{"situation": r["situation"], "error": r["error"]} for r in failed],
        wall_s=time.perf_counter() - wall0,
        workers=n_workers,
        scheduler=scheduler or "LocalCluster",
        colav_ms_median=float(np.median(decide)) if decide else None,
        own=own,
        safety_distance_m=done[0]["safety_distance_m"] if done else None,
    )
    write_json(out / "summary.json", summary)
    return summary


def _run_on_dask(files, out: Path, cfg, own, workers, scheduler, progress) -> tuple[dict, int]:
    """stem → encounter_task result of every file, and the number of workers used."""
    results = {}
    with dask_client(workers, scheduler) as client:
        tag = uuid.uuid4().hex[:12]  # fresh task keys: never a cached result of another run
        futures = [
            client.submit(
                encounter_task, str(p), str(out / p.stem), cfg, own, key=f"enc-{p.stem}-{tag}"
            )
            for p in files
        ]
        bar = tqdm(total=len(files), unit="situation", disable=not progress)
        for future, path in zip(futures, files, strict=True):
            try:
                results[path.stem] = future.result()
            except Exception as e:  # noqa: BLE001 — a lost worker fails this situation only
                results[path.stem] = {"status": "failed", "situation": path.stem, "error": str(e)}
            bar.update(1)
        bar.close()
        n_workers = len(client.nthreads())
    return results, n_workers
