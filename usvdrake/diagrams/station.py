"""The simulated station: the boat as the rest of the software sees it.

Ports (DESIGN.md): input ``thruster_command``; outputs ``thrust_measured``, the enabled sensors'
``lidar_scan`` (2D), ``lidar_points`` (3D), ``imu``, ``gps``, and, in simulation only,
``ground_truth_state``. The hardware station exports the same names.
"""

import dataclasses

from pydrake.systems.framework import Diagram, DiagramBuilder

from usvdrake.scenario import Scenario
from usvdrake.sensors.gps import Gps
from usvdrake.sensors.imu import Imu
from usvdrake.sensors.lidar2d import Lidar2D
from usvdrake.sensors.lidar3d import Lidar3D
from usvdrake.sensors.pose_sensor import PoseSensor
from usvdrake.sensors.thrust_sensor import ThrustSensor, thrust_noise_scale
from usvdrake.systems.vessel.environment import Environment
from usvdrake.systems.vessel.thrust_mixer import ThrustMixer
from usvdrake.systems.vessel.vessel_plant import VesselPlant
from usvdrake.vessel import VesselParams
from usvdrake.worlds.world import World


def make_sim_station(scenario: Scenario, vessel: VesselParams, world: World) -> Diagram:
    """Thrust mixer → vessel plant ← environment, and the scenario's sensors, as one named
    Diagram ``station``."""
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
    if "lidar2d" in sensors.enabled:
        lidar = builder.AddNamedSystem(
            "lidar_2d", Lidar2D(sensors.lidar2d, world.scene, scenario.seed)
        )
        builder.Connect(state, lidar.GetInputPort("state"))
        builder.ExportOutput(lidar.GetOutputPort("lidar_scan"), "lidar_scan")
    if "lidar3d" in sensors.enabled:
        lidar = builder.AddNamedSystem(
            "lidar_3d", Lidar3D(sensors.lidar3d, world.scene, scenario.seed)
        )
        builder.Connect(state, lidar.GetInputPort("state"))
        builder.ExportOutput(lidar.GetOutputPort("lidar_points"), "lidar_points")
    if "imu" in sensors.enabled:
        imu = builder.AddNamedSystem("imu", Imu(sensors.imu, scenario.seed))
        builder.Connect(state, imu.GetInputPort("state"))
        builder.Connect(plant.GetOutputPort("acceleration"), imu.GetInputPort("acceleration"))
        builder.ExportOutput(imu.GetOutputPort("imu"), "imu")
    if "gps" in sensors.enabled:
        antenna = sensors.gps.antenna_height
        gps_cfg = (
            sensors.gps
            if sensors.gps.datum
            else dataclasses.replace(sensors.gps, datum=world.datum)
        )
        gps = builder.AddNamedSystem(
            "gps",
            Gps(
                gps_cfg,
                scenario.seed,
                denied=lambda x, y: bool(world.gps_denied_at(x, y)),
                sky_blocked=lambda x, y: world.sky_blocked(x, y, antenna),
            ),
        )
        builder.Connect(state, gps.GetInputPort("state"))
        builder.ExportOutput(gps.GetOutputPort("gps"), "gps")

    if "pose" in sensors.enabled:
        pose = builder.AddNamedSystem("pose_sensor", PoseSensor(sensors.pose, scenario.seed))
        builder.Connect(state, pose.GetInputPort("state"))
        builder.ExportOutput(pose.GetOutputPort("pose_measurement"), "pose_measurement")

    builder.ExportInput(mixer.GetInputPort("thruster_command"), "thruster_command")
    builder.ExportOutput(mixer.GetOutputPort("thrust_applied"), "thrust_applied")
    builder.ExportOutput(state, "ground_truth_state")
    station = builder.Build()
    station.set_name("station")
    return station
