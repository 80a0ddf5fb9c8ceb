"""Builders: scenario → Drake diagrams. One vessel = station (sim | hardware) + autonomy.

Importing this package registers the built-in estimators, controllers, SLAM methods and
hardware devices in the registries it exports; a new one registers itself the same way
(``docs/extending.md``).
"""

from usvdrake.diagrams import controllers, estimators, exploration, slam  # noqa: F401  (register)
from usvdrake.diagrams.devices import DEVICES, Device
from usvdrake.diagrams.scenarios import check_scenario, load_scenario, with_overrides
from usvdrake.diagrams.variants import (
    CONTROLLERS,
    ESTIMATORS,
    SLAM_METHODS,
    AutonomyParts,
    Variant,
    check_variants,
)
from usvdrake.diagrams.vessel_diagram import build_vessel_diagram

__all__ = [
    "CONTROLLERS",
    "DEVICES",
    "ESTIMATORS",
    "SLAM_METHODS",
    "AutonomyParts",
    "Device",
    "Variant",
    "build_vessel_diagram",
    "check_scenario",
    "check_variants",
    "load_scenario",
    "with_overrides",
]
