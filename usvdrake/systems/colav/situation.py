"""DNV ``trafficgen`` traffic situations and encounter settings → our world frame (plain numpy).

A traffic situation (schemaVersion 0.2.0, the format of DNV's standard encounter set, Sæter et
al. 2023; field meanings from the trafficgen docs) names an own ship and target ships, each
with an initial true heading [deg, clockwise from north], waypoints in WGS84 lat/lon [deg] with
the speed over ground of the leg that starts at each waypoint [kn], and static data (id, name,
MMSI, dimensions [m]: length, width and a/b/c/d, the distances from the AIS/GPS antenna to bow,
stern, port and starboard).

Our world frame is local ENU (x east, y north, metres) with its origin at the own ship's first
waypoint (:mod:`usvdrake.sensors.geodesy`, exact topocentric PROJ pipeline, height 0 on the
WGS84 ellipsoid). Our heading ψ is in radians from +x (east), counter-clockwise — the yaw of
``usvdrake.systems.vessel.vessel_dynamics.rotation`` — so ψ = π/2 − h for a true heading h.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from usvdrake.errors import ConfigError
from usvdrake.sensors.geodesy import Datum, LocalFrame

KNOT = 1852.0 / 3600.0  # [m/s] per knot (international nautical mile)
NAUTICAL_MILE = 1852.0  # [m]
DATA_DIR = Path(__file__).resolve().parent / "data"
DEFAULT_SETTINGS_PATH = DATA_DIR / "encounter_settings.json"
CANAL_DIR = DATA_DIR / "canal"  # the canal-scale set: Roboat II among canal boats (README.md)
# The own ship of DNV's standard set (BASTO VI, 122 m): the scale the encounter defaults are for.
REFERENCE_LENGTH_M = 122.0


def knots_to_mps(v):
    """Speed [kn] → [m/s]."""
    return np.asarray(v, float) * KNOT if np.ndim(v) else float(v) * KNOT


def mps_to_knots(v):
    """Speed [m/s] → [kn]."""
    return np.asarray(v, float) / KNOT if np.ndim(v) else float(v) / KNOT


def heading_deg_true_to_psi(h):
    """True heading [deg, clockwise from north] → our ψ [rad, counter-clockwise from east],
    wrapped to (−π, π]."""
    a = np.pi / 2.0 - np.radians(np.asarray(h, float))
    out = np.arctan2(np.sin(a), np.cos(a))
    return float(out) if out.ndim == 0 else out


def psi_to_heading_deg_true(psi):
    """Our ψ [rad, counter-clockwise from east] → true heading [deg, clockwise from north] in
    [0, 360)."""
    out = np.mod(90.0 - np.degrees(np.asarray(psi, float)), 360.0)
    out = np.where(out >= 360.0 - 1e-9, 0.0, out)  # −0.0 % 360 and rounding edges
    return float(out) if out.ndim == 0 else out


@dataclass(frozen=True, eq=False)
class Ship:
    """One ship of a traffic situation (geodetic as read, plus our local ENU route)."""

    id: int
    name: str
    mmsi: int | None
    ship_type: str | None
    length: float  # [m]
    width: float  # [m]
    height: float | None  # [m]
    # Antenna offsets [m] to bow, stern, port, starboard (None when the file omits them).
    a: float | None
    b: float | None
    c: float | None
    d: float | None
    heading_deg: float  # initial true heading [deg]
    nav_status: str | None
    lat: tuple[float, ...]  # waypoints [deg]
    lon: tuple[float, ...]
    sog_kn: tuple[float, ...]  # speed of the leg starting at each waypoint [kn]
    xy: np.ndarray = field(repr=False)  # (n, 2) waypoints in the local frame [m]

    @property
    def psi0(self) -> float:
        """Initial heading in our convention [rad]."""
        return heading_deg_true_to_psi(self.heading_deg)

    @property
    def speed0(self) -> float:
        """Initial speed (first leg) [m/s]."""
        return knots_to_mps(self.sog_kn[0])

    @property
    def leg_speeds(self) -> np.ndarray:
        """Speed of each leg i → i+1 [m/s] (length n−1; the first speed for one waypoint)."""
        s = np.asarray(self.sog_kn, float) * KNOT
        return s[:-1] if len(s) > 1 else s

    def route_length(self) -> float:
        """Length of the waypoint polyline [m]."""
        return float(np.sum(np.linalg.norm(np.diff(self.xy, axis=0), axis=1)))

    def state_at(self, t):
        """Position, heading and speed at times ``t`` [s] when following the waypoints at the leg
        speeds from t = 0: (x, y, ψ, speed) arrays. Past the last waypoint the ship keeps the
        last leg's course and speed (targets sail on; a single waypoint means a straight course at
        the initial heading)."""
        t = np.atleast_1d(np.asarray(t, float))
        xy, speeds = self.xy, self.leg_speeds
        if len(xy) < 2:
            course = np.array([np.cos(self.psi0), np.sin(self.psi0)])
            p = xy[0] + np.outer(np.maximum(t, 0.0) * speeds[0], course)
            n = len(t)
            return p[:, 0], p[:, 1], np.full(n, self.psi0), np.full(n, speeds[0])
        seg = np.diff(xy, axis=0)
        seg_len = np.linalg.norm(seg, axis=1)
        seg_dir = seg / np.maximum(seg_len, 1e-12)[:, None]
        seg_t = seg_len / np.maximum(speeds, 1e-9)
        t_start = np.concatenate([[0.0], np.cumsum(seg_t)])
        i = np.clip(np.searchsorted(t_start, t, side="right") - 1, 0, len(seg) - 1)
        dt = np.maximum(t - t_start[i], 0.0)
        p = xy[i] + seg_dir[i] * (dt * speeds[i])[:, None]
        psi = np.arctan2(seg_dir[i, 1], seg_dir[i, 0])
        return p[:, 0], p[:, 1], psi, speeds[i].astype(float)


@dataclass(frozen=True, eq=False)
class TrafficSituation:
    """A traffic situation in our local ENU frame (origin: own ship's first waypoint)."""

    title: str
    description: str
    own_ship: Ship
    targets: tuple[Ship, ...]
    start_time: str | None
    source: Path | None
    frame: LocalFrame = field(repr=False)

    @property
    def target_titles(self) -> tuple[str, ...]:
        """The title split per target ("HO, CR-GW" → ("HO", "CR-GW")); trafficgen writes one
        code per target ship, in the order of ``targetShips``."""
        return tuple(s.strip() for s in self.title.split(",") if s.strip())

    def to_local(self, lat, lon):
        """WGS84 (lat, lon) [deg] → local (x east, y north) [m]."""
        e, n, _ = self.frame.to_local(lat, lon)
        return e, n

    def to_geodetic(self, x, y):
        """Local (x, y) [m] → WGS84 (lat, lon) [deg] of the point on the ellipsoid (height 0)
        whose local (x, y) these are — the inverse of :meth:`to_local`; the ENU up coordinate
        (the Earth's drop, ≈ d²/2R) is found by one fixed-point step (sub-millimetre at 50 km)."""
        lat, lon, _ = self.frame.to_geodetic(x, y, 0.0)
        for _ in range(2):
            u = self.frame.to_local(lat, lon, 0.0)[2]
            lat, lon, _ = self.frame.to_geodetic(x, y, u)
        return lat, lon


@dataclass(frozen=True)
class EncounterSettings:
    """trafficgen's ``encounter_settings.json``: classification sectors [deg] and ranges."""

    theta13_criteria: float = 67.5
    theta14_criteria: float = 5.0
    theta15_criteria: float = 5.0
    theta15: tuple[float, float] = (112.5, 247.5)
    relative_speed: dict = field(default_factory=dict)  # name → (min, max) × own speed
    situation_length: float | None = None  # [min]
    max_meeting_distance: float | None = None  # [nmi]
    common_vector: float | None = None  # [min]
    situation_develop_time: float | None = None  # [min]
    disable_land_check: bool | None = None
    source: Path | None = None


# --------------------------------------------------------------------------------- reading


def _read_json(path: Path):
    try:
        text = path.read_text()
    except OSError as e:
        raise ConfigError(path, "", "a readable JSON file", e.strerror or type(e).__name__) from e
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ConfigError(path, "", "valid JSON", f"{e.msg} at line {e.lineno}") from e


def _number(node, key, path, where, default=None, required=True):
    value = node.get(key, default) if isinstance(node, dict) else default
    if value is None:
        if required:
            raise ConfigError(path, f"{where}.{key}", "a number", "nothing")
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(path, f"{where}.{key}", "a number", repr(value))
    if not np.isfinite(value):
        raise ConfigError(path, f"{where}.{key}", "a finite number", repr(value))
    return float(value)


def _obj(node, key, path, where, required=True):
    value = node.get(key) if isinstance(node, dict) else None
    if value is None:
        if required:
            raise ConfigError(path, f"{where}.{key}", "an object", "nothing")
        return {}
    if not isinstance(value, dict):
        raise ConfigError(path, f"{where}.{key}", "an object", type(value).__name__)
    return value


def _raw_waypoints(node, path, where):
    """[(lat, lon, sog_kn | None)] from ``waypoints`` (or ``initial.position`` if none)."""
    wps = node.get("waypoints")
    initial = _obj(node, "initial", path, where, required=False)
    if wps is None or wps == []:
        pos = _obj(initial, "position", path, f"{where}.initial", required=False)
        if not pos:
            raise ConfigError(path, f"{where}.waypoints", "a list of waypoints", "nothing")
        wps = [{"position": pos, "leg": {"sog": initial.get("sog")}}]
    if not isinstance(wps, list):
        raise ConfigError(path, f"{where}.waypoints", "a list", type(wps).__name__)
    out = []
    for k, wp in enumerate(wps):
        w = f"{where}.waypoints[{k}]"
        if not isinstance(wp, dict):
            raise ConfigError(path, w, "an object", type(wp).__name__)
        pos = _obj(wp, "position", path, w)
        lat = _number(pos, "lat", path, f"{w}.position", pos.get("latitude"))
        lon = _number(pos, "lon", path, f"{w}.position", pos.get("longitude"))
        if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 360.0):
            raise ConfigError(path, f"{w}.position", "lat in [-90, 90], lon in [-180, 360]",
                              f"({lat}, {lon})")  # fmt: skip
        leg = wp.get("leg") if isinstance(wp.get("leg"), dict) else {}
        sog = _number(leg, "sog", path, f"{w}.leg", required=False)
        out.append((lat, lon, sog))
    return out, initial


def _leg_speeds(raw, initial, path, where) -> tuple[float, ...]:
    """Each waypoint's leg speed [kn]; missing ones take the previous leg's (or initial sog)."""
    fallback = _number(initial, "sog", path, f"{where}.initial", required=False)
    speeds, last = [], fallback
    for _, _, sog in raw:
        last = sog if sog is not None else last
        speeds.append(last)
    if speeds and speeds[0] is None:  # only later legs carry a speed: back-fill
        first = next((s for s in speeds if s is not None), None)
        speeds = [first if s is None else s for s in speeds]
    if not speeds or speeds[0] is None:
        raise ConfigError(path, f"{where}.waypoints[0].leg.sog", "a speed [kn]", "nothing")
    if any(s < 0 for s in speeds):
        raise ConfigError(path, f"{where}.waypoints[].leg.sog", "speeds >= 0", str(speeds))
    return tuple(float(s) for s in speeds)


def _parse_ship(node, path: Path, where: str, frame: LocalFrame, default_id: int) -> Ship:
    if not isinstance(node, dict):
        raise ConfigError(path, where, "an object", type(node).__name__)
    raw, initial = _raw_waypoints(node, path, where)
    sog_kn = _leg_speeds(raw, initial, path, where)
    static = _obj(node, "static", path, where, required=False)
    dims = _obj(static, "dimensions", path, f"{where}.static", required=False)
    sw = f"{where}.static.dimensions"
    length = _number(dims, "length", path, sw, required=False)
    width = _number(dims, "width", path, sw, required=False)
    a, b = (_number(dims, k, path, sw, required=False) for k in ("a", "b"))
    c, d = (_number(dims, k, path, sw, required=False) for k in ("c", "d"))
    if length is None and a is not None and b is not None:
        length = a + b
    if width is None and c is not None and d is not None:
        width = c + d
    if length is None or width is None or length <= 0 or width <= 0:
        raise ConfigError(path, sw, "length and width > 0 [m]", f"{length}, {width}")
    lat = tuple(w[0] for w in raw)
    lon = tuple(w[1] for w in raw)
    x, y = frame.to_local(np.array(lat), np.array(lon))[:2]
    xy = np.column_stack([np.atleast_1d(x), np.atleast_1d(y)])
    heading = _number(initial, "heading", path, f"{where}.initial", required=False)
    if heading is None:
        heading = _number(initial, "cog", path, f"{where}.initial", required=False)
    if heading is None:  # course of the first leg
        if len(xy) < 2:
            raise ConfigError(path, f"{where}.initial.heading", "a heading [deg]", "nothing")
        dx, dy = xy[1] - xy[0]
        heading = psi_to_heading_deg_true(np.arctan2(dy, dx))
    mmsi = static.get("mmsi")
    return Ship(
        id=int(static.get("id", default_id)),
        name=str(static.get("name", f"ship_{default_id}")),
        mmsi=int(mmsi) if isinstance(mmsi, (int, float)) else None,
        ship_type=static.get("shipType"),
        length=length,
        width=width,
        height=_number(dims, "height", path, sw, required=False),
        a=a,
        b=b,
        c=c,
        d=d,
        heading_deg=float(heading),
        nav_status=initial.get("navStatus"),
        lat=lat,
        lon=lon,
        sog_kn=sog_kn,
        xy=xy,
    )


def parse_situation(doc, source: Path | str | None = None) -> TrafficSituation:
    """A decoded traffic-situation JSON document → :class:`TrafficSituation`."""
    path = Path(source) if source is not None else Path("<traffic situation>")
    if not isinstance(doc, dict):
        raise ConfigError(path, "", "a JSON object", type(doc).__name__)
    own_node = doc.get("ownShip")
    if not isinstance(own_node, dict):
        raise ConfigError(path, "ownShip", "an object", type(own_node).__name__)
    raw, _ = _raw_waypoints(own_node, path, "ownShip")
    frame = LocalFrame(Datum("situation", raw[0][0], raw[0][1], 0.0))
    own = _parse_ship(own_node, path, "ownShip", frame, default_id=1)
    targets_node = doc.get("targetShips", [])
    if not isinstance(targets_node, list):
        raise ConfigError(path, "targetShips", "a list", type(targets_node).__name__)
    targets = tuple(
        _parse_ship(t, path, f"targetShips[{k}]", frame, default_id=k + 2)
        for k, t in enumerate(targets_node)
    )
    start = doc.get("startTime", doc.get("start_time"))
    return TrafficSituation(
        title=str(doc.get("title", "")),
        description=str(doc.get("description", "")),
        own_ship=own,
        targets=targets,
        start_time=str(start) if start is not None else None,
        source=Path(source) if source is not None else None,
        frame=frame,
    )


def load_situation(path: Path | str) -> TrafficSituation:
    """Read a trafficgen traffic-situation JSON file; :class:`ConfigError` if it is broken."""
    path = Path(path)
    return parse_situation(_read_json(path), path)


def situation_files(directory: Path | str) -> list[Path]:
    """The situation files of a folder (``*.json`` except ``encounter_settings.json``), sorted."""
    d = Path(directory)
    return sorted(p for p in d.glob("*.json") if p.name != "encounter_settings.json")


def resolve_situation(name: str, file="scenario", key="traffic.situation") -> Path:
    """A situation file from a path or a shipped situation's bare name (``traffic_situation_01``
    of DNV's set, ``canal_situation_01`` of the canal set); :class:`ConfigError` otherwise."""
    path = Path(name)
    if path.is_file():
        return path
    if path.name == str(name):
        for folder in (DATA_DIR, CANAL_DIR):
            if (folder / f"{name}.json").is_file():
                return folder / f"{name}.json"
    raise ConfigError(file, key, "a traffic-situation JSON file or a shipped situation's name",
                      repr(name))  # fmt: skip


def settings_path_for(situation_path: Path | str) -> Path:
    """The ``encounter_settings.json`` beside a situation file (the settings it was generated
    with), else the standard set's."""
    beside = Path(situation_path).parent / "encounter_settings.json"
    return beside if beside.is_file() else DEFAULT_SETTINGS_PATH


def load_encounter_settings(path: Path | str | None = None) -> EncounterSettings:
    """Read trafficgen's ``encounter_settings.json`` (default: the copy shipped in ``data/``)."""
    path = Path(path) if path is not None else DEFAULT_SETTINGS_PATH
    doc = _read_json(path)
    if not isinstance(doc, dict):
        raise ConfigError(path, "", "a JSON object", type(doc).__name__)
    cls = _obj(doc, "classification", path, "", required=False)
    defaults = EncounterSettings()
    theta15 = cls.get("theta15", list(defaults.theta15))
    if (
        not isinstance(theta15, list)
        or len(theta15) != 2
        or not all(isinstance(v, (int, float)) for v in theta15)
    ):
        raise ConfigError(path, "classification.theta15", "two numbers [deg]", repr(theta15))
    rel = {}
    for name, rng in _obj(doc, "relativeSpeed", path, "", required=False).items():
        if not isinstance(rng, list) or len(rng) != 2:
            raise ConfigError(path, f"relativeSpeed.{name}", "[min, max]", repr(rng))
        rel[name] = (float(rng[0]), float(rng[1]))

    def opt(key):
        return _number(doc, key, path, "", required=False)

    def crit(key, default):
        return _number(cls, key, path, "classification", default)

    land = doc.get("disableLandCheck")
    return EncounterSettings(
        theta13_criteria=crit("theta13Criteria", defaults.theta13_criteria),
        theta14_criteria=crit("theta14Criteria", defaults.theta14_criteria),
        theta15_criteria=crit("theta15Criteria", defaults.theta15_criteria),
        theta15=(float(theta15[0]), float(theta15[1])),
        relative_speed=rel,
        situation_length=opt("situationLength"),
        max_meeting_distance=opt("maxMeetingDistance"),
        common_vector=opt("commonVector"),
        situation_develop_time=opt("situationDevelopTime"),
        disable_land_check=bool(land) if land is not None else None,
        source=path,
    )
