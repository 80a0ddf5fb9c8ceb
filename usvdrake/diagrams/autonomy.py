"""The autonomy half: estimate → guidance → controller → thruster commands.

Which estimator, controller and SLAM method is the scenario's choice, looked up by name in the
registries of :mod:`usvdrake.diagrams.variants` (built-ins: :mod:`~usvdrake.diagrams.estimators`,
:mod:`~usvdrake.diagrams.controllers`, :mod:`~usvdrake.diagrams.exploration`,
:mod:`~usvdrake.diagrams.slam`).
"""

from pydrake.systems.framework import Diagram, DiagramBuilder

from usvdrake.diagrams.variants import CONTROLLERS, ESTIMATORS, AutonomyParts
from usvdrake.scenario import Scenario
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World


def make_autonomy(
    scenario: Scenario, vessel: VesselParams, world: World, meshcat=None, member: str = ""
) -> Diagram:
    """The autonomy diagram of ``scenario``. ``meshcat``: where the operator's controls go
    (exploration only); without it the operator is the scenario's command script. ``member``:
    which of the fleet's boats this is (controller ``taxi``)."""
    parts = AutonomyParts(DiagramBuilder(), scenario, vessel, world, meshcat, member)
    controller = CONTROLLERS.get(scenario.controller)
    if controller.adds_estimator:
        controller.add(parts)
    else:
        parts.estimate = ESTIMATORS.get(scenario.estimator).add(parts)
        controller.add(parts)
    parts.builder.ExportOutput(parts.estimate, "state_estimate")
    if scenario.slam.method != "none":  # an observer unless the controllers fly on it
        parts.slam()
    autonomy = parts.builder.Build()
    autonomy.set_name("autonomy")
    return autonomy
