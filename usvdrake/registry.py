"""Registries: how a scenario's names become components.

A scenario names its parts as strings (``controller: nmpc``, ``world: canal_demo``,
``sensors.enabled: [lidar2d, imu]``). Each kind of part has one :class:`Registry` that maps a
name to what builds it, kept in the layer that builds that kind:

=================  ==========================================  =================================
kind               registry                                    entry
=================  ==========================================  =================================
worlds             ``usvdrake.worlds.WORLDS``                  ``(seed) -> World``
sensors            ``usvdrake.diagrams.sensors.SENSORS``       ``Sensor(port, system, make)``
estimators         ``usvdrake.diagrams.ESTIMATORS``            :class:`~usvdrake.diagrams.Variant`
controllers        ``usvdrake.diagrams.CONTROLLERS``           :class:`~usvdrake.diagrams.Variant`
SLAM methods       ``usvdrake.diagrams.SLAM_METHODS``          :class:`~usvdrake.diagrams.Variant`
hardware devices   ``usvdrake.diagrams.DEVICES``               :class:`~usvdrake.diagrams.Device`
=================  ==========================================  =================================

Adding one is a module that defines it plus one ``REGISTRY.register(name, entry)`` call
(``docs/extending.md`` has a worked example of each). This module is plain Python so that every
layer can use it.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Generic, TypeVar

from usvdrake.errors import ConfigError

T = TypeVar("T")


class Registry(Generic[T]):
    """Names → entries of one kind (``kind`` names it in error messages, e.g. "controller")."""

    def __init__(self, kind: str, key: str | None = None):
        self.kind = kind
        self.key = key or kind  # the scenario key that names an entry (for error messages)
        self._entries: dict[str, T] = {}

    def register(self, name: str, entry: T, replace: bool = False) -> T:
        """Add ``entry`` under ``name``; a second registration of a name is an error unless
        ``replace`` (so two plugins cannot silently shadow each other). Returns ``entry``."""
        if not name or not name.replace("_", "").isalnum():
            raise ValueError(f"{self.kind} name {name!r}: use letters, digits and underscores")
        if name in self._entries and not replace:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Remove ``name`` (tests and notebooks that register a temporary entry)."""
        self._entries.pop(name, None)

    def get(self, name: str, file: str = "scenario", key: str | None = None) -> T:
        """The entry named ``name``; an unknown name is a one-line :class:`ConfigError` that
        lists the known ones."""
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            expected = "one of " + ", ".join(self.names())
            raise ConfigError(file, key or self.key, expected, repr(name)) from None

    def names(self) -> list[str]:
        return sorted(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}: {', '.join(self.names())})"
