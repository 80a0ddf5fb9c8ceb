"""The autonomy's variants: estimators, controllers and SLAM methods, each chosen by name.

A scenario names one of each (``estimator: nmhe``, ``controller: nmpc``, ``slam.method:
graph``). Each name maps to a :class:`Variant` in its registry; the variant's ``add`` puts its
systems into the autonomy diagram being built (:class:`AutonomyParts`), its ``check`` refuses
scenarios it cannot serve with one line. The built-in variants register themselves in
:mod:`~usvdrake.diagrams.estimators`, :mod:`~usvdrake.diagrams.controllers`,
:mod:`~usvdrake.diagrams.exploration` and :mod:`~usvdrake.diagrams.slam`; a new one is a module
of the same shape plus one ``register`` call (``docs/extending.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pydrake.systems.framework import DiagramBuilder, OutputPort
from pydrake.systems.primitives import PassThrough

from usvdrake.diagrams.sensors import SENSORS
from usvdrake.errors import ConfigError
from usvdrake.registry import Registry
from usvdrake.scenario import Scenario
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World


@dataclass(frozen=True)
class Variant:
    """One way to fill a slot of the autonomy.

    ``add(parts)`` adds and wires the variant's systems. An estimator returns its
    ``state_estimate`` output port (and may set ``parts.disturbance_estimate``); a controller
    reads ``parts.estimate`` and exports ``thruster_command``, ``mission_complete`` and
    ``reference``; a SLAM method exports ``slam_pose``, ``slam_covariance`` and its map and
    returns its system. ``check(scenario, file)`` raises :class:`~usvdrake.errors.ConfigError`
    for a scenario the variant cannot serve (a missing sensor, an incompatible estimator).
    """

    add: Callable[[AutonomyParts], Any]
    description: str = ""
    check: Callable[[Scenario, str], None] | None = None
    # controllers only: the controller adds the estimator itself (the exploration's observer
    # needs the allocation's achieved force, which only the controller has)
    adds_estimator: bool = False
    # controllers only: the mission's waypoints are required
    needs_waypoints: bool = True


ESTIMATORS: Registry[Variant] = Registry("estimator")
CONTROLLERS: Registry[Variant] = Registry("controller")
SLAM_METHODS: Registry[Variant] = Registry("SLAM method", key="slam.method")


@dataclass
class AutonomyParts:
    """The autonomy diagram while it is built: what the variants add to and read from."""

    builder: DiagramBuilder
    scenario: Scenario
    vessel: VesselParams  # nominal (the autonomy never sees the plant's model error)
    world: World
    meshcat: Any = None  # where operator controls go, if a Meshcat is live
    member: str = ""  # the fleet boat this is (controller taxi)
    estimate: OutputPort | None = None  # [x y ψ u v r] the controller flies on
    disturbance_estimate: OutputPort | None = None  # [N, N, N·m] estimated environment force
    tau_achieved: OutputPort | None = None  # [N, N, N·m] the allocation's achieved force
    _added: dict = field(default_factory=dict)

    def once(self, key: str, add: Callable[[], Any]) -> Any:
        """``add()`` the first time ``key`` is asked for; the same result afterwards (two
        variants that need the oracle, or the SLAM, share one)."""
        if key not in self._added:
            self._added[key] = add()
        return self._added[key]

    def oracle(self):
        """The oracle estimator, added once: ``ground_truth_state`` passed through (the only
        place the autonomy reads ground truth)."""

        def add():
            oracle = self.builder.AddNamedSystem("oracle_estimator", PassThrough(6))
            self.builder.ExportInput(oracle.get_input_port(), "ground_truth_state")
            return oracle

        return self.once("oracle", add)

    def slam(self):
        """The scenario's SLAM system (``slam.method``), added and exported once."""
        method = self.scenario.slam.method
        return self.once("slam", lambda: SLAM_METHODS.get(method).add(self))


def require_sensors(s: Scenario, file: str, names: tuple[str, ...], why: str) -> None:
    """A variant's check that the scenario enables the sensors it reads (one line if not)."""
    if any(n not in s.sensors.enabled for n in names):
        wanted = " and ".join(names) if len(names) > 1 else f"'{names[0]}'"
        raise ConfigError(
            file, "sensors.enabled", f"{wanted} in the list ({why})", repr(s.sensors.enabled)
        )


def check_variants(s: Scenario, file: str = "scenario") -> Scenario:
    """The checks of the scenario's chosen sensors, estimator, controller and SLAM method (names
    must be registered). Returns ``s`` unchanged."""
    for i, name in enumerate(s.sensors.enabled):
        SENSORS.get(name, file, f"sensors.enabled[{i}]")
    controller = CONTROLLERS.get(s.controller, file)
    estimator = ESTIMATORS.get(s.estimator, file)
    slam = SLAM_METHODS.get(s.slam.method, file)
    for variant in (controller, estimator, slam):
        if variant.check is not None:
            variant.check(s, file)
    if controller.needs_waypoints and not s.mission.waypoints:
        raise ConfigError(file, "mission.waypoints", "at least one [x, y] waypoint", "none")
    return s
