"""Froude scaling of a traffic situation (plain numpy): DNV's ship-scale encounters for a small
own ship such as Roboat II.

With the length ratio k = L_model / L_ship, Froude similarity keeps U / √(g L) equal: lengths
scale by k, speeds by √k and times by √k, so every encounter keeps its geometry and its timing
relative to the ships' manoeuvres (the usual rule of model basins; our use of it for traffic
situations). Positions scale about the own ship's first waypoint (the local origin); the
geodetic waypoints are recomputed from the scaled local ones, so ``track.csv`` stays consistent.
"""

import dataclasses

import numpy as np

from usvdrake.systems.colav.situation import Ship, TrafficSituation


def _scaled_ship(ship: Ship, situation: TrafficSituation, k: float) -> Ship:
    xy = ship.xy * k
    lat, lon = situation.to_geodetic(xy[:, 0], xy[:, 1])
    dims = {
        key: (None if getattr(ship, key) is None else getattr(ship, key) * k)
        for key in ("length", "width", "height", "a", "b", "c", "d")
    }
    return dataclasses.replace(
        ship,
        xy=xy,
        lat=tuple(np.atleast_1d(lat).tolist()),
        lon=tuple(np.atleast_1d(lon).tolist()),
        sog_kn=tuple(s * np.sqrt(k) for s in ship.sog_kn),
        **dims,
    )


def froude_scaled(
    situation: TrafficSituation, k: float, own_length=None, own_width=None
) -> TrafficSituation:
    """The situation at length scale k (speeds × √k); the own ship's hull becomes
    ``own_length`` × ``own_width`` [m] (centred on its reference point) when given."""
    if not k > 0.0:
        raise ValueError(f"froude_scaled: k must be positive, got {k}")
    own = _scaled_ship(situation.own_ship, situation, k)
    if own_length is not None and own_width is not None:
        own = dataclasses.replace(
            own, length=float(own_length), width=float(own_width), a=None, b=None, c=None, d=None
        )
    return dataclasses.replace(
        situation,
        own_ship=own,
        targets=tuple(_scaled_ship(s, situation, k) for s in situation.targets),
        description=f"{situation.description} [Froude-scaled, k = {k:.4g}]".lstrip(),
    )
