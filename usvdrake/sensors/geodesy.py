"""Local ENU ↔ WGS84 geodetic coordinates with PROJ (through pyproj).

The world frame of a scenario is a local tangent plane (x east, y north, z up) whose origin is a
named :class:`Datum`. The conversion is the exact topocentric transformation, as one PROJ
pipeline::

    +proj=pipeline
      +step +proj=cart +ellps=WGS84                     geodetic (λ, φ, h) → ECEF (X, Y, Z)
      +step +proj=topocentric +ellps=WGS84 +lat_0=φ0 +lon_0=λ0 +h_0=h0   ECEF → ENU (e, n, u)

(PROJ's ``topocentric`` operation: the geocentric/topocentric conversion of IOGP Guidance Note
7-2, after the geodetic → geocentric one). It is a rotation and translation of ECEF, exact at any
distance; the flat-world ENU plane and the curved Earth part ways only through the ``u``
coordinate (≈ d²/2R: 8 cm at 1 km, 2 m at 5 km), which is why a GPS fix carries its own
altitude. Latitude and longitude are in degrees, heights above the WGS84 ellipsoid in metres.

The datum heights are ellipsoidal heights of the water surface at the datum (where a vessel's
antenna sits, give or take its mast): geoid undulation + water level above the local vertical
datum. They matter only for the ``altitude`` a simulated GPS reports.
"""

from dataclasses import dataclass

import numpy as np
from pyproj import Transformer


@dataclass(frozen=True)
class Datum:
    """The origin of a local ENU world frame."""

    name: str
    latitude: float  # [deg] WGS84, north positive
    longitude: float  # [deg] WGS84, east positive
    height: float  # [m] above the WGS84 ellipsoid


DATUMS: dict[str, Datum] = {
    # Amsterdam canal ring: Herengracht by the Leidsegracht, the waters Roboat II sails in (Roboat
    # II §VI). Height: the Dutch quasi-geoid (NLGEO2018) lies about 43 m above the ellipsoid here
    # (RDNAPTRANS™2018 uses a fixed 43 m as the Dutch mean), and the canal-ring water level
    # ("grachtenpeil") is held at NAP −0.40 m, so the water surface is ≈ 42.6 m ellipsoidal.
    "amsterdam": Datum("amsterdam", 52.3676, 4.8897, 42.6),
    # Charles River basin between MIT and Back Bay (MIT Sailing Pavilion), where MIT's Roboat
    # prototypes were first tested. Geoid undulation about −28.3 m (NGS GEOID18 around Boston);
    # the basin is held by the Charles River Dam at roughly +0.5 m NAVD88, so ≈ −27.8 m.
    "charles_river": Datum("charles_river", 42.3566, -71.0865, -27.8),
    # NTNU, Trondheim: the coordinates of Ueland 2017's home (the Marine Technology Centre basin
    # area; the point itself is on the Gløshaugen campus, the Tyholt basins ~2 km east — any nearby
    # point serves as an ENU origin). Geoid undulation ≈ 40 m (NN2000 geoid over Trondheim); height
    # taken at sea level (Trondheimsfjord), i.e. ≈ 40 m ellipsoidal, for open-water runs.
    "trondheim": Datum("trondheim", 63.4187, 10.4030, 40.0),
    # Ho Chi Minh City University of Technology (HCMUT, 268 Lý Thường Kiệt) by Phú Thọ lake.
    # The Vietnamese geoid is negative in the north-west and positive in the south-east and
    # small over the Mekong/Saigon lowlands (EGM2008, VIGAC2017); the lake surface is ~2 m above
    # mean sea level, so ≈ 2 m ellipsoidal (uncertain by a few metres, irrelevant to the plane).
    "ho_chi_minh_city": Datum("ho_chi_minh_city", 10.7725, 106.6578, 2.0),
}


def datum_by_name(name: str) -> Datum:
    """The shipped :class:`Datum` called ``name``; ``KeyError`` naming the valid ones if none."""
    try:
        return DATUMS[name]
    except KeyError:
        raise KeyError(
            f"unknown datum {name!r}; expected one of: {', '.join(sorted(DATUMS))}"
        ) from None


def topocentric_pipeline(datum: Datum) -> str:
    """The PROJ pipeline string geodetic (lon, lat, h) → topocentric (e, n, u) at ``datum``."""
    return (
        "+proj=pipeline +step +proj=cart +ellps=WGS84 "
        f"+step +proj=topocentric +ellps=WGS84 +lat_0={datum.latitude!r} "
        f"+lon_0={datum.longitude!r} +h_0={datum.height!r}"
    )


class LocalFrame:
    """Conversions between a datum's local ENU frame and WGS84 geodetic coordinates.

    Both directions accept scalars or arrays (broadcast like numpy) and return floats or arrays
    of the broadcast shape. Immutable after construction (safe to share between systems).
    """

    def __init__(self, datum: Datum | str):
        self.datum = datum_by_name(datum) if isinstance(datum, str) else datum
        self._transformer = Transformer.from_pipeline(topocentric_pipeline(self.datum))

    def to_geodetic(self, e, n, u=0.0):
        """ENU [m] → (latitude [deg], longitude [deg], ellipsoidal height [m])."""
        e, n, u = np.broadcast_arrays(*(np.asarray(a, float) for a in (e, n, u)))
        lon, lat, h = self._transformer.transform(e, n, u, direction="INVERSE")
        return _unwrap(lat, e), _unwrap(lon, e), _unwrap(h, e)

    def to_local(self, latitude, longitude, height=None):
        """(latitude [deg], longitude [deg], ellipsoidal height [m]) → ENU (e, n, u) [m]; the
        height defaults to the datum's (so u is then the drop of the Earth's surface)."""
        if height is None:
            height = self.datum.height
        lat, lon, h = np.broadcast_arrays(
            *(np.asarray(a, float) for a in (latitude, longitude, height))
        )
        e, n, u = self._transformer.transform(lon, lat, h)
        return _unwrap(e, lat), _unwrap(n, lat), _unwrap(u, lat)


def _unwrap(value, like):
    """A float for 0-d input, an array of the input's shape otherwise."""
    out = np.asarray(value, float).reshape(np.shape(like))
    return float(out) if out.ndim == 0 else out
