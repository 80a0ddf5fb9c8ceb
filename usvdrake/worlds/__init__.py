"""Worlds: seeded generators by name (``make_world("amsterdam_canals", seed=0)``)."""

from collections.abc import Callable

import shapely

from usvdrake.worlds.basin import ntnu_basin
from usvdrake.worlds.canal import amsterdam_canals, canal_demo, charles_river
from usvdrake.worlds.natural import phu_tho_lake, valley
from usvdrake.worlds.solids import Solid, box, cylinder, prism
from usvdrake.worlds.world import OccupancyGrid, World, hull_clearance


def open_water(seed: int = 0) -> World:
    """400 m × 400 m of calm water with no obstacles (identification and control tests)."""
    return World(
        name="open_water",
        seed=seed,
        water=shapely.box(-200, -200, 200, 200),
        datum="charles_river",
        description="open water, no obstacles",
    )


WORLDS: dict[str, Callable[[int], World]] = {
    "amsterdam_canals": amsterdam_canals,
    "canal_demo": canal_demo,
    "charles_river": charles_river,
    "ntnu_basin": ntnu_basin,
    "open_water": open_water,
    "phu_tho_lake": phu_tho_lake,
    "valley": valley,
}


def available_worlds() -> list[str]:
    return sorted(WORLDS)


def make_world(name: str, seed: int = 0) -> World:
    if name not in WORLDS:
        raise KeyError(f"unknown world {name!r}; expected one of {', '.join(available_worlds())}")
    return WORLDS[name](seed)


__all__ = [
    "OccupancyGrid",
    "Solid",
    "World",
    "WORLDS",
    "available_worlds",
    "box",
    "cylinder",
    "hull_clearance",
    "make_world",
    "prism",
]
