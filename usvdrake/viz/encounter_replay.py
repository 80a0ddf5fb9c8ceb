"""``encounter_replay``: a Meshcat HTML replay of a traffic encounter, every ship to scale.

Drawn after the run from the logged tracks (nothing is simulated here): the own ship and each
target as a box of its length × beam (centred between the AIS antenna's bow and stern offsets
when the situation gives them, so the box sits where the hull is), a white mark on the fore
deck, the own ship's required-CPA disc, a faint disc under each target (to find a small boat in a
wide view), the planned route, and every ship's sailed track as a
line. The animation runs ``speedup`` × faster than simulated time so that a 40 min ship-scale
encounter plays in about a minute; Meshcat's player can slow it down.
"""

import numpy as np
from pydrake.geometry import Box, Cylinder, Meshcat, Rgba
from pydrake.math import RigidTransform, RotationMatrix

from usvdrake.viz.meshcat_world import frame_view, light_scene, view_bounds
from usvdrake.viz.vessel_visualizer import FLEET_COLORS, HULL_COLOR, ROUTE_COLOR, TRAIL_COLOR

SAFETY_COLOR = Rgba(0.62, 0.0, 1.0, 0.12)  # the own ship's colour, faint: the required CPA
DECK_MARK = Rgba(1.0, 1.0, 1.0, 1.0)
MAX_FRAMES = 1200  # poses written per ship (the tracks are downsampled to at most this)
ROOT = "/encounter"


def hull_offset(length: float, a: float | None, b: float | None) -> float:
    """Where the hull's centre lies ahead of the ship's reference point [m]: half of (bow −
    stern) antenna offsets, 0 when the situation does not give them."""
    if a is None or b is None:
        return 0.0
    return 0.5 * (float(a) - float(b)) * length / max(float(a) + float(b), 1e-9)


def _add_ship(meshcat: Meshcat, path: str, ship, color: Rgba, marker: float = 0.0) -> None:
    length, width = float(ship.length), float(ship.width)
    height = max(0.08 * length, 0.2 * width)
    x = hull_offset(length, ship.a, ship.b)
    meshcat.SetObject(f"{path}/hull", Box(length, width, height), color)
    meshcat.SetTransform(f"{path}/hull", RigidTransform([x, 0.0, height / 2]))
    meshcat.SetObject(f"{path}/bow_mark", Box(0.15 * length, 0.4 * width, 0.02 * height), DECK_MARK)
    meshcat.SetTransform(f"{path}/bow_mark", RigidTransform([x + 0.35 * length, 0.0, height]))
    if marker > 0.0:  # a faint disc: a 2 m boat is a dot in a 300 m view
        halo = Rgba(color.r(), color.g(), color.b(), 0.25)
        meshcat.SetObject(f"{path}/marker", Cylinder(marker, 0.01), halo)


def _line(meshcat: Meshcat, path: str, xy, color: Rgba, width: float, z: float) -> None:
    xy = np.asarray(xy, float).reshape(-1, 2)
    if len(xy) > 1:
        meshcat.SetLine(path, np.vstack([xy.T, np.full(len(xy), z)]), width, color)


def _poses(meshcat: Meshcat, path: str, track, frames: np.ndarray, speedup: float) -> None:
    for k in frames:
        pose = RigidTransform(
            RotationMatrix.MakeZRotation(float(track.psi[k])), [track.x[k], track.y[k], 0.0]
        )
        meshcat.SetTransform(path, pose, float(track.t[k]) / speedup)


def encounter_replay_html(
    meshcat: Meshcat,
    situation,
    own_track,
    target_tracks: dict,
    safety_distance_m: float,
    play_seconds: float = 60.0,
    frames_per_second: float = 20.0,
) -> str:
    """Draw the encounter into ``meshcat`` as a recording and return its static HTML page.

    ``situation``: a ``TrafficSituation`` (its own ship and targets give the dimensions and the
    planned route); ``own_track`` and ``target_tracks`` (target id → track): objects with
    arrays ``t, x, y, psi`` (``evaluation.ShipTrack``) in the situation's local frame."""
    t_end = float(own_track.t[-1]) if len(own_track.t) else 0.0
    speedup = max(t_end / play_seconds, 1.0)
    meshcat.Delete(ROOT)
    meshcat.StartRecording(frames_per_second, set_visualizations_while_recording=False)
    light_scene(meshcat)
    meshcat.SetProperty("/Grid", "visible", False)  # a 10 m grid means nothing at sea
    points = [own_track.xy, situation.own_ship.xy] + [tr.xy for tr in target_tracks.values()]
    bounds = view_bounds(np.vstack(points))
    frame_view(meshcat, bounds)
    marker = 0.015 * max(bounds[2] - bounds[0], bounds[3] - bounds[1])
    _line(meshcat, f"{ROOT}/route", situation.own_ship.xy, ROUTE_COLOR, 2.0, 0.02)
    _line(meshcat, f"{ROOT}/own/track", own_track.xy, TRAIL_COLOR, 3.0, 0.04)
    own = f"{ROOT}/own/ship"
    _add_ship(meshcat, own, situation.own_ship, HULL_COLOR)
    meshcat.SetObject(f"{own}/safety", Cylinder(safety_distance_m, 0.01), SAFETY_COLOR)
    frames = np.unique(np.linspace(0, len(own_track.t) - 1, MAX_FRAMES).astype(int))
    _poses(meshcat, own, own_track, frames, speedup)
    for i, ship in enumerate(situation.targets):
        track = target_tracks.get(ship.id)
        if track is None:
            continue
        c = FLEET_COLORS[i % len(FLEET_COLORS)]
        color = Rgba(*c, 1.0)
        path = f"{ROOT}/targets/{ship.id}"
        _line(meshcat, f"{path}/track", track.xy, Rgba(*c, 0.9), 2.0, 0.03)
        _add_ship(meshcat, f"{path}/ship", ship, color, max(marker, ship.length))
        k = np.unique(np.linspace(0, len(track.t) - 1, MAX_FRAMES).astype(int))
        _poses(meshcat, f"{path}/ship", track, k, speedup)
    meshcat.StopRecording()
    meshcat.PublishRecording()
    return meshcat.StaticHtml()
