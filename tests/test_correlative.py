"""Correlative scan matching (Olson 2009) seeds PLICP across motions too large for its basin."""

import numpy as np

from usvdrake.sensors.raycast import cast
from usvdrake.systems.slam.correlative import correlative_search, distance_field
from usvdrake.systems.slam.plicp import plicp
from usvdrake.worlds.synthetic import HOKUYO, cluttered_room


def points(scene, pose):
    r = cast(scene, HOKUYO, [0.0], np.array(pose[:2]), 1.0, pose[2], 30.0)[0]
    ok = np.isfinite(r)
    a = HOKUYO.azimuths[ok]
    return np.column_stack([r[ok] * np.cos(a), r[ok] * np.sin(a)])


def test_distance_field_is_zero_on_points_and_grows_away():
    pts = np.array([[0.0, 0.0], [1.0, 0.0]])
    field, lo = distance_field(pts, 0.05, 1.0)
    r, c = (
        np.floor((pts[:, 1] - lo[1]) / 0.05).astype(int),
        np.floor((pts[:, 0] - lo[0]) / 0.05).astype(int),
    )
    assert np.all(field[r, c] == 0.0)
    assert field.max() > 0.9


def test_large_motion_recovered_where_plain_plicp_fails():
    scene = cluttered_room()
    ref, cur = points(scene, (0.0, 0.0, 0.0)), points(scene, (1.0, -0.8, np.deg2rad(35.0)))
    truth = np.array([1.0, -0.8, np.deg2rad(35.0)])
    plain = plicp(ref, cur)
    plain_err = np.hypot(plain.t[0] - truth[0], plain.t[1] - truth[1])
    seed, score = correlative_search(ref, cur)
    assert np.hypot(*(seed[:2] - truth[:2])) <= 0.1 and abs(seed[2] - truth[2]) <= np.deg2rad(2.0)
    refined = plicp(ref, cur, initial=tuple(seed))
    assert np.hypot(refined.t[0] - truth[0], refined.t[1] - truth[1]) < 1e-3
    assert abs(refined.theta - truth[2]) < np.deg2rad(0.05)
    assert plain_err > 0.1  # the reason the search exists
