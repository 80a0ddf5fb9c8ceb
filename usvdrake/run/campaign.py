"""Monte Carlo campaigns: one scenario over many random days, run on Dask.

``run_campaign(load_scenario("river_tracking"), runs=200, workers=2, out_dir="out/campaign")``
randomises the scenario once per run and simulates every run in a Dask worker process.

**Determinism.** Run ``i`` draws from ``numpy.random.default_rng(SeedSequence(seed).spawn(N)[i])``
(child ``i`` of the campaign seed, the same whatever ``N``), so run ``i`` of a campaign is the
same scenario on every machine. Each run's exact scenario is written to
``DIR/runs/run_NNNN.yaml``; ``usvdrake run DIR/runs/run_0007.yaml`` reproduces run 7 bit for bit
(the worker runs the very YAML text it was given, parsed the way ``usvdrake run`` parses it).

**What is randomised** (:func:`randomise`, ranges in :class:`Ranges`):

* ``seed``: uniform in [0, 2³¹). It drives every noise stream (gusts, current variation, sensor
  noise) *and the world's random layout*: in the canal and river worlds the moored boats and
  facades move, in the natural worlds the rocks and trees. The world is therefore *not* kept
  fixed (a scenario has one seed for both); the scenario validator re-checks that the start and
  every waypoint lie in free water of that run's world, with clear straight legs between them,
  and the whole draw is redone otherwise.
* disturbances, scaling the scenario's own values (a calm scenario stays calm):
  current speed (and its variation std) × U(0.5, 1.5), wind mean speed × U(0.5, 1.5),
  gust std × U(0.5, 1.5), significant wave height × U(0.5, 1.5), each independently; current,
  wind and wave directions + U(-30°, 30°) each.
* the initial state: the position uniformly in a disc of one hull length around the scenario's
  start, the heading + U(-15°, 15°) (velocities as given); redrawn unless in free water.
* model errors: ``model_error`` = the scenario's × U(0.8, 1.2) on each of the *plant's*
  ξ = [m11 m22 m33 Xu Yv Nr] (:func:`usvdrake.diagrams.station.with_model_error`); the
  autonomy (NMPC, NMHE, PD, allocation) keeps the vessel file's nominal ξ.

**Outputs.** ``DIR/campaign.json``: per-run rows (index, scenario seed, status, error, the
draw's factors and offsets, the run's metrics dict, its wall and CPU time) and a summary (runs,
completed, failed, successes, success rate, and n / median / p5 / p95 / min / max / mean of every
numeric metric present, bools as the fraction true); ``DIR/report.html``: those statistics,
histograms, the failed and the unsuccessful runs; ``DIR/runs/run_NNNN.json``: each row as its run
completes. A run that raises is recorded as failed with its error (one line, and the
traceback); it never stops the campaign. "Success" = ``mission_complete`` and
``collision_samples == 0``; ``success_rate`` counts failed runs as unsuccessful. The metrics are
``run_mission(scenario, record=False).metrics``; :func:`is_timing_key` names those that measure
the computer (wall time, solver milliseconds) rather than the run.

**Dask.** By default a ``LocalCluster`` of ``workers`` processes with one thread each (and one
BLAS/OpenMP thread, set before the workers start), bound to localhost; ``scheduler`` connects to
an existing cluster instead, whose workers must have ``usvdrake`` installed (set
``OMP_NUM_THREADS=1`` there yourself). Only YAML text travels to the workers: pydrake objects
do not pickle, so every diagram is built inside the worker.
"""

from __future__ import annotations

import dataclasses
import html
import json
import logging
import math
import os
import re
import time
import traceback
import uuid
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import dask
import numpy as np
from dask.distributed import Client, LocalCluster, WorkerPlugin, as_completed
from matplotlib.figure import Figure
from pydrake.common.yaml import yaml_load_typed
from tqdm import tqdm

from usvdrake.diagrams import check_scenario, with_overrides
from usvdrake.jsonable import jsonable
from usvdrake.run.mission import run_mission
from usvdrake.scenario import Scenario, scenario_yaml
from usvdrake.typed_yaml import ConfigError
from usvdrake.vessel import load_vessel
from usvdrake.viz.report import png_base64

WORKER_ENV = {  # one thread per worker for every numeric library: K workers use K cores
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "VECLIB_MAXIMUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}
WALL_KEYS = ("wall_time_s", "realtime_factor")  # depend on the machine, not on the run
# Histograms and summary lead with these when present; every other numeric metric follows.
MAIN_METRICS = (
    "position_rmse_m",
    "cross_track_rmse_m",
    "path_length_m",
    "min_clearance_m",
    "mean_speed_mps",
    "final_distance_to_goal_m",
    "sim_time_s",
    "collision_samples",
    "thrust_saturated_fraction",
)
NOT_METRICS = ("seed",)


def is_timing_key(key: str) -> bool:
    """A metric that measures the computer, not the run (wall time, solver milliseconds): it
    differs between two runs of the same scenario."""
    return key in WALL_KEYS or re.search(r"(^|_)ms(_|$)", key) is not None


@dataclass(frozen=True)
class Ranges:
    """The randomisation ranges of :func:`randomise` (factors multiply the scenario's value)."""

    disturbance_scale: tuple[float, float] = (0.5, 1.5)  # current, wind, gusts, wave height
    direction_deg: float = 30.0  # ± on current, wind and wave directions
    position_hulls: float = 1.0  # start jitter: disc radius in hull lengths
    heading_deg: float = 15.0  # ± on the initial heading
    model_error: float = 0.2  # each plant ξ factor × U(1 - e, 1 + e)
    max_draws: int = 100  # redraws (start/waypoints not in free water) before giving up


RANGES = Ranges()


def _draw(base: Scenario, rng: np.random.Generator, r: Ranges, hull_length: float) -> Scenario:
    lo, hi = r.disturbance_scale
    env = base.environment
    cur, wind, waves = env.current, env.wind, env.waves
    k_current = rng.uniform(lo, hi)
    current = dataclasses.replace(
        cur,
        speed=cur.speed * k_current,
        variation_std=cur.variation_std * k_current,
        direction_deg=cur.direction_deg + rng.uniform(-r.direction_deg, r.direction_deg),
    )
    wind = dataclasses.replace(
        wind,
        mean_speed=wind.mean_speed * rng.uniform(lo, hi),
        gust_std=wind.gust_std * rng.uniform(lo, hi),
        direction_deg=wind.direction_deg + rng.uniform(-r.direction_deg, r.direction_deg),
    )
    waves = dataclasses.replace(
        waves,
        significant_height=waves.significant_height * rng.uniform(lo, hi),
        direction_deg=waves.direction_deg + rng.uniform(-r.direction_deg, r.direction_deg),
    )
    radius = r.position_hulls * hull_length * math.sqrt(rng.uniform())  # uniform over the disc
    angle = rng.uniform(-math.pi, math.pi)
    q0 = [float(v) for v in base.initial_state]
    q0[0] += radius * math.cos(angle)
    q0[1] += radius * math.sin(angle)
    q0[2] += math.radians(rng.uniform(-r.heading_deg, r.heading_deg))
    model_error = [
        float(f) * rng.uniform(1.0 - r.model_error, 1.0 + r.model_error) for f in base.model_error
    ]
    return dataclasses.replace(
        base,
        seed=int(rng.integers(0, 2**31)),
        environment=dataclasses.replace(env, current=current, wind=wind, waves=waves),
        initial_state=q0,
        model_error=model_error,
    )


def randomise(scenario: Scenario, rng: np.random.Generator, ranges: Ranges = RANGES) -> Scenario:
    """A validated random variant of ``scenario`` (see the module docstring for what varies).

    Draws until the variant passes :func:`usvdrake.scenario.check_scenario` (start and
    waypoints in free water of the variant's world); ConfigError after ``ranges.max_draws``."""
    hull_length = load_vessel(scenario.vessel).hull.length
    error = None
    for _ in range(ranges.max_draws):
        s = _draw(scenario, rng, ranges, hull_length)
        try:
            return check_scenario(s, f"{scenario.name} (randomised)")
        except ConfigError as e:
            error = e
    raise ConfigError(
        f"{scenario.name} (randomised)",
        error.key,
        f"a valid draw within {ranges.max_draws} tries",
        f"none (last: {error.got})",
    )


def draw_summary(base: Scenario, s: Scenario) -> dict:
    """How ``s`` differs from ``base``: the factors and offsets :func:`randomise` drew."""

    def ratio(a, b):
        return float(a / b) if b else None

    e, b = s.environment, base.environment
    return {
        "seed": s.seed,
        "current_factor": ratio(e.current.speed, b.current.speed),
        "current_direction_offset_deg": e.current.direction_deg - b.current.direction_deg,
        "wind_factor": ratio(e.wind.mean_speed, b.wind.mean_speed),
        "gust_factor": ratio(e.wind.gust_std, b.wind.gust_std),
        "wind_direction_offset_deg": e.wind.direction_deg - b.wind.direction_deg,
        "wave_height_factor": ratio(e.waves.significant_height, b.waves.significant_height),
        "wave_direction_offset_deg": e.waves.direction_deg - b.waves.direction_deg,
        "start_offset_m": float(
            math.hypot(
                s.initial_state[0] - base.initial_state[0],
                s.initial_state[1] - base.initial_state[1],
            )
        ),
        "heading_offset_deg": math.degrees(s.initial_state[2] - base.initial_state[2]),
        "model_error": [float(a / b) for a, b in zip(s.model_error, base.model_error, strict=True)],
    }


def scenario_from_yaml(text: str, file: str = "scenario") -> Scenario:
    """Parse and validate scenario YAML text (the same values ``load_scenario`` gives)."""
    return check_scenario(yaml_load_typed(schema=Scenario, data=text, defaults=Scenario()), file)


def run_one(index: int, text: str) -> dict:
    """The Dask task: simulate one run's scenario YAML; never raises (errors are the result)."""
    t0 = (time.perf_counter(), time.process_time())
    try:
        metrics = run_mission(scenario_from_yaml(text, f"run {index}"), record=False).metrics
        return {"status": "completed", "error": None, "metrics": metrics, **_took(t0)}
    except Exception as e:  # noqa: BLE001 — any failure is the run's result
        return _failed(e, traceback.format_exc(), **_took(t0))


def _took(t0: tuple[float, float]) -> dict:
    """The run's wall and CPU time in the worker (CPU < wall: the core was shared)."""
    return {
        "run_wall_s": time.perf_counter() - t0[0],
        "run_cpu_s": time.process_time() - t0[1],
        "worker_pid": os.getpid(),
    }


def _failed(e: BaseException, tb: str | None = None, **extra) -> dict:
    first = (str(e).strip().splitlines() or [""])[0]
    return {
        "status": "failed",
        "error": f"{type(e).__name__}: {first}".rstrip(": "),
        "traceback": tb,
        "metrics": None,
        **extra,
    }


HEARTBEAT_LOST = "Failed to communicate with scheduler during heartbeat"


def drop_closing_heartbeat(record: logging.LogRecord) -> bool:
    """A logging filter: False for a worker's heartbeat that found the scheduler gone."""
    return not record.getMessage().startswith(HEARTBEAT_LOST)


class QuietHeartbeat(WorkerPlugin):
    """Filters the worker's "Failed to communicate with scheduler during heartbeat" traceback
    out of its log: when a LocalCluster closes, a heartbeat in flight can meet the scheduler
    already gone and print it on our stderr (dask/distributed#7105, open). A scheduler lost in
    the middle of a run fails its futures, which the runners report, so nothing is hidden."""

    name = "usvdrake-quiet-heartbeat"

    def setup(self, worker) -> None:
        logger = logging.getLogger("distributed.worker")
        if drop_closing_heartbeat not in logger.filters:
            logger.addFilter(drop_closing_heartbeat)


@contextmanager
def dask_client(workers: int, scheduler: str | None):
    if scheduler:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as e:
            raise ConfigError(
                "campaign", "scheduler", "a reachable Dask scheduler address", repr(scheduler)
            ) from e
        with client:
            yield client
        return
    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **WORKER_ENV}
    # before the worker process starts, so numpy's BLAS sees it at import
    with (
        dask.config.set({"distributed.nanny.pre-spawn-environ": environ}),
        _environ_kept(environ) as restore,
        LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            env=WORKER_ENV,
        ) as cluster,
        Client(cluster) as client,
    ):
        restore()
        client.register_plugin(QuietHeartbeat())
        yield client


@contextmanager
def _environ_kept(keys):
    """Keeps this process's values of the environment variables ``keys``: a Dask nanny writes
    its pre-spawn environment into the parent's ``os.environ`` too and never undoes it, so a
    notebook that ran a campaign had NUMBA_NUM_THREADS=1 and its next numba compilation
    raised (numba refuses a thread count other than its running pool's). Yields the restoring
    function (call it once the workers are up); it runs again on exit (a restarted worker)."""
    saved = {k: os.environ.get(k) for k in keys}

    def restore() -> None:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v

    try:
        yield restore
    finally:
        restore()


def run_campaign(
    scenario: Scenario,
    runs: int,
    workers: int = 2,
    scheduler: str | None = None,
    seed: int = 0,
    out_dir: str | Path | None = None,
    duration: float | None = None,
    progress: bool = True,
    ranges: Ranges = RANGES,
) -> dict:
    """Randomise ``scenario`` ``runs`` times and simulate every run on Dask.

    Returns the campaign dict written to ``out_dir/campaign.json`` (``rows`` per run, ``summary``)
    and, when ``out_dir`` is given, writes ``out_dir/runs/run_NNNN.yaml`` (each run's scenario,
    before any run starts), ``out_dir/runs/run_NNNN.json`` (its row, as it completes) and
    ``out_dir/report.html``. ``duration`` overrides the scenario's before randomising."""
    if not (isinstance(runs, int) and runs >= 1):
        raise ConfigError("campaign", "runs", "an integer >= 1", repr(runs))
    if scheduler is None and not (isinstance(workers, int) and workers >= 1):
        raise ConfigError("campaign", "workers", "an integer >= 1", repr(workers))
    if not (isinstance(seed, int) and seed >= 0):
        raise ConfigError("campaign", "seed", "an integer >= 0", repr(seed))
    base = with_overrides(scenario, duration=duration)
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        (out / "runs").mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()

    rows: list[dict] = []
    texts: dict[int, str] = {}
    for i, child in enumerate(np.random.SeedSequence(seed).spawn(runs)):
        row = {"index": i, "seed": None, "status": "pending", "error": None, "yaml": None}
        try:
            s = randomise(base, np.random.default_rng(child), ranges)
            s = dataclasses.replace(
                s,
                name=f"{base.name}_run_{i:04d}",
                description=f"{base.description} [campaign seed {seed}, run {i}]".lstrip(),
            )
            texts[i] = scenario_yaml(s)
            row.update(seed=s.seed, draw=draw_summary(base, s))
            if out is not None:
                path = out / "runs" / f"run_{i:04d}.yaml"
                path.write_text(texts[i])
                row["yaml"] = str(path.relative_to(out))
        except Exception as e:  # noqa: BLE001 — a run that cannot be drawn is a failed run
            row.update(_failed(e, traceback.format_exc()))
        rows.append(row)

    if texts:
        with dask_client(workers, scheduler) as client:
            tag = uuid.uuid4().hex[:12]  # fresh task keys: never a cached result of another run
            futures = {
                client.submit(run_one, i, text, key=f"usvdrake-run-{i:04d}-{tag}"): i
                for i, text in texts.items()
            }
            bar = None
            if progress:
                bar = tqdm(total=runs, unit="run", desc=f"campaign {base.name}")
                bar.update(runs - len(texts))
            for future in as_completed(futures):
                i = futures[future]
                try:
                    result = future.result()
                except Exception as e:  # noqa: BLE001 — a lost worker fails this run only
                    result = _failed(e)
                rows[i].update(result)
                if out is not None:  # as it comes: an interrupted campaign keeps its runs
                    (out / "runs" / f"run_{i:04d}.json").write_text(
                        json.dumps(jsonable(rows[i]), indent=1) + "\n"
                    )
                if bar is not None:
                    bar.update(1)
                    done = [r for r in rows if r["status"] != "pending"]
                    bar.set_postfix(failed=sum(r["status"] == "failed" for r in done))
            if bar is not None:
                bar.close()
            n_workers = len(client.nthreads())
    else:
        n_workers = 0

    campaign = {
        "scenario": base.name,
        "description": base.description,
        "campaign_seed": seed,
        "duration_s": base.duration,
        "workers": n_workers,
        "scheduler": scheduler or "LocalCluster",
        "wall_time_s": time.perf_counter() - wall0,
        "ranges": dataclasses.asdict(ranges),
        "summary": summarise(rows),
        "rows": rows,
    }
    campaign = jsonable(campaign)
    if out is not None:
        (out / "campaign.json").write_text(json.dumps(campaign, indent=1) + "\n")
        write_campaign_report(out / "report.html", campaign)
    return campaign


OUTCOMES = ("success", "timed out", "collided", "failed")


def outcome(row: dict) -> str:
    """Why a run did or did not succeed: ``success``, ``failed`` (an error), ``collided`` or
    ``timed out`` (the duration ended before the mission completed)."""
    if row.get("status") != "completed":
        return "failed"
    m = row.get("metrics") or {}
    if m.get("collision_samples", 0):
        return "collided"
    if not m.get("mission_complete"):
        return "timed out"
    return "success"


def is_success(row: dict) -> bool:
    return outcome(row) == "success"


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def numeric_metrics(rows: list[dict]) -> dict[str, np.ndarray]:
    """{metric: values over the completed runs} for every numeric metric (bools and None
    skipped), the main metrics first."""
    values: dict[str, list[float]] = {}
    for row in rows:
        for key, v in (row.get("metrics") or {}).items():
            if key not in NOT_METRICS and _is_number(v):
                values.setdefault(key, []).append(float(v))
    order = [k for k in MAIN_METRICS if k in values] + sorted(set(values) - set(MAIN_METRICS))
    return {k: np.asarray(values[k]) for k in order}


def summarise(rows: list[dict]) -> dict:
    completed = [r for r in rows if r["status"] == "completed"]
    successes = sum(is_success(r) for r in rows)
    stats = {
        key: {
            "n": len(v),
            "median": float(np.median(v)),
            "p5": float(np.percentile(v, 5)),
            "p95": float(np.percentile(v, 95)),
            "min": float(v.min()),
            "max": float(v.max()),
            "mean": float(v.mean()),
        }
        for key, v in numeric_metrics(completed).items()
    }
    flags: dict[str, list[bool]] = {}
    for r in completed:
        for key, v in r["metrics"].items():
            if isinstance(v, bool):
                flags.setdefault(key, []).append(v)
    return {
        "runs": len(rows),
        "completed": len(completed),
        "failed": sum(r["status"] == "failed" for r in rows),
        "successes": successes,
        "success_rate": successes / len(rows) if rows else 0.0,
        "outcomes": {k: sum(outcome(r) == k for r in rows) for k in OUTCOMES},
        "fractions_true": {k: float(np.mean(v)) for k, v in flags.items()},
        "metrics": stats,
    }


def _histogram_png(key: str, values: np.ndarray) -> str:
    fig = Figure(figsize=(4.2, 2.8))
    ax = fig.subplots()
    bins = min(30, max(5, int(np.sqrt(len(values))) + 1))
    if np.ptp(values) == 0:
        bins = 1
    ax.hist(values, bins=bins, color="#4c72b0", edgecolor="white")
    for q, style in ((5, ":"), (50, "-"), (95, ":")):
        ax.axvline(np.percentile(values, q), color="#c44e52", ls=style, lw=1)
    ax.set_title(key, fontsize=10)
    ax.set_ylabel("runs")
    ax.tick_params(labelsize=8)
    return png_base64(fig, dpi=90)


def _fmt(v) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.4g}"
    return html.escape(str(v))


def _link(row: dict) -> str:
    if not row.get("yaml"):
        return "–"
    return f"<a href='{html.escape(row['yaml'])}'>{html.escape(row['yaml'])}</a>"


def write_campaign_report(path: str | Path, campaign: dict) -> Path:
    """``report.html``: summary, per-metric statistics and histograms (median solid, p5/p95
    dotted), failed runs with their errors, completed runs that were not successful."""
    rows, summary = campaign["rows"], campaign["summary"]
    esc = html.escape
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>usvdrake campaign {esc(campaign['scenario'])}</title>",
        "<style>body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse;"
        "font-size:90%}td,th{border:1px solid #ccc;padding:2px 8px;text-align:right}"
        "td.l{text-align:left}.grid img{margin:4px}</style></head><body>",
        f"<h1>usvdrake campaign {esc(campaign['scenario'])}</h1>",
        f"<p>{esc(campaign['description'])}</p>",
        f"<p>{summary['runs']} runs (campaign seed {campaign['campaign_seed']}, "
        f"{campaign['duration_s']:g} s each at most), {summary['completed']} completed, "
        f"{summary['failed']} failed; success (mission complete, no collision) "
        f"{summary['successes']}/{summary['runs']} = {100 * summary['success_rate']:.1f} %. "
        f"{campaign['workers']} workers, {campaign['wall_time_s']:.1f} s wall.</p>",
        "<h2>Metrics over the completed runs</h2><table><tr><th>metric</th><th>n</th>"
        "<th>median</th><th>p5</th><th>p95</th><th>min</th><th>max</th></tr>",
    ]
    for key, st in summary["metrics"].items():
        cells = "".join(f"<td>{_fmt(st[c])}</td>" for c in ("n", "median", "p5", "p95"))
        cells += f"<td>{_fmt(st['min'])}</td><td>{_fmt(st['max'])}</td>"
        parts.append(f"<tr><td class='l'>{esc(key)}</td>{cells}</tr>")
    parts.append("</table>")
    for key, frac in summary["fractions_true"].items():
        parts.append(f"<p>{esc(key)}: true in {100 * frac:.1f} % of the completed runs</p>")
    parts.append("<h2>Histograms</h2><div class='grid'>")
    completed = [r for r in rows if r["status"] == "completed"]
    for key, values in numeric_metrics(completed).items():
        parts.append(
            f"<img alt='{esc(key)}' src='data:image/png;base64,{_histogram_png(key, values)}'>"
        )
    parts.append("</div>")

    failed = [r for r in rows if r["status"] == "failed"]
    parts.append(f"<h2>Failed runs ({len(failed)})</h2>")
    if failed:
        parts.append("<table><tr><th>run</th><th>seed</th><th>scenario</th><th>error</th></tr>")
        for r in failed:
            parts.append(
                f"<tr><td>{r['index']}</td><td>{_fmt(r['seed'])}</td><td class='l'>{_link(r)}</td>"
                f"<td class='l'>{esc(r['error'] or '')}</td></tr>"
            )
        parts.append("</table>")
    unsuccessful = [r for r in completed if not is_success(r)]
    parts.append(f"<h2>Completed but unsuccessful runs ({len(unsuccessful)})</h2>")
    if unsuccessful:
        parts.append(
            "<table><tr><th>run</th><th>seed</th><th>scenario</th><th>mission complete</th>"
            "<th>collision samples</th><th>final distance to goal [m]</th></tr>"
        )
        for r in unsuccessful:
            m = r["metrics"]
            parts.append(
                f"<tr><td>{r['index']}</td><td>{_fmt(r['seed'])}</td>"
                f"<td class='l'>{_link(r)}</td>"
                f"<td>{_fmt(m.get('mission_complete'))}</td>"
                f"<td>{_fmt(m.get('collision_samples'))}</td>"
                f"<td>{_fmt(m.get('final_distance_to_goal_m'))}</td></tr>"
            )
        parts.append("</table>")
    parts.append(
        "<p>Reproduce a run: <code>usvdrake run DIR/runs/run_NNNN.yaml</code>.</p></body></html>"
    )
    path = Path(path)
    path.write_text("\n".join(parts))
    return path
