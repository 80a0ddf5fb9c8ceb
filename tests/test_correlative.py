"""Correlative scan matching (Olson 2009) seeds PLICP across motions too large for its basin."""

import numpy as np
import pytest

from usvdrake.sensors.raycast import cast
from usvdrake.systems.slam.correlative import (
    LikelihoodField,
    correlative_match,
    distance_field,
)
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
    seed = correlative_match(LikelihoodField.build(ref, margin=2.2), cur).pose
    assert np.hypot(*(seed[:2] - truth[:2])) <= 0.1 and abs(seed[2] - truth[2]) <= np.deg2rad(2.0)
    refined = plicp(ref, cur, initial=tuple(seed))
    assert np.hypot(refined.t[0] - truth[0], refined.t[1] - truth[1]) < 1e-3
    assert abs(refined.theta - truth[2]) < np.deg2rad(0.05)
    assert plain_err > 0.1  # the reason the search exists


def test_branch_and_bound_equals_the_exhaustive_search():
    """Olson's two-level search returns the best candidate of the fine grid, scored one by one."""
    scene = cluttered_room()
    ref, cur = points(scene, (0.0, 0.0, 0.0)), points(scene, (0.37, -0.21, np.deg2rad(7.0)))
    field = LikelihoodField.build(ref, 0.05, 0.1, margin=1.5)
    step = np.deg2rad(1.0)
    match = correlative_match(
        field, cur, (0.0, 0.0, 0.0), 0.5, np.deg2rad(10.0), step, 150, distinct=0.3
    )
    sub = cur[:: -(-len(cur) // 150)]
    grid = [
        (field.score(sub, (x, y, th)), (x, y, th))
        for th in step * np.arange(-10, 11)
        for x in 0.05 * np.arange(-10, 11)
        for y in 0.05 * np.arange(-10, 11)
    ]
    best, best_pose = max(grid, key=lambda c: c[0])
    assert match.score == pytest.approx(best, abs=1e-9)
    assert np.allclose(match.pose, best_pose, atol=1e-9)
    assert np.hypot(match.pose[0] - 0.37, match.pose[1] + 0.21) <= 0.05
    # the runner-up too: the best of the translations ≥ 0.3 m (6 cells) from the best pose
    far = [c for c in grid if np.hypot(c[1][0] - best_pose[0], c[1][1] - best_pose[1]) > 0.3]
    assert match.runner_up == pytest.approx(max(c[0] for c in far), abs=1e-9)


def corridor(shift: float) -> np.ndarray:
    """Two walls 3 m apart with a post every 1 m along them, seen from x = shift."""
    x = np.arange(-15.0, 15.0, 0.02)
    posts = np.concatenate([np.arange(-15.0, 15.0, 1.0) + d for d in (0.0, 0.1)])
    walls = [np.column_stack([x, np.full_like(x, y)]) for y in (-1.5, 1.5)]
    studs = [np.column_stack([posts, np.full_like(posts, y)]) for y in (-1.3, 1.3)]
    pts = np.vstack(walls + studs)
    return pts[np.abs(pts[:, 0]) < 10.0] - [shift, 0.0]


def test_runner_up_exposes_a_repeating_corridor_but_not_a_room():
    ref = corridor(0.0)
    field = LikelihoodField.build(ref, 0.05, 0.1, margin=2.5)
    aliased = correlative_match(field, corridor(0.3)[::3], (0.0, 0.0, 0.0), 1.5, 0.2, distinct=0.5)
    assert aliased.runner_up >= 0.9 * aliased.score  # a post 1 m along fits as well
    # the runner-up's pose: at least `distinct` from the best, and it scores what it reports
    second = aliased.runner_up_pose
    assert np.hypot(*(second[:2] - aliased.pose[:2])) >= 0.5 - 1e-9
    assert abs(abs(second[0] - aliased.pose[0]) - 1.0) <= 0.1  # the next post along
    # (the search scores a subsample of ≤ 400 of the points, hence not to 1e-9)
    assert field.score(corridor(0.3)[::3], second) == pytest.approx(aliased.runner_up, abs=0.01)
    scene = cluttered_room()
    room = LikelihoodField.build(points(scene, (0.0, 0.0, 0.0)), 0.05, 0.1, margin=2.5)
    cur = points(scene, (0.3, 0.2, 0.1))
    clear = correlative_match(room, cur, (0.0, 0.0, 0.0), 1.5, 0.3, distinct=0.5)
    assert clear.runner_up < 0.7 * clear.score
    assert np.hypot(clear.pose[0] - 0.3, clear.pose[1] - 0.2) <= 0.1
