"""The simulated station: the boat as the rest of the software sees it.

Ports (DESIGN.md): input ``thruster_command``; outputs ``thrust_measured`` and, in simulation
only, ``ground_truth_state``. The sensor ports (``lidar_scan``, ``lidar_points``, ``imu``, ``gps``)
are added by the sensors issue; the hardware station exports the same names.
"""

from pydrake.systems.framework import Diagram, DiagramBuilder

from usvdrake.scenario import Scenario
from usvdrake.systems.vessel.environment import Environment
from usvdrake.systems.vessel.thrust_mixer import ThrustMixer
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import VesselParams


def make_sim_station(scenario: Scenario, vessel: VesselParams) -> Diagram:
    """Thrust mixer → vessel plant ← environment, as one named Diagram ``station``."""
    builder = DiagramBuilder()
    mixer = builder.AddNamedSystem("thrust_mixer", ThrustMixer(vessel.thrusters))
    plant = builder.AddNamedSystem("plant", VesselPlant(vessel, scenario.initial_state))
    env = builder.AddNamedSystem(
        "environment", Environment(scenario.environment, vessel, scenario.seed)
    )
    builder.Connect(mixer.GetOutputPort("tau"), plant.GetInputPort("tau"))
    builder.Connect(env.GetOutputPort("tau_env"), plant.GetInputPort("tau_env"))
    builder.Connect(env.GetOutputPort("current"), plant.GetInputPort("current"))
    builder.Connect(plant.GetOutputPort("state"), env.GetInputPort("state"))

    builder.ExportInput(mixer.GetInputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(mixer.GetOutputPort("thrust_applied"), "thrust_measured")
    builder.ExportOutput(plant.GetOutputPort("state"), "ground_truth_state")
    station = builder.Build()
    station.set_name("station")
    return station
