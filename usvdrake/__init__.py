"""usvdrake: autonomous surface vessels as Drake block diagrams.

Public API::

    from usvdrake import load_vessel, load_scenario, build_vessel_diagram, run_mission
"""

from usvdrake.diagrams.vessel_diagram import build_vessel_diagram
from usvdrake.mission import MissionResult, make_meshcat, run_mission
from usvdrake.scenario import Scenario, load_scenario
from usvdrake.typed_yaml import ConfigError
from usvdrake.vessel import VesselParams, load_vessel

__all__ = [
    "ConfigError",
    "MissionResult",
    "Scenario",
    "VesselParams",
    "build_vessel_diagram",
    "load_scenario",
    "load_vessel",
    "make_meshcat",
    "run_mission",
]
