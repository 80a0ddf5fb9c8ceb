"""The ranges a scenario's numbers must lie in (:data:`RANGES`) and the helpers that find and
check a number's rule; :func:`usvdrake.scenario.check_numbers` applies them to a scenario."""

import dataclasses
import re

import numpy as np

# The ranges of a scenario's numbers: dotted key → (low, high), both inclusive, or
# (low, high, "(]") with the low end excluded. ``a.b`` covers every item of a list field ``a.b``;
# ``x[i]`` one item; ``[*]`` any item of a list of configs; a key starting with ``*`` every key
# ending so (an exact key wins). Every number must first be finite. The caps keep a run from
# stalling the integrator or needing more than a few GB.
DAY = 86400.0
WORLD = 1.0e6  # [m] how far from the world's origin a position may be
RANGES: dict[str, tuple] = {
    "duration": (0.0, DAY, "(]"),
    "seed": (0, 2**32 - 1),
    "*rate_hz": (0.0, 1000.0, "(]"),  # every update rate
    "sensors.lidar2d.rate_hz": (0.0, 1000.0),  # 0: the preset's
    "sensors.lidar3d.rate_hz": (0.0, 1000.0),
    "simulation.max_step": (1e-4, 60.0),
    "simulation.accuracy": (1e-10, 1.0),
    "environment.update_period": (1e-3, 3600.0),
    "model_error": (0.1, 10.0),
    "initial_state[3]": (-20.0, 20.0),  # [m/s] u
    "initial_state[4]": (-20.0, 20.0),  # [m/s] v
    "initial_state[5]": (-10.0, 10.0),  # [rad/s] r
    "fleet.vessels[*].initial_state[3]": (-20.0, 20.0),
    "fleet.vessels[*].initial_state[4]": (-20.0, 20.0),
    "fleet.vessels[*].initial_state[5]": (-10.0, 10.0),
    "environment.wind.mean_speed": (0.0, 60.0),
    "environment.wind.gust_std": (0.0, 30.0),
    "environment.wind.gust_time_constant": (0.0, DAY, "(]"),
    "environment.wind.air_density": (0.0, 100.0, "(]"),
    "environment.current.speed": (0.0, 10.0),
    "environment.current.variation_std": (0.0, 5.0),
    "environment.current.variation_time_constant": (0.0, DAY, "(]"),
    "environment.waves.significant_height": (0.0, 10.0),
    "environment.waves.peak_period": (0.5, 30.0),
    "environment.waves.components": (1, 1000),
    "nmpc.horizon": (0.0, 60.0, "(]"),  # [s]; and at most NMPC_MAX_STEPS intervals of nmpc.dt
    "nmpc.dt": (0.01, 10.0),
    "nmpc.nlp_max_iterations": (1, 1000),
    "nmhe.horizon": (2, 200),  # [samples]
    "nmhe.disturbance_std": (0.0, 1e6, "(]"),
    "nmhe.accel_std": (0.0, 1e6, "(]"),
    "nmhe.gyro_std": (0.0, 1e6, "(]"),
    "nmhe.bias_std": (0.0, 1e6),  # 0: no slow force
    "nmhe.accel_bias_std": (0.0, 1e6),  # 0: bias not learnt
    "nmhe.pose_variance": (0.0, 1e12, "(]"),
    "nmhe.thrust_variance": (0.0, 1e12, "(]"),
    "nmhe.angle_variance": (0.0, 1e12, "(]"),
    "nmhe.arrival_variance": (0.0, 1e12, "(]"),
    "mission.speed": (0.0, 20.0),
    "traffic.ais_period": (0.01, 3600.0),  # [s]
    "mission.acceptance_radius": (0.0, 1e4, "(]"),
    "mission.slowdown_radius": (0.0, 1e4, "(]"),
    "control.lookahead": (0.0, 1e4, "(]"),
    "control.heading_natural_frequency": (0.0, 100.0, "(]"),
    "control.heading_damping": (0.0, 100.0, "(]"),
    "control.surge_bandwidth": (0.0, 100.0, "(]"),
    "control.sway_bandwidth": (0.0, 100.0, "(]"),
    "visualization.trail_chunk": (0.01, DAY),
    "visualization.arrow_length": (0.0, 100.0),
    "visualization.occupancy_resolution": (0.0, 100.0),  # 0: off
    "slam.hector.resolution": (0.01, 10.0),
    "slam.graph.map_resolution": (0.05, 10.0),
    "exploration.explorer.resolution": (0.01, 10.0),
    "fleet.taxi.resolution": (0.05, 100.0),
    "fleet.assignment_resolution": (0.05, 100.0),
    "fleet.coordinator_period": (1e-3, DAY),
    "hardware.stale_timeout": (0.0, 3600.0, "(]"),
    "hardware.sensor_timeout": (0.0, 3600.0, "(]"),
    "hardware.poll_period": (1e-4, 10.0),
    # where things are: within 1000 km of the world's origin (coordinates of 1e300 overflow)
    "initial_state[0]": (-WORLD, WORLD),
    "initial_state[1]": (-WORLD, WORLD),
    "initial_state[2]": (-1000.0, 1000.0),  # [rad] any heading, not an absurd number of turns
    "fleet.vessels[*].initial_state[0]": (-WORLD, WORLD),
    "fleet.vessels[*].initial_state[1]": (-WORLD, WORLD),
    "fleet.vessels[*].initial_state[2]": (-1000.0, 1000.0),
    "fleet.vessels[*].fail_at": (-DAY, DAY),
    "mission.waypoints[*]": (-WORLD, WORLD),
    "fleet.requests[*].pickup": (-WORLD, WORLD),
    "fleet.requests[*].destination": (-WORLD, WORLD),
    "fleet.requests[*].time": (0.0, DAY),
    "slam.hector.map_origin": (-WORLD, WORLD),
    "slam.graph.map_origin": (-WORLD, WORLD),
    "slam.hector.map_size": (0.0, 1e4, "(]"),  # [m]; and a bounded number of cells, below
    "slam.graph.map_size": (0.0, 1e4, "(]"),
    "*direction_deg": (-3600.0, 3600.0),
    "*azimuth_deg": (-3600.0, 3600.0),
    "*width_deg": (0.0, 360.0),
    "*mount": (-1000.0, 1000.0),  # [m, m, m, rad] a sensor on the hull
    "*lever_arm": (-1000.0, 1000.0),
    "*range_max": (0.0, 1e4),  # 0: the preset's
    "*max_range": (0.0, 1e4),
    "*_std": (0.0, 1e6),
    "*_sigma": (0.0, 1e6),
    "*fraction": (0.0, 1.0),
    "*dropout": (0.0, 1.0),
    "*inflation": (0.0, 1e3),
    "*baudrate": (1, 1e8),
}
DEFAULT_RANGE = (-1e9, 1e9)  # any other number: finite and of a size nothing here overflows on
MAX_MAP_CELLS = 1e8  # a 2D map of float64 cells: 800 MB
NMPC_MAX_STEPS = 200  # nmpc.horizon / nmpc.dt: the QP grows with the intervals


def number_leaves(obj, key: str = ""):
    """Every number of a config tree as ``(dotted key, value)``: dataclass fields, list items
    (``key[i]``) and mapping values, at any depth (bools are not numbers)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            yield from number_leaves(getattr(obj, f.name), f"{key}.{f.name}" if key else f.name)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            yield from number_leaves(v, f"{key}[{i}]")
    elif isinstance(obj, dict):
        for k, v in obj.items():
            yield from number_leaves(v, f"{key}.{k}")
    elif isinstance(obj, (int, float, np.number)) and not isinstance(obj, (bool, np.bool_)):
        yield key, obj


def range_of(key: str) -> tuple | None:
    """The :data:`RANGES` rule for a number's dotted key (``fleet.vessels[1].initial_state[3]``),
    or None."""
    inner = re.sub(r"\[\d+\](?=.)", "[*]", key)  # all indices but a last one → [*]
    candidates = [inner, re.sub(r"\[\d+\]$", "", inner)]
    for c in candidates:
        if c in RANGES:
            return RANGES[c]
    for c in candidates:
        for pattern, rule in RANGES.items():
            if pattern.startswith("*") and c.endswith(pattern[1:]):
                return rule
    return None


def in_range(value, rule: tuple) -> bool:
    low, high, *ends = rule
    above = value > low if ends == ["(]"] else value >= low
    return bool(above and value <= high)


def describe_range(rule: tuple) -> str:
    low, high, *ends = rule
    if ends == ["(]"]:
        kind = "a positive number" if low == 0 else "a number"
        return f"{kind} in ({low:g}, {high:g}]"
    return f"a number in [{low:g}, {high:g}]"
