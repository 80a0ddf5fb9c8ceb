"""One simulation loop for every runner: mission, fleet and hardware-in-the-loop.

:func:`simulate` applies the scenario's integrator settings, paces to the wall clock if asked,
stops when a ``done`` port reads > 0, the duration elapses or SIGINT/SIGTERM asks it to
(:mod:`usvdrake.run.interrupt`), shows a progress bar and measures
the wall time. :func:`make_meshcat` and :func:`write_tum` are the small output helpers the
runners share.
"""

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat, MeshcatParams
from pydrake.systems.analysis import ResetIntegratorFromFlags, Simulator, SimulatorStatus
from pydrake.systems.framework import EventStatus
from tqdm import tqdm

from usvdrake.run.interrupt import stop_reason
from usvdrake.scenario import SimulationConfig


def make_meshcat(port: int | None = None, announce: bool = True) -> Meshcat:
    """A Meshcat server bound to localhost only (never exposed on the network). ``announce``:
    let Drake print its "listening at" line (False for a Meshcat that only records the
    replay: nobody is meant to connect to it)."""
    params = MeshcatParams()
    params.host = "localhost"
    if port is not None:
        params.port = port
    drake_log = logging.getLogger("drake")
    level = drake_log.level
    if not announce:
        drake_log.setLevel(logging.WARNING)
    try:
        return Meshcat(params)
    finally:
        drake_log.setLevel(level)


@dataclass
class MissionResult:
    metrics: dict
    times: np.ndarray  # [s] log sample times
    states: np.ndarray  # (n × 6) ground truth [x y ψ u v r]
    reference: np.ndarray  # (n × 3) [ψ_d, u_d, e]
    thrust: np.ndarray  # (n × command size) applied thrust
    files: dict = field(default_factory=dict)  # name → path of what was written
    tracks: dict = field(default_factory=dict)  # fleets: boat name → (n × 6) ground truth


@dataclass
class SimulationOutcome:
    simulator: Simulator
    sim_time: float  # [s] simulated time reached
    done: bool  # the done port fired (the run did not merely time out)
    wall_time: float  # [s] wall-clock time spent advancing
    interrupted: str | None = None  # "SIGINT" / "SIGTERM": stopped early on request

    @property
    def realtime_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")


def write_tum(path: Path, times: np.ndarray, states: np.ndarray) -> None:
    """TUM trajectory of planar states [x y ψ ...]: t x y z qx qy qz qw (yaw-only quaternion)."""
    half = states[:, 2] / 2
    zeros = np.zeros_like(times)
    rows = np.column_stack(
        [times, states[:, 0], states[:, 1], zeros, zeros, zeros, np.sin(half), np.cos(half)]
    )
    np.savetxt(path, rows, fmt="%.6f", header="t x y z qx qy qz qw")


def simulate(
    diagram,
    duration: float,
    done_system=None,
    done_port: str = "mission_complete",
    reason: str = "mission complete",
    settings: SimulationConfig | None = None,
    realtime_rate: float = 0.0,
    progress: bool = False,
    step: float | None = None,
    postfix=None,
    unit: str = "sim s",
) -> SimulationOutcome:
    """Simulate ``diagram`` until ``done_system``'s output ``done_port`` (a subsystem of
    ``diagram``) reads > 0 or ``duration`` elapses.

    ``settings``: integrator, accuracy and largest step (None keeps Drake's defaults, as the
    hardware loop does: it has no continuous state of its own). The loop advances ``step``
    sim-seconds at a time (default: 1/200 of the run, at least 0.5 s) under a progress bar if
    asked; ``postfix(context)`` adds text to it.
    """
    simulator = Simulator(diagram)
    if settings is not None:
        ResetIntegratorFromFlags(simulator, settings.integrator, settings.max_step)
        simulator.get_mutable_integrator().set_target_accuracy(settings.accuracy)
    simulator.set_target_realtime_rate(realtime_rate)
    context = simulator.get_mutable_context()
    port = None if done_system is None else done_system.GetOutputPort(done_port)

    def monitor(root_context):
        if stop_reason() is not None:  # SIGINT / SIGTERM: stop at this step, outputs follow
            return EventStatus.ReachedTermination(diagram, "interrupted")
        if port is not None and port.Eval(done_system.GetMyContextFromRoot(root_context))[0] > 0:
            return EventStatus.ReachedTermination(diagram, reason)
        return EventStatus.Succeeded()

    simulator.set_monitor(monitor)
    bar = None
    if progress:
        bar = tqdm(
            total=duration,
            unit=unit,
            bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} " + unit + " [{elapsed}<{remaining}"
            "{postfix}]",
        )
    step = step or max(0.5, duration / 200.0)
    wall0 = time.perf_counter()
    t, done = 0.0, False
    try:
        simulator.Initialize()
        while t < duration - 1e-9 and stop_reason() is None:
            status = simulator.AdvanceTo(min(t + step, duration))
            new_t = context.get_time()
            if bar is not None:
                if postfix is not None:
                    bar.set_postfix_str(postfix(context))
                bar.update(new_t - t)
            t = new_t
            if status.reason() == SimulatorStatus.ReturnReason.kReachedTerminationCondition:
                done = stop_reason() is None
                break
    finally:
        if bar is not None:
            bar.close()
    return SimulationOutcome(simulator, t, done, time.perf_counter() - wall0, stop_reason())
