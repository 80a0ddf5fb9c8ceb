"""Local ENU ↔ WGS84: round trips, the datum at the origin, metres per degree, bad names."""

import numpy as np
import pytest

from usvdrake.sensors.geodesy import DATUMS, Datum, LocalFrame, datum_by_name

RNG = np.random.default_rng(0)
E, N = RNG.uniform(-5000.0, 5000.0, (2, 200))
U = RNG.uniform(-100.0, 100.0, 200)


@pytest.mark.parametrize("name", sorted(DATUMS))
def test_round_trip_within_a_millimetre(name):
    frame = LocalFrame(name)
    lat, lon, h = frame.to_geodetic(E, N, U)
    e, n, u = frame.to_local(lat, lon, h)
    err = np.sqrt((e - E) ** 2 + (n - N) ** 2 + (u - U) ** 2)
    assert err.max() < 1e-3


@pytest.mark.parametrize("name", sorted(DATUMS))
def test_datum_is_the_origin(name):
    d = DATUMS[name]
    frame = LocalFrame(d)
    lat, lon, h = frame.to_geodetic(0.0, 0.0, 0.0)
    assert isinstance(lat, float)
    assert (lat, lon, h) == pytest.approx((d.latitude, d.longitude, d.height), abs=1e-9)
    assert frame.to_local(d.latitude, d.longitude) == pytest.approx((0, 0, 0), abs=1e-6)


def test_one_kilometre_north_is_a_hundred_and_eleventh_of_a_degree():
    frame = LocalFrame("amsterdam")
    lat, lon, _ = frame.to_geodetic(0.0, 1000.0, 0.0)
    # WGS84 meridian arc at 52.4° N: 111.26 km per degree (1/111.2 to 0.1 %)
    assert lat - 52.3676 == pytest.approx(1 / 111.2, rel=1e-3)
    assert lon == pytest.approx(4.8897, abs=1e-12)
    # 1 km east: a degree of longitude shrinks with cos φ
    _, lon, _ = frame.to_geodetic(1000.0, 0.0, 0.0)
    assert lon - 4.8897 == pytest.approx(1 / (111.32 * np.cos(np.deg2rad(52.3676))), rel=3e-3)


def test_the_earth_drops_away_from_the_tangent_plane():
    frame = LocalFrame("trondheim")
    _, _, h = frame.to_geodetic(0.0, 5000.0, 0.0)  # 5 km along the plane: ≈ d²/2R above
    assert h - DATUMS["trondheim"].height == pytest.approx(5000.0**2 / (2 * 6.37e6), rel=0.02)


def test_arrays_keep_their_shape():
    frame = LocalFrame(Datum("here", 10.0, 20.0, 0.0))
    lat, lon, h = frame.to_geodetic(np.zeros((3, 2)), np.ones((3, 2)))
    assert lat.shape == lon.shape == h.shape == (3, 2)


def test_unknown_datum_names_the_valid_ones():
    with pytest.raises(KeyError) as err:
        datum_by_name("atlantis")
    for name in DATUMS:
        assert name in str(err.value)
    with pytest.raises(KeyError):
        LocalFrame("atlantis")
