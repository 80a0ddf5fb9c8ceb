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


def _placed_ship(ship: Ship, rotation: np.ndarray, offset: np.ndarray, turn: float) -> Ship:
    heading = float(np.mod(ship.heading_deg - np.degrees(turn), 360.0))
    return dataclasses.replace(ship, xy=ship.xy @ rotation.T + offset, heading_deg=heading)


def placed(situation: TrafficSituation, x0: float, y0: float, psi0: float) -> TrafficSituation:
    """The situation moved rigidly into a world frame: the own ship's start (the local origin)
    goes to (x0, y0) [m] and its initial heading to ψ0 [rad], every target keeping its place
    and course relative to the own ship. The ships' ``xy`` and ``heading_deg`` are then world
    ones; their ``lat``/``lon`` stay those of the file (geodesy does not apply to a world)."""
    turn = float(psi0 - situation.own_ship.psi0)  # counter-clockwise
    c, s = np.cos(turn), np.sin(turn)
    rotation = np.array([[c, -s], [s, c]])
    offset = np.array([x0, y0], float)
    return dataclasses.replace(
        situation,
        own_ship=_placed_ship(situation.own_ship, rotation, offset, turn),
        targets=tuple(_placed_ship(t, rotation, offset, turn) for t in situation.targets),
    )
