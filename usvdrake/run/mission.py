"""``run_mission``: simulate a scenario's vessel diagram, record it, and measure it."""

import json
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.logs.mission_log import MissionLogWriter, add_mission_recorder
from usvdrake.logs.run_summary import write_run_summary, write_scenario
from usvdrake.run.fleet import run_fleet_mission
from usvdrake.run.measure import (
    SIGNALS,
    Signal,
    final_values,
    interruption,
    measure_mission,
    recorded_signal_ports,
)
from usvdrake.run.simulate import MissionResult, make_meshcat, simulate, write_tum
from usvdrake.scenario import Scenario, scenario_yaml
from usvdrake.vessel import load_vessel
from usvdrake.viz.replay import finish_replay
from usvdrake.viz.report import write_report
from usvdrake.worlds import make_world


def run_mission(
    scenario: Scenario,
    out_dir: str | Path | None = None,
    meshcat: Meshcat | None = None,
    record: bool = True,
    progress: bool = False,
    realtime_rate: float = 0.0,
    live=None,
) -> MissionResult:
    """Simulate ``scenario`` until its mission completes or ``scenario.duration`` elapses.

    ``meshcat``: draw into this Meshcat (live); if None and ``record`` is set, a private
    localhost Meshcat is made just for the HTML replay. ``out_dir``: write ``metrics.json``,
    ``replay.html``, ``report.html`` and ``ground_truth.tum`` there. ``realtime_rate``: 0 runs as
    fast as possible, 1.0 paces the simulation to the wall clock (for watching live). ``live``: a
    :class:`~usvdrake.logs.mission_log.live.FoxgloveLive` that streams the log as it is written
    (needs ``out_dir``).

    A fleet scenario (controller ``taxi``) runs :func:`usvdrake.run.fleet.run_fleet_mission`: its
    result has the service metrics and one track per boat (``tracks``) instead of ``states``.
    """
    if scenario.controller == "taxi":
        return run_fleet_mission(scenario, out_dir, meshcat, record, progress, realtime_rate)
    vessel = load_vessel(scenario.vessel)
    world = make_world(scenario.world, scenario.seed)
    if meshcat is None and record and out_dir is not None:
        meshcat = make_meshcat(announce=False)  # for the replay only
    builder = DiagramBuilder()
    vessel_diagram = builder.AddNamedSystem(
        "vessel", build_vessel_diagram(scenario, meshcat=meshcat, vessel=vessel, world=world)
    )
    period = 1.0 / scenario.visualization.rate_hz
    loggers = {}
    for name in SIGNALS:
        if vessel_diagram.HasOutputPort(name):
            loggers[name] = LogVectorOutput(vessel_diagram.GetOutputPort(name), builder, period)
            loggers[name].set_name(f"log_{name}")
    log_writer = None
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
        # written while the simulation runs (flushed every 0.5 s): a crash keeps all but ~1 s
        log_writer = MissionLogWriter(Path(out_dir) / "log.mcap", live=live)
        write_scenario(log_writer, scenario_yaml(scenario))
        add_mission_recorder(
            builder,
            vessel_diagram,
            log_writer,
            scenario.visualization.rate_hz,
            extra=recorded_signal_ports(vessel_diagram),
        )
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
        finals = final_values(vessel_diagram, context)
        if log_writer is not None:  # what a replay of the log needs to measure it again
            kept = {k: v for k, v in finals.items() if k != "reference_track"}  # rebuilt on replay
            summary = {**kept, "done": complete, "interrupted": outcome.interrupted}
            write_run_summary(log_writer, t, summary)
    finally:  # an interrupted or failed run still leaves a finished, readable log
        if log_writer is not None:
            log_writer.close()

    if meshcat is not None:
        viz = vessel_diagram.GetSubsystemByName("vessel_visualizer")
        viz.ForcedPublish(viz.GetMyContextFromRoot(context))
        viz.finish(viz.GetMyContextFromRoot(context))

    signals = {
        name: Signal(lg.FindLog(context).sample_times(), lg.FindLog(context).data().T)
        for name, lg in loggers.items()
    }
    measured = measure_mission(scenario, vessel, world, signals, finals, complete)
    metrics = {}
    for key, value in measured.items():  # the wall clock's two numbers beside the sim time
        metrics[key] = value
        if key == "sim_time_s":
            metrics["wall_time_s"] = float(wall)
            metrics["realtime_factor"] = outcome.realtime_factor
            # SIGINT / SIGTERM stopped the run early: every output is still written
            metrics.update(interruption(outcome.interrupted))
    times, states = signals["ground_truth_state"].times, signals["ground_truth_state"].values
    reference = signals["reference"].values
    thrust = signals["thrust_applied"].values
    result = MissionResult(metrics, times, states, reference, thrust)
    if out_dir is not None:
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        if meshcat is not None and record:
            meshcat.StopRecording()
            meshcat.PublishRecording()
            speed = {vessel.name: np.hypot(states[:, 3], states[:, 4])}
            page = finish_replay(
                meshcat.StaticHtml(), times, speed, f"usvdrake run {scenario.name}"
            )
            (out / "replay.html").write_text(page)
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
