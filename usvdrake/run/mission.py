"""``run_mission``: simulate a scenario's vessel diagram, record it, and measure it."""

import json
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from usvdrake.analysis.metrics import (
    control_estimation_metrics,
    exploration_metrics,
    mission_metrics,
    slam3d_metrics,
    slam_metrics,
    vessel_clearance,
)
from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.logs.mission_log import MissionLogWriter, add_mission_recorder
from usvdrake.run.fleet import run_fleet_mission
from usvdrake.run.simulate import MissionResult, make_meshcat, simulate, write_tum
from usvdrake.scenario import Scenario
from usvdrake.systems.slam.slam_summary import Slam2DSummary, Slam3DSummary
from usvdrake.vessel import load_vessel
from usvdrake.viz.report import write_report
from usvdrake.worlds import make_world


def _exploration_summary(scenario, vessel, world, finals, logs, times, states, clearance) -> dict:
    """The NTNU explorer's metrics (:func:`exploration_metrics`) on the final SLAM map, with the
    time the explorer declared the exploration finished and which map and pose it used."""
    status_log = logs["explorer_status"]
    status = status_log.data().T
    done = np.flatnonzero(status[:, 2] > 0)
    final = finals["explorer_status"]
    finished_time = None
    if len(done):
        finished_time = float(status_log.sample_times()[done[0]])
    elif final[2] > 0:  # finished after the last log sample: the run stopped right there
        finished_time = float(finals["time"])
    out = exploration_metrics(
        times,
        states,
        vessel,
        world,
        finals["slam_map"],
        scenario.exploration.explorer.resolution,
        finished_time,
        clearance,
    )
    out.update(
        map_source=f"slam:{scenario.slam.method}",
        pose_source="passive_observer(slam_pose)"
        if scenario.estimator == "observer"
        else "ground_truth (oracle)",
        planning_cycles=int(final[3]),
    )
    return out


# Ports whose values at the end of a run the metrics read (diagnostics, summaries, final maps)
FINAL_PORTS = (
    "mission_complete",
    "nmpc_diagnostics",
    "reference_track",
    "nmhe_diagnostics",
    "slam_summary",
    "slam_map",
    "explorer_status",
)


def final_values(vessel, context) -> dict:
    """The exported :data:`FINAL_PORTS` the vessel diagram has, evaluated at the run's end
    (plus ``time``): all the metrics read of the systems besides the logged signals."""
    vessel_context = vessel.GetMyContextFromRoot(context)
    finals = {"time": context.get_time()}
    for name in FINAL_PORTS:
        if name == "slam_map" and not vessel.HasOutputPort("explorer_status"):
            continue  # rendering the map costs; only the exploration's coverage reads it
        if vessel.HasOutputPort(name):
            finals[name] = vessel.GetOutputPort(name).Eval(vessel_context)
    return finals


def run_mission(
    scenario: Scenario,
    out_dir: str | Path | None = None,
    meshcat: Meshcat | None = None,
    record: bool = True,
    progress: bool = False,
    realtime_rate: float = 0.0,
) -> MissionResult:
    """Simulate ``scenario`` until its mission completes or ``scenario.duration`` elapses.

    ``meshcat``: draw into this Meshcat (live); if None and ``record`` is set, a private
    localhost Meshcat is made just for the HTML replay. ``out_dir``: write ``metrics.json``,
    ``replay.html``, ``report.html`` and ``ground_truth.tum`` there. ``realtime_rate``: 0 runs as
    fast as possible, 1.0 paces the simulation to the wall clock (for watching live).

    A fleet scenario (controller ``taxi``) runs :func:`usvdrake.run.fleet.run_fleet_mission`: its
    result has the service metrics and one track per boat (``tracks``) instead of ``states``.
    """
    if scenario.controller == "taxi":
        return run_fleet_mission(scenario, out_dir, meshcat, record, progress, realtime_rate)
    vessel = load_vessel(scenario.vessel)
    world = make_world(scenario.world, scenario.seed)
    if meshcat is None and record and out_dir is not None:
        meshcat = make_meshcat()
    builder = DiagramBuilder()
    vessel_diagram = builder.AddNamedSystem(
        "vessel", build_vessel_diagram(scenario, meshcat=meshcat, vessel=vessel, world=world)
    )
    period = 1.0 / scenario.visualization.rate_hz
    logged = ["ground_truth_state", "reference", "thrust_applied", "state_estimate"]
    logged += [
        p
        for p in (
            "pose_measurement",
            "nmhe_solve_ms",
            "estimate_time",
            "slam_pose",
            "explorer_status",
        )
        if vessel_diagram.HasOutputPort(p)
    ]
    loggers = {
        name: LogVectorOutput(vessel_diagram.GetOutputPort(name), builder, period)
        for name in logged
    }
    for name, logger in loggers.items():
        logger.set_name(f"log_{name}")
    log_writer = None
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        # written while the simulation runs (flushed every 0.5 s): a crash keeps all but ~1 s
        log_writer = MissionLogWriter(Path(out_dir) / "log.mcap")
        add_mission_recorder(builder, vessel_diagram, log_writer, scenario.visualization.rate_hz)
    diagram = builder.Build()
    diagram.set_name("mission")

    if meshcat is not None and record:
        meshcat.StartRecording(
            frames_per_second=scenario.visualization.rate_hz,
            set_visualizations_while_recording=True,
        )
    try:
        outcome = simulate(
            diagram,
            scenario.duration,
            vessel_diagram,
            settings=scenario.simulation,
            realtime_rate=realtime_rate,
            progress=progress,
        )
        t, complete, wall = outcome.sim_time, outcome.done, outcome.wall_time
        context = outcome.simulator.get_context()
    finally:  # an interrupted or failed run still leaves a finished, readable log
        if log_writer is not None:
            log_writer.close()

    if meshcat is not None:
        viz = vessel_diagram.GetSubsystemByName("vessel_visualizer")
        viz.ForcedPublish(viz.GetMyContextFromRoot(context))
        viz.finish(viz.GetMyContextFromRoot(context))

    logs = {name: lg.FindLog(context) for name, lg in loggers.items()}
    times = logs["ground_truth_state"].sample_times()
    states = logs["ground_truth_state"].data().T
    reference = logs["reference"].data().T
    thrust = logs["thrust_applied"].data().T
    finals = final_values(vessel_diagram, context)
    metrics = {
        "scenario": scenario.name,
        "vessel": scenario.vessel,
        "world": scenario.world,
        "seed": scenario.seed,
        "estimator": scenario.estimator,
        "sim_time_s": float(t),
        "wall_time_s": float(wall),
        "realtime_factor": float(t / wall) if wall > 0 else float("inf"),
        "mission_complete": bool(complete or finals["mission_complete"][0] > 0),
    }
    clearance = vessel_clearance(world, states, vessel)  # once: several metrics read it
    goals = np.asarray(scenario.mission.waypoints)
    metrics.update(
        mission_metrics(times, states, reference, thrust, vessel, world, goals, clearance)
    )

    metrics.update(
        control_estimation_metrics(
            times,
            states,
            logs["state_estimate"].data().T,
            finals,
            logs["pose_measurement"].data().T if "pose_measurement" in logs else None,
            logs["nmhe_solve_ms"].data().ravel() if "nmhe_solve_ms" in logs else None,
            logs["estimate_time"].data().ravel() if "estimate_time" in logs else None,
        )
    )
    summary = finals.get("slam_summary")
    if isinstance(summary, Slam2DSummary):
        metrics.update(slam_metrics(times, states, logs["slam_pose"].data().T, summary))
    elif isinstance(summary, Slam3DSummary):
        metrics.update(slam3d_metrics(times, states, logs["slam_pose"].data().T, summary))
    if "explorer_status" in finals:
        metrics.update(
            _exploration_summary(scenario, vessel, world, finals, logs, times, states, clearance)
        )

    result = MissionResult(metrics, times, states, reference, thrust)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        if meshcat is not None and record:
            meshcat.StopRecording()
            meshcat.PublishRecording()
            (out / "replay.html").write_text(meshcat.StaticHtml())
            result.files["replay"] = out / "replay.html"
        write_report(
            out / "report.html",
            f"usvdrake run {scenario.name}",
            metrics,
            times,
            states,
            reference,
            thrust,
            vessel,
            world,
            scenario.mission.waypoints,
        )
        write_tum(out / "ground_truth.tum", times, states)
        (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n")
        (out / "diagram.dot").write_text(vessel_diagram.GetGraphvizString(max_depth=2))
        result.files.update(
            metrics=out / "metrics.json",
            report=out / "report.html",
            trajectory=out / "ground_truth.tum",
            diagram=out / "diagram.dot",
            log=out / "log.mcap",
        )
    return result
