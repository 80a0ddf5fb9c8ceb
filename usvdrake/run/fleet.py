"""``run_fleet_mission``: simulate a fleet scenario (controller ``taxi``) until every ride is
served or the time is up, and measure the service and its safety."""

import json
from pathlib import Path

import numpy as np
import shapely
from matplotlib.figure import Figure
from pydrake.geometry import Meshcat
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from usvdrake.analysis.metrics import vessel_clearance
from usvdrake.diagrams.fleet_diagram import build_fleet_diagram
from usvdrake.run.measure import interruption
from usvdrake.run.simulate import MissionResult, make_meshcat, simulate
from usvdrake.scenario import Scenario
from usvdrake.systems.guidance.taxi_pilot import PHASES
from usvdrake.vessel import VesselParams, load_vessel
from usvdrake.viz.replay import finish_replay
from usvdrake.viz.vessel_visualizer import FLEET_COLORS
from usvdrake.worlds import make_world


def hull_polygons(states: np.ndarray, vessel: VesselParams) -> np.ndarray:
    """The hull footprints (box hulls: length × beam rectangles) at ``states`` (n × ≥3)."""
    half = np.array([vessel.hull.length, vessel.hull.beam]) / 2
    corners = np.array([[1, 1], [-1, 1], [-1, -1], [1, -1]]) * half
    c, s = np.cos(states[:, 2]), np.sin(states[:, 2])
    x = states[:, :1] + c[:, None] * corners[:, 0] - s[:, None] * corners[:, 1]
    y = states[:, 1:2] + s[:, None] * corners[:, 0] + c[:, None] * corners[:, 1]
    return shapely.polygons(np.stack([x, y], axis=-1))


def separations(tracks: dict[str, np.ndarray], vessel: VesselParams) -> dict:
    """Hull-to-hull distances [m] between every pair of boats, sample by sample (the tracks
    share their sample times). Returns {"a|b": distances}."""
    names = list(tracks)
    hulls = {n: hull_polygons(tracks[n], vessel) for n in names}
    out = {}
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            out[f"{a}|{b}"] = shapely.distance(hulls[a], hulls[b])
    return out


def run_fleet_mission(
    scenario: Scenario,
    out_dir: str | Path | None = None,
    meshcat: Meshcat | None = None,
    record: bool = True,
    progress: bool = False,
    realtime_rate: float = 0.0,
) -> MissionResult:
    """Simulate ``scenario``'s fleet; returns its metrics and each boat's track (a
    ``MissionResult``; also ``metrics.json``, ``rides.json``, ``fleet.png`` and, with a Meshcat,
    ``replay.html`` in ``out_dir``).

    Metrics: ``requests_served`` (delivered), ``mean_wait_s`` (request → boat at the pickup),
    ``mean_trip_s`` (pickup → destination), ``min_separation_m`` (closest approach of two hulls
    over the run, 10 Hz), ``collision_samples`` (hull samples touching the world) and
    ``min_clearance_m`` per boat and overall, each boat's path length, NMPC failures, replans and
    holds, and the wall time.
    """
    vessel = load_vessel(scenario.vessel)
    world = make_world(scenario.world, scenario.seed)
    if meshcat is None and record and out_dir is not None:
        meshcat = make_meshcat(announce=False)  # for the replay only
    builder = DiagramBuilder()
    fleet = builder.AddNamedSystem("fleet", build_fleet_diagram(scenario, meshcat, vessel, world))
    names = [v.name for v in scenario.fleet.vessels]
    period = 1.0 / scenario.visualization.rate_hz
    loggers = {}
    for name in names:
        for port in ("ground_truth_state", "state_estimate", "reference", "taxi_status"):
            logger = LogVectorOutput(fleet.GetOutputPort(f"{name}.{port}"), builder, period)
            logger.set_name(f"log_{name}_{port}")
            loggers[name, port] = logger
    diagram = builder.Build()
    diagram.set_name("fleet_mission")
    if meshcat is not None and record:
        meshcat.StartRecording(frames_per_second=2.0, set_visualizations_while_recording=True)
    status_port = fleet.GetOutputPort("fleet_status")
    n_requests = len(scenario.fleet.requests)

    def served(context) -> str:
        done = status_port.Eval(fleet.GetMyContextFromRoot(context))[0]
        return f"served {int(done)}/{n_requests}"

    outcome = simulate(
        diagram,
        scenario.duration,
        fleet,
        "all_served",
        "every ride served",
        settings=scenario.simulation,
        realtime_rate=realtime_rate,
        progress=progress,
        step=5.0,
        postfix=served,
    )
    t, complete, wall = outcome.sim_time, outcome.done, outcome.wall_time
    context = outcome.simulator.get_context()

    coordinator = fleet.GetSubsystemByName("coordinator")
    ledger = coordinator.dispatch(coordinator.GetMyContextFromRoot(context))
    tracks = {n: loggers[n, "ground_truth_state"].FindLog(context).data().T for n in names}
    times = loggers[names[0], "ground_truth_state"].FindLog(context).sample_times()
    metrics = {
        "scenario": scenario.name,
        "world": scenario.world,
        "vessels": names,
        "seed": scenario.seed,
        "sim_time_s": float(t),
        "wall_time_s": float(wall),
        "realtime_factor": outcome.realtime_factor,
        **interruption(outcome.interrupted),  # SIGINT / SIGTERM stopped it early
        "all_served": bool(complete),
    }
    metrics.update(ledger.metrics())
    pairs = separations(tracks, vessel)
    closest = min(pairs, key=lambda k: float(np.min(pairs[k])))
    metrics["min_separation_m"] = float(np.min(pairs[closest]))
    metrics["min_separation_pair"] = closest
    metrics["min_separation_time_s"] = float(times[int(np.argmin(pairs[closest]))])
    per_boat = {}
    for n in names:
        boat = fleet.GetSubsystemByName(n)
        boat_context = boat.GetMyContextFromRoot(context)
        clearance = vessel_clearance(world, tracks[n], vessel)
        finite = clearance[np.isfinite(clearance)]
        status = loggers[n, "taxi_status"].FindLog(context).data().T
        per_boat[n] = {
            "path_length_m": float(np.sum(np.hypot(*np.diff(tracks[n][:, :2], axis=0).T))),
            "min_clearance_m": float(finite.min()) if len(finite) else None,
            "collision_samples": int(np.sum(clearance < 0.0)),
            "nmpc_failures": int(boat.GetOutputPort("nmpc_failures").Eval(boat_context)[0]),
            "replans": int(status[-1, 5]),
            "holds": int(status[-1, 6]),
            "final_phase": PHASES[int(status[-1, 0])],
            "rides": sum(1 for r in ledger.rides if r.vessel == n and r.delivered is not None),
        }
    metrics["per_vessel"] = per_boat
    metrics["path_length_m"] = sum(b["path_length_m"] for b in per_boat.values())
    metrics["collision_samples"] = sum(b["collision_samples"] for b in per_boat.values())
    clearances = [
        b["min_clearance_m"] for b in per_boat.values() if b["min_clearance_m"] is not None
    ]
    metrics["min_clearance_m"] = min(clearances) if clearances else None
    metrics["nmpc_failures"] = sum(b["nmpc_failures"] for b in per_boat.values())

    empty = np.zeros((0, 3))
    result = MissionResult(metrics, times, np.zeros((0, 6)), empty, empty, tracks=tracks)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
        rides = [
            {
                "request": i,
                "time": r.request.time,
                "pickup": list(r.request.pickup),
                "destination": list(r.request.destination),
                "vessel": r.vessel,
                "assigned": r.assigned,
                "picked_up": r.picked_up,
                "delivered": r.delivered,
                "released": r.released,
                "stranded": r.stranded,
                "path_costs_m": r.costs,
                "free_vessel_positions": r.positions,
                "history": [list(h) for h in r.history],
            }
            for i, r in enumerate(ledger.rides)
        ]
        (out / "rides.json").write_text(json.dumps(rides, indent=2) + "\n")
        plot_fleet(out / "fleet.png", world, tracks, ledger, names, scenario.name)
        if meshcat is not None and record:
            meshcat.StopRecording()
            meshcat.PublishRecording()
            speed = {n: np.hypot(tracks[n][:, 3], tracks[n][:, 4]) for n in names}
            title = f"usvdrake run {scenario.name}"
            page = finish_replay(meshcat.StaticHtml(), times, speed, title, fleet_colors=True)
            (out / "replay.html").write_text(page)
        (out / "diagram.dot").write_text(fleet.GetGraphvizString(max_depth=1))
        result.files.update(
            {k: out / f for k, f in (("metrics", "metrics.json"), ("rides", "rides.json"))}
        )
        result.files.update(plot=out / "fleet.png", diagram=out / "diagram.dot")
        if meshcat is not None and record:
            result.files["replay"] = out / "replay.html"
    return result


def plot_fleet(path, world, tracks: dict, ledger, names: list[str], title: str) -> None:
    """The canals, each boat's track in its colour, pickups (o) and destinations (x)."""
    fig = Figure(figsize=(9, 8))
    ax = fig.subplots()
    water = world.water
    for poly in getattr(water, "geoms", [water]):
        ax.fill(*poly.exterior.xy, color="#cfe3f3", lw=0)
        for hole in poly.interiors:
            ax.fill(*hole.xy, color="white", lw=0)
    for k, n in enumerate(names):
        color = FLEET_COLORS[k % len(FLEET_COLORS)]
        ax.plot(tracks[n][:, 0], tracks[n][:, 1], color=color, lw=1.2, label=n)
        ax.plot(*tracks[n][0, :2], "s", color=color, ms=6)
    for i, r in enumerate(ledger.rides):
        ax.plot(*r.request.pickup, "o", color="green", ms=6)
        ax.plot(*r.request.destination, "x", color="red", ms=7)
        ax.annotate(str(i), r.request.pickup, fontsize=8, xytext=(3, 3), textcoords="offset points")
    served = sum(r.delivered is not None for r in ledger.rides)
    ax.set_title(f"{title}: {served}/{len(ledger.rides)} rides served (o pickup, x destination)")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.legend(loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def fleet_summary(metrics: dict, out_dir=None) -> str:
    """A few lines for the terminal."""
    m = metrics
    wait = "-" if m["mean_wait_s"] is None else f"{m['mean_wait_s']:.0f} s"
    trip = "-" if m["mean_trip_s"] is None else f"{m['mean_trip_s']:.0f} s"
    lines = [
        f"{m['scenario']}: {m['requests_served']}/{m['requests']} rides served in "
        f"{m['sim_time_s']:.0f} s ({m['realtime_factor']:.1f}x real time); mean wait {wait}, "
        f"mean trip {trip}",
        f"closest approach of two hulls {m['min_separation_m']:.2f} m "
        f"({m['min_separation_pair']} at {m['min_separation_time_s']:.0f} s); "
        f"{m['collision_samples']} samples touching the world; "
        f"{m['nmpc_failures']} NMPC failures",
    ]
    for name, b in m["per_vessel"].items():
        lines.append(
            f"  {name}: {b['rides']} rides, {b['path_length_m']:.0f} m, {b['replans']} plans, "
            f"{b['holds']} holds, min clearance {b['min_clearance_m']:.2f} m"
        )
    if out_dir is not None:
        files = ("metrics.json", "rides.json", "fleet.png", "replay.html")
        written = [f for f in files if (Path(out_dir) / f).is_file()]
        lines.append(f"written to {out_dir}: {', '.join(written)}")
    return "\n".join(lines)
