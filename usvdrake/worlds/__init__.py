"""Worlds: seeded generators by name (``make_world("amsterdam_canals", seed=0)``)."""

from collections.abc import Callable

import shapely

from usvdrake.registry import Registry
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


# A world is a seeded generator ``(seed) -> World``; a new one is registered by name
# (``WORLDS.register("harbour", harbour)``) and a scenario's ``world:`` can then name it.
WORLDS: Registry[Callable[[int], World]] = Registry("world")
for _make in (
    amsterdam_canals, canal_demo, charles_river, ntnu_basin, open_water, phu_tho_lake, valley
):  # fmt: skip
    WORLDS.register(_make.__name__, _make)


def available_worlds() -> list[str]:
    return WORLDS.names()


def make_world(name: str, seed: int = 0) -> World:
    """The world ``name`` built with ``seed``; an unknown name is a one-line ConfigError."""
    return WORLDS.get(name, "world", "world")(seed)


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
