"""The autonomy half: estimate → guidance → controller → thrust allocation.

With ``estimator: oracle`` the estimate is the station's ``ground_truth_state`` passed through
unchanged (the only place the autonomy may read ground truth); the SLAM and NMHE issues add
estimators fed by the sensor ports instead.
"""

from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import PassThrough

from usvdrake.scenario import Scenario
from usvdrake.systems.control.heading_speed_controller import HeadingSpeedController
from usvdrake.systems.guidance.los_guidance import LosGuidance
from usvdrake.systems.vessel.thrust_allocation import ThrustAllocation
from usvdrake.vessel import VesselParams


def make_autonomy(scenario: Scenario, vessel: VesselParams) -> Diagram:
    builder = DiagramBuilder()
    if scenario.estimator != "oracle":
        raise ValueError(f"estimator {scenario.estimator!r} is not available yet")
    estimator = builder.AddNamedSystem("oracle_estimator", PassThrough(6))
    builder.ExportInput(estimator.get_input_port(), "ground_truth_state")

    guidance = builder.AddNamedSystem(
        "los_guidance", LosGuidance(scenario.mission, scenario.control, vessel.cruise_speed)
    )
    controller = builder.AddNamedSystem(
        "heading_speed_controller", HeadingSpeedController(vessel.hydrodynamics, scenario.control)
    )
    allocation = builder.AddNamedSystem("thrust_allocation", ThrustAllocation(vessel))
    builder.Connect(estimator.get_output_port(), guidance.GetInputPort("state_estimate"))
    builder.Connect(estimator.get_output_port(), controller.GetInputPort("state_estimate"))
    builder.Connect(guidance.GetOutputPort("reference"), controller.GetInputPort("reference"))
    builder.Connect(controller.GetOutputPort("tau_desired"), allocation.GetInputPort("tau_desired"))

    builder.ExportOutput(allocation.GetOutputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(guidance.GetOutputPort("mission_complete"), "mission_complete")
    builder.ExportOutput(guidance.GetOutputPort("reference"), "reference")
    builder.ExportOutput(controller.GetOutputPort("tau_desired"), "tau_desired")
    builder.ExportOutput(allocation.GetOutputPort("tau_achieved"), "tau_achieved")
    builder.ExportOutput(estimator.get_output_port(), "state_estimate")
    autonomy = builder.Build()
    autonomy.set_name("autonomy")
    return autonomy
