"""usvdrake: autonomous surface vessels as Drake block diagrams.

Public API::

    from usvdrake import load_vessel, load_scenario, build_vessel_diagram, run_mission

The names are imported on first use, so that ``import usvdrake`` (and ``usvdrake --help``) does
not pull in Drake, gtsam and scipy before a command needs them.
"""

import importlib

_PUBLIC = {  # name → module that defines it
    "ConfigError": "usvdrake.errors",
    "MissionResult": "usvdrake.run.simulate",
    "Scenario": "usvdrake.scenario",
    "VesselParams": "usvdrake.vessel",
    "build_vessel_diagram": "usvdrake.diagrams",
    "load_scenario": "usvdrake.diagrams",
    "load_vessel": "usvdrake.vessel",
    "make_meshcat": "usvdrake.run.simulate",
    "run_mission": "usvdrake.run.mission",
}

__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
        globals()[name] = value  # cached: the next access is a plain attribute
        return value
    raise AttributeError(f"module 'usvdrake' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
