"""Worlds: generators by name, each seeded (``make_world("canal_demo", seed=0)``)."""

from collections.abc import Callable

from usvdrake.worlds.canal import canal_demo, open_water
from usvdrake.worlds.world import Box, World, hull_clearance

WORLDS: dict[str, Callable[[int], World]] = {
    "canal_demo": canal_demo,
    "open_water": open_water,
}


def available_worlds() -> list[str]:
    return sorted(WORLDS)


def make_world(name: str, seed: int = 0) -> World:
    if name not in WORLDS:
        raise KeyError(f"unknown world {name!r}; expected one of {', '.join(available_worlds())}")
    return WORLDS[name](seed)


__all__ = ["Box", "World", "WORLDS", "available_worlds", "make_world", "hull_clearance"]
