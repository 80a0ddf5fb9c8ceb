"""The simulated station: the boat as the rest of the software sees it.

Ports (DESIGN.md): input ``thruster_command``; outputs ``thrust_measured``, the enabled sensors'
``lidar_scan`` (2D), ``lidar_points`` (3D), ``imu``, ``gps``, and, in simulation only,
``ground_truth_state``. The hardware station exports the same names.
"""

import dataclasses

import numpy as np
from pydrake.systems.framework import Diagram, DiagramBuilder

from usvdrake.diagrams.sensors import SENSORS
from usvdrake.scenario import Scenario
from usvdrake.sensors.sampled_lidar import OtherVessels
from usvdrake.sensors.thrust_sensor import ThrustSensor, thrust_noise_scale
from usvdrake.systems.vessel.environment import Environment
from usvdrake.systems.vessel.thrust_mixer import ThrustMixer
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World


def make_sim_station(scenario: Scenario, vessel: VesselParams, world: World) -> Diagram:
    """Thrust mixer → vessel plant ← environment, and the scenario's sensors, as one named
    Diagram ``station``. ``vessel`` is the nominal vessel; the plant and the wave loads use its
    ξ times ``scenario.model_error`` (the truth the autonomy's nominal model does not know)."""
    builder = DiagramBuilder()
    mixer = builder.AddNamedSystem("thrust_mixer", ThrustMixer(vessel.thrusters))
    true_vessel = with_model_error(vessel, scenario.model_error)  # the physics: plant + waves
    plant = builder.AddNamedSystem("plant", VesselPlant(true_vessel, scenario.initial_state))
    env = builder.AddNamedSystem(
        "environment", Environment(scenario.environment, true_vessel, scenario.seed)
    )
    builder.Connect(mixer.GetOutputPort("tau"), plant.GetInputPort("tau"))
    builder.Connect(env.GetOutputPort("tau_env"), plant.GetInputPort("tau_env"))
    builder.Connect(env.GetOutputPort("current"), plant.GetInputPort("current"))
    builder.Connect(plant.GetOutputPort("state"), env.GetInputPort("state"))
    state = plant.GetOutputPort("state")

    sensors = scenario.sensors
    thrust = builder.AddNamedSystem(
        "thrust_sensor",
        ThrustSensor(
            sensors.thrust, scenario.seed, thrust_noise_scale(vessel.thrusters, sensors.thrust)
        ),
    )
    builder.Connect(mixer.GetOutputPort("thrust_applied"), thrust.GetInputPort("thrust_applied"))
    builder.ExportOutput(thrust.GetOutputPort("thrust_measured"), "thrust_measured")
    others = fleet_others(scenario, vessel)
    others_exported = False
    for name in sensors.enabled:
        sensor = SENSORS.get(name)
        system = builder.AddNamedSystem(sensor.system, sensor.make(scenario, world, others))
        builder.Connect(state, system.GetInputPort("state"))
        builder.ExportOutput(system.GetOutputPort(sensor.port), sensor.port)
        if system.HasInputPort("acceleration"):  # the IMU measures the plant's acceleration
            builder.Connect(
                plant.GetOutputPort("acceleration"), system.GetInputPort("acceleration")
            )
        if others is not None and system.HasInputPort("other_vessels"):
            if others_exported:  # a second lidar sees them too
                builder.ConnectInput("other_vessels", system.GetInputPort("other_vessels"))
            else:
                builder.ExportInput(system.GetInputPort("other_vessels"), "other_vessels")
                others_exported = True

    builder.ExportInput(mixer.GetInputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(mixer.GetOutputPort("thrust_applied"), "thrust_applied")
    builder.ExportOutput(state, "ground_truth_state")
    station = builder.Build()
    station.set_name("station")
    return station


def with_model_error(vessel: VesselParams, factors) -> VesselParams:
    """``vessel`` with its ξ = [m11 m22 m33 Xu Yv Nr] multiplied by ``factors`` (a copy; the
    same object when all factors are 1)."""
    if all(f == 1.0 for f in factors):
        return vessel
    xi = vessel.hydrodynamics.as_vector() * np.asarray(factors, float)
    keys = ("m11", "m22", "m33", "Xu", "Yv", "Nr")
    hydro = dataclasses.replace(
        vessel.hydrodynamics, **dict(zip(keys, map(float, xi), strict=True))
    )
    return dataclasses.replace(vessel, hydrodynamics=hydro)


def fleet_others(scenario: Scenario, vessel: VesselParams) -> OtherVessels | None:
    """The other boats of a fleet scenario as this boat's lidar sees them (same hull; from
    its draught below the water to 1.5 m above it: deck, canopy and passengers), or None."""
    count = len(scenario.fleet.vessels) - 1 if scenario.controller == "taxi" else 0
    if count <= 0:
        return None
    hull = vessel.hull
    return OtherVessels(count, hull.length, hull.beam, -hull.draught, 1.5)
