"""Builders: scenario → Drake diagrams. One vessel = station (sim | hardware) + autonomy.

Importing this package registers the built-in estimators, controllers and SLAM methods in
the registries it exports; a new variant registers itself the same way (``docs/extending.md``).
"""

from usvdrake.diagrams import controllers, estimators, exploration, slam  # noqa: F401  (register)
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
    "ESTIMATORS",
    "SLAM_METHODS",
    "AutonomyParts",
    "Variant",
    "build_vessel_diagram",
    "check_scenario",
    "check_variants",
    "load_scenario",
    "with_overrides",
]
