"""The built-in estimators: where the autonomy's ``state_estimate`` comes from.

``oracle`` passes ground truth through; ``nmhe`` is Roboat II's moving-horizon estimator on the
pose sensor and the measured thrust (with the IMU's interval means when the vessel carries an
IMU); ``slam`` flies on the 3D SLAM's [x y ψ u v r] (Roboat II §V); ``observer`` is the NTNU
explorer's passive observer on the SLAM pose, added by the ``explore`` controller.
"""

from dataclasses import replace

import numpy as np

from usvdrake.diagrams.variants import ESTIMATORS, AutonomyParts, Variant, require_sensors
from usvdrake.errors import ConfigError
from usvdrake.scenario import Scenario
from usvdrake.systems.estimation.imu_interval import ImuIntervalMean
from usvdrake.systems.estimation.nmhe_system import Nmhe
from usvdrake.systems.estimation.observer_dynamics import fossen_gains
from usvdrake.systems.estimation.passive_observer import PassiveObserver


def add_oracle(parts: AutonomyParts):
    return parts.oracle().get_output_port()


def add_nmhe(parts: AutonomyParts):
    """Roboat II's NMHE on ``pose_measurement`` and ``thrust_measured`` (and ``imu``)."""
    builder, scenario = parts.builder, parts.scenario
    nmhe_cfg = scenario.nmhe
    with_imu = "imu" in scenario.sensors.enabled
    if with_imu:  # the NMHE's IMU model where the IMU sits
        nmhe_cfg = replace(nmhe_cfg, imu_lever_arm=list(scenario.sensors.imu.lever_arm))
    nmhe = builder.AddNamedSystem(
        "nmhe", Nmhe(parts.vessel, nmhe_cfg, initial_state=scenario.initial_state)
    )
    builder.ExportInput(nmhe.GetInputPort("pose_measurement"), "pose_measurement")
    builder.ExportInput(nmhe.GetInputPort("thrust_measured"), "thrust_measured")
    if with_imu:  # Roboat II's NMHE with the IMU's interval means
        imu_mean = builder.AddNamedSystem(
            "imu_interval_mean",
            ImuIntervalMean(
                1.0 / nmhe_cfg.rate_hz,
                1.0 / scenario.sensors.imu.rate_hz,
                offset=0.5 * nmhe_cfg.update_offset,
            ),
        )
        builder.ExportInput(imu_mean.GetInputPort("imu"), "imu")
        builder.Connect(imu_mean.GetOutputPort("imu_mean"), nmhe.GetInputPort("imu_mean"))
    for port in ("nmhe_failures", "nmhe_solve_ms", "estimate_time", "nmhe_diagnostics"):
        builder.ExportOutput(nmhe.GetOutputPort(port), port)
    parts.disturbance_estimate = nmhe.GetOutputPort("tau_env_estimate")
    return nmhe.GetOutputPort("state_estimate")


def check_nmhe(s: Scenario, file: str) -> None:
    require_sensors(s, file, ("pose",), "the NMHE measures it")


def add_slam_estimate(parts: AutonomyParts):
    return parts.slam().GetOutputPort("slam_state")


def check_slam_estimate(s: Scenario, file: str) -> None:
    if s.slam.method != "factor_graph" or s.controller == "explore":
        raise ConfigError(
            file,
            "estimator",
            "'slam' only with slam.method factor_graph and a waypoint controller",
            f"slam with slam.method {s.slam.method!r}, controller {s.controller!r}",
        )


def add_observer(parts: AutonomyParts):
    """The NTNU explorer's passive observer (Fossen 2011 §11.4.1) on the SLAM pose and the
    allocation's achieved force; its bias estimate is exported and feeds the PD controller."""
    cfg = parts.scenario.exploration.observer
    xi = parts.vessel.hydrodynamics
    gains = fossen_gains(xi, cfg.cutoff, T=cfg.bias_time_constant, rate_hz=cfg.rate_hz)
    pose0 = np.asarray(parts.scenario.initial_state[:3], float)
    observer = parts.builder.AddNamedSystem("passive_observer", PassiveObserver(xi, gains, pose0))
    parts.builder.Connect(
        parts.slam().GetOutputPort("slam_pose"), observer.GetInputPort("pose_measurement")
    )
    parts.builder.Connect(parts.tau_achieved, observer.GetInputPort("tau"))
    bias = observer.GetOutputPort("bias_estimate")
    parts.builder.ExportOutput(bias, "bias_estimate")
    parts.disturbance_estimate = bias
    return observer.GetOutputPort("state_estimate")


def check_observer(s: Scenario, file: str) -> None:
    if s.controller != "explore":
        raise ConfigError(
            file,
            "estimator",
            "'oracle' or 'nmhe' (the observer serves controller explore)",
            "'observer'",
        )


ESTIMATORS.register("oracle", Variant(add_oracle, "ground truth passed through"))
ESTIMATORS.register(
    "nmhe", Variant(add_nmhe, "Roboat II NMHE on pose + thrust (+ IMU)", check_nmhe)
)
ESTIMATORS.register(
    "slam", Variant(add_slam_estimate, "the 3D factor-graph SLAM's state", check_slam_estimate)
)
ESTIMATORS.register(
    "observer", Variant(add_observer, "passive observer on the SLAM pose", check_observer)
)
