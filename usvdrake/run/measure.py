"""A mission's metrics from what it recorded: its signals at the visualisation rate and the
final values of its diagnostics ports. One function, :func:`measure_mission`, scores a live run
(signals from Drake's loggers) and a replayed mission log (signals and final values read back
from ``log.mcap``, :func:`metrics_from_log`) the same way.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.common.yaml import yaml_load_typed

from usvdrake.analysis.metrics import (
    control_estimation_metrics,
    exploration_metrics,
    mission_metrics,
    slam3d_metrics,
    slam_metrics,
    vessel_clearance,
)
from usvdrake.diagrams.controllers import make_reference
from usvdrake.logs.mission_log import read_mission_log
from usvdrake.logs.mission_log.recorder import RecordedPort
from usvdrake.logs.run_summary import read_run_summary
from usvdrake.scenario import Scenario
from usvdrake.systems.colav.evaluation import traffic_metrics
from usvdrake.systems.slam.slam_summary import Slam2DSummary, Slam3DSummary
from usvdrake.vessel import VesselParams, load_vessel
from usvdrake.worlds import make_world
from usvdrake.worlds.world import World

# The signals the metrics read: vessel-diagram port → mission-log topic.
SIGNALS = {
    "ground_truth_state": "/ground_truth",
    "reference": "/reference",
    "thrust_applied": "/thrust_applied",
    "state_estimate": "/state_estimate",
    "pose_measurement": "/pose_measurement",
    "nmhe_solve_ms": "/nmhe_solve_ms",
    "estimate_time": "/estimate_time",
    "slam_pose": "/slam_pose",
    "explorer_status": "/explorer_status",
    "target_states": "/target_states",  # traffic (scenario ``traffic``): [x y ψ speed] each
}
REQUIRED = ("ground_truth_state", "reference", "thrust_applied", "state_estimate")

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


@dataclass
class Signal:
    times: np.ndarray  # [s]
    values: np.ndarray  # (n × m)


def recorded_signal_ports(vessel) -> list[RecordedPort]:
    """The :data:`SIGNALS` the mission log does not record by default, as recorder ports (so
    that a replay has every signal the metrics read)."""
    extra = []
    for port in ("nmhe_solve_ms", "estimate_time", "explorer_status", "target_states"):
        if vessel.HasOutputPort(port):
            n = vessel.GetOutputPort(port).size()
            names = tuple(f"v{i}" for i in range(n))
            extra.append(RecordedPort(port, SIGNALS[port], "vector", size=n, names=names))
    return extra


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


def _exploration_summary(scenario, vessel, world, finals, signals, states, clearance) -> dict:
    """The NTNU explorer's metrics (:func:`exploration_metrics`) on the final SLAM map, with the
    time the explorer declared the exploration finished and which map and pose it used."""
    status = signals["explorer_status"]
    done = np.flatnonzero(status.values[:, 2] > 0)
    final = finals["explorer_status"]
    finished_time = None
    if len(done):
        finished_time = float(status.times[done[0]])
    elif final[2] > 0:  # finished after the last log sample: the run stopped right there
        finished_time = float(finals["time"])
    times = signals["ground_truth_state"].times
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


def measure_mission(
    scenario: Scenario,
    vessel: VesselParams,
    world: World,
    signals: dict[str, Signal],
    finals: dict,
    done: bool = False,
) -> dict:
    """Every metric of a mission but the wall clock's: ``signals`` (port → :class:`Signal`,
    :data:`SIGNALS`) and ``finals`` (:func:`final_values`); ``done``: the run ended on its done
    port (the mission completed before the duration)."""
    truth = signals["ground_truth_state"]
    times, states = truth.times, truth.values
    reference = signals["reference"].values
    thrust = signals["thrust_applied"].values
    metrics = {
        "scenario": scenario.name,
        "vessel": scenario.vessel,
        "world": scenario.world,
        "seed": scenario.seed,
        "estimator": scenario.estimator,
        "sim_time_s": float(finals["time"]),
        "mission_complete": bool(done or finals["mission_complete"][0] > 0),
    }
    clearance = vessel_clearance(world, states, vessel)  # once: several metrics read it
    goals = np.asarray(scenario.mission.waypoints)
    metrics.update(
        mission_metrics(times, states, reference, thrust, vessel, world, goals, clearance)
    )

    def values(name):
        return signals[name].values if name in signals else None

    metrics.update(
        control_estimation_metrics(
            times,
            states,
            signals["state_estimate"].values,
            finals,
            values("pose_measurement"),
            None if "nmhe_solve_ms" not in signals else values("nmhe_solve_ms").ravel(),
            None if "estimate_time" not in signals else values("estimate_time").ravel(),
        )
    )
    summary = finals.get("slam_summary")
    if isinstance(summary, Slam2DSummary):
        metrics.update(slam_metrics(times, states, values("slam_pose"), summary))
    elif isinstance(summary, Slam3DSummary):
        metrics.update(slam3d_metrics(times, states, values("slam_pose"), summary))
    if "target_states" in signals:  # traffic: how near the vessel came to the target ships
        metrics.update(traffic_metrics(times, states, signals["target_states"].values))
    if "explorer_status" in finals:
        metrics.update(
            _exploration_summary(scenario, vessel, world, finals, signals, states, clearance)
        )
    return metrics


def signals_from_log(path: str | Path) -> dict[str, Signal]:
    """The :data:`SIGNALS` a mission log holds, stamped with the times their messages carry."""
    topics = {topic: port for port, topic in SIGNALS.items()}
    rows: dict[str, tuple[list, list]] = {}
    for topic, t, message in read_mission_log(path, list(topics)):
        if not isinstance(message, dict):
            continue
        if "q" in message:  # a state message: [x y ψ u v r]
            row = message["q"]
        else:
            skip = ("t", "timestamp", "frame_id", "pose")
            row = [
                v
                for k, v in message.items()
                if k not in skip and (v is None or isinstance(v, int | float))
            ]
        row = [np.nan if v is None else v for v in row]  # null: a non-finite value
        times, values = rows.setdefault(topics[topic], ([], []))
        times.append(message.get("t", t))
        values.append(row)
    return {
        port: Signal(np.asarray(t, float), np.asarray(v, float).reshape(len(t), -1))
        for port, (t, v) in rows.items()
    }


def metrics_from_log(path: str | Path) -> dict:
    """A finished mission log's metrics, measured as the live run measured them (its scenario
    and final values are in the log: :mod:`usvdrake.logs.run_summary`)."""
    yaml_text, finals = read_run_summary(path)
    if yaml_text is None or finals is None:
        raise ValueError(f"{path}: no scenario or run summary (a log of an unfinished run?)")
    scenario = yaml_load_typed(schema=Scenario, data=yaml_text, defaults=Scenario())
    vessel = load_vessel(scenario.vessel)
    world = make_world(scenario.world, scenario.seed)
    if "nmpc_diagnostics" in finals and scenario.controller == "nmpc":
        finals["reference_track"] = make_reference(scenario, world)  # rebuilt, deterministic
    signals = signals_from_log(path)
    missing = [p for p in REQUIRED if p not in signals]
    if missing:
        raise ValueError(f"{path}: the log has no {', '.join(SIGNALS[p] for p in missing)}")
    metrics = measure_mission(scenario, vessel, world, signals, finals, finals.get("done", False))
    metrics.update(interruption(finals.get("interrupted")))
    return metrics


def interruption(signal_name: str | None) -> dict:
    """The metrics that say whether SIGINT / SIGTERM stopped the run early (and which)."""
    if signal_name is None:
        return {"interrupted": False}
    return {"interrupted": True, "interrupted_by": signal_name}
