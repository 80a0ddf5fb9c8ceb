"""Correlative scan matching (Olson 2009) seeds PLICP across motions too large for its basin."""

import numpy as np
import pytest
from scipy.ndimage import distance_transform_edt

from usvdrake.systems.slam.correlative import correlative_match, lateral_motion, match_covariance
from usvdrake.systems.slam.likelihood_field import (
    LikelihoodField,
    _squared_distance_transform,
    _window_max,
    distance_field,
)
from usvdrake.systems.slam.plicp import plicp
from usvdrake.worlds.raycast import cast
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


@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (40, 70), (301, 199)])
def test_the_distance_transform_is_scipys_to_the_bit(shape):
    """Our exact EDT (Felzenszwalb and Huttenlocher) against scipy's, sparse and dense grids:
    the square roots of the integer squared distances are the same floats."""
    rng = np.random.default_rng(shape[0] * 1000 + shape[1])
    for density in (0.001, 0.05, 0.6):
        empty = rng.random(shape) >= density
        empty.flat[rng.integers(empty.size)] = False  # at least one point
        ours = np.sqrt(_squared_distance_transform(empty).astype(float))
        np.testing.assert_array_equal(ours, distance_transform_edt(empty))


@pytest.mark.parametrize("shape", [(1, 1), (3, 17), (40, 70), (101, 63)])
def test_the_bound_tables_are_the_block_maxima(shape):
    """``_window_max``: every cell the max of the n × n cells ``step`` apart from it (those
    beyond the edge left out), as a plain numpy max over the padded shifts gives it."""
    rng = np.random.default_rng(shape[0] * 7 + shape[1])
    field = rng.random(shape)
    for n, step in ((1, 1), (2, 1), (2, 4), (2, 16), (3, 2), (4, 1), (5, 3)):
        padded = np.full((shape[0] + n * step, shape[1] + n * step), -np.inf)
        padded[: shape[0], : shape[1]] = field
        expected = np.max(
            [
                padded[a * step : a * step + shape[0], b * step : b * step + shape[1]]
                for a in range(n)
                for b in range(n)
            ],
            axis=0,
        )
        np.testing.assert_array_equal(_window_max(field, n, step), expected)


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


def test_a_least_score_drops_only_matches_below_it():
    """``min_score``: a best above it is the plain search's (pose, score and runner-up); when
    the best is below it the match is the guess with score 0, which a caller refusing scores
    below it refuses as it refused the plain answer."""
    scene = cluttered_room()
    room = LikelihoodField.build(points(scene, (0.0, 0.0, 0.0)), 0.05, 0.1, margin=2.5)
    cur, guess = points(scene, (0.3, 0.2, 0.1)), (0.1, -0.1, 0.0)
    plain = correlative_match(room, cur, guess, 1.5, 0.3, distinct=0.5)
    for least in (0.5 * plain.score, plain.score):
        m = correlative_match(room, cur, guess, 1.5, 0.3, distinct=0.5, min_score=least)
        assert np.array_equal(m.pose, plain.pose) and m.score == plain.score
        assert m.runner_up == plain.runner_up
    above = correlative_match(room, cur, guess, 1.5, 0.3, min_score=min(1.01 * plain.score, 1))
    assert above.score == 0.0 and np.array_equal(above.pose, guess)
    with pytest.raises(ValueError, match="lateral prior"):
        correlative_match(room, cur, min_score=0.5, prior_from=(0, 0, 0), lateral_weight=0.25)


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


def test_a_rival_floor_gives_the_exact_searchs_answer_to_is_there_a_rival():
    """``rival_above``: above the fraction the runner-up is the exact one (score and pose), below
    it none is reported; the best match is the same either way."""
    ref = corridor(0.0)
    field = LikelihoodField.build(ref, 0.05, 0.1, margin=2.5)
    scene = cluttered_room()
    room = LikelihoodField.build(points(scene, (0.0, 0.0, 0.0)), 0.05, 0.1, margin=2.5)
    cases = [(field, corridor(0.3)[::3], 0.2), (room, points(scene, (0.3, 0.2, 0.1)), 0.3)]
    for f, cur, angle in cases:
        exact = correlative_match(f, cur, (0.0, 0.0, 0.0), 1.5, angle, distinct=0.5)
        ratio = exact.runner_up / exact.score
        for above in (0.5 * ratio, 0.999 * ratio, min(1.001 * ratio, 1.0), 1.0):
            m = correlative_match(
                f, cur, (0.0, 0.0, 0.0), 1.5, angle, distinct=0.5, rival_above=above
            )
            assert np.array_equal(m.pose, exact.pose) and m.score == exact.score
            if above < ratio:
                assert m.runner_up == exact.runner_up
                assert np.array_equal(m.runner_up_pose, exact.runner_up_pose)
            else:
                assert m.runner_up == 0.0 and m.runner_up_pose is None
            # so "is a rival above the fraction?" is answered as by the exact search
            assert (m.runner_up > above * m.score) == (exact.runner_up > above * exact.score)
            # and as soon as one is found with first_rival: the same answer, not the best rival
            q = correlative_match(
                f, cur, (0.0, 0.0, 0.0), 1.5, angle, distinct=0.5, rival_above=above,
                first_rival=True,
            )  # fmt: skip
            assert np.array_equal(q.pose, exact.pose) and q.score == exact.score
            assert (q.runner_up > above * q.score) == (exact.runner_up > above * exact.score)
            assert q.runner_up <= exact.runner_up
    with pytest.raises(ValueError, match="rival_above"):
        correlative_match(room, cases[1][1], distinct=0.5, rival_above=1.5)
    with pytest.raises(ValueError, match="lateral prior"):
        correlative_match(
            room,
            cases[1][1],
            distinct=0.5,
            rival_above=0.7,
            prior_from=(0, 0, 0),
            lateral_weight=1.0,
        )


def test_the_levelled_search_equals_the_exhaustive_one_past_the_fields_edges():
    """A window wider than the field's margin puts points off the table on every side: the
    top2, top, mid and coarse bounds of blocks that start off it but reach into it must still
    bound them (the table's first cells do), so the search returns the exhaustive grid's best."""
    scene = cluttered_room()
    ref, cur = points(scene, (0.0, 0.0, 0.0)), points(scene, (0.62, -0.47, np.deg2rad(4.0)))
    sub = cur[:: -(-len(cur) // 60)]
    step = np.deg2rad(2.0)
    for margin, guess in ((0.1, (0.0, 0.0, 0.0)), (0.1, (-0.9, 0.8, 0.0)), (1.5, (0.3, 0.0, 0.0))):
        field = LikelihoodField.build(ref, 0.05, 0.1, margin=margin)
        match = correlative_match(field, sub, guess, 1.0, np.deg2rad(6.0), step, 60)
        grid = [
            (field.score(sub, (guess[0] + x, guess[1] + y, th)), (guess[0] + x, guess[1] + y, th))
            for th in step * np.arange(-3, 4)
            for x in 0.05 * np.arange(-20, 21)
            for y in 0.05 * np.arange(-20, 21)
        ]
        best = max(c[0] for c in grid)
        assert match.score == pytest.approx(best, abs=1e-12)
        assert field.score(sub, match.pose) == pytest.approx(best, abs=1e-12)


def test_lateral_motion_is_zero_along_any_arc_and_the_offset_when_sliding():
    assert lateral_motion((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)) == 0.0  # driving straight
    assert lateral_motion((2.0, 1.0, 0.3), (2.0, 1.0, 0.8)) == 0.0  # turning on the spot
    for radius, angle in ((3.0, 0.4), (0.7, -1.1)):  # a circular arc, left and right
        end = (radius * np.sin(angle), radius * (1.0 - np.cos(angle)), angle)
        assert lateral_motion((0.0, 0.0, 0.0), end) == pytest.approx(0.0, abs=1e-12)
    assert lateral_motion((0.0, 0.0, 0.0), (0.0, 0.4, 0.0)) == pytest.approx(0.4)
    # facing +y, a step towards −x is a slide to the left
    assert lateral_motion((1.0, 2.0, np.pi / 2), (0.0, 2.0, np.pi / 2)) == pytest.approx(1.0)
    assert lateral_motion((1.0, 2.0, np.pi / 2), (1.0, 3.0, np.pi / 2)) == pytest.approx(0.0)


def test_branch_and_bound_with_the_lateral_prior_equals_the_exhaustive_search():
    """The prior lowers each fine candidate by weight · sideways²; the coarse bounds by its least
    value over the cell, so the two-level search still returns the exhaustive grid's best."""
    scene = cluttered_room()
    ref, cur = points(scene, (0.0, 0.0, 0.0)), points(scene, (0.37, -0.21, np.deg2rad(7.0)))
    field = LikelihoodField.build(ref, 0.05, 0.1, margin=1.5)
    step, prev, weight = np.deg2rad(1.0), np.array([0.1, -0.4, 0.2]), 20.0
    match = correlative_match(
        field, cur, (0.0, 0.0, 0.0), 0.5, np.deg2rad(10.0), step, 150, 0.3, prev, weight
    )
    sub = cur[:: -(-len(cur) // 150)]
    grid = [
        (field.score(sub, pose) - weight * lateral_motion(prev, pose) ** 2, pose)
        for th in step * np.arange(-10, 11)
        for x in 0.05 * np.arange(-10, 11)
        for y in 0.05 * np.arange(-10, 11)
        for pose in [(x, y, th)]
    ]
    best, best_pose = max(grid, key=lambda c: c[0])
    assert np.allclose(match.pose, best_pose, atol=1e-9)
    # the reported score is the likelihood alone, the runner-up's too
    assert match.score == pytest.approx(field.score(sub, best_pose), abs=1e-9)
    far = [c for c in grid if np.hypot(c[1][0] - best_pose[0], c[1][1] - best_pose[1]) > 0.3]
    second = max(far, key=lambda c: c[0])[1]
    assert match.runner_up == pytest.approx(field.score(sub, second), abs=1e-9)
    # a weight this strong pulls the answer off the unpenalised optimum towards no sliding
    free = correlative_match(field, cur, (0.0, 0.0, 0.0), 0.5, np.deg2rad(10.0), step, 150)
    assert abs(lateral_motion(prev, match.pose)) < abs(lateral_motion(prev, free.pose))


def test_lateral_prior_picks_the_alias_reached_without_sliding():
    """A corridor along the sensor's y axis with a post every 1 m: shifts along it by whole
    posts fit alike, and they are sideways motions. Alone the search takes the best fit; with
    the prior the one the previous pose reaches by driving (no sliding) wins."""
    along_y = np.array([[0.0, -1.0], [1.0, 0.0]])  # the corridor of corridor() turned by 90°
    field = LikelihoodField.build(corridor(0.0) @ along_y.T, 0.05, 0.1, margin=2.5)
    cur = corridor(0.3)[::3] @ along_y.T  # seen from 0.3 m along it (+y)
    args = (field, cur, (0.0, 0.0, 0.0), 1.5, 0.1)
    alone = correlative_match(*args)
    assert abs(alone.pose[1] - 0.3) <= 0.05 and abs(alone.pose[0]) <= 0.05
    # the previous scan taken where the post 1 m back (or on) fits without sliding: that wins
    for prev_y in (-0.7, 1.3):
        prior = correlative_match(*args, prior_from=(0.0, prev_y, 0.0), lateral_weight=0.25)
        assert abs(prior.pose[1] - prev_y) <= 0.05 and abs(prior.pose[0]) <= 0.05
        assert 0.8 * alone.score < prior.score < alone.score  # a slightly worse fit


def test_match_covariance_spreads_along_a_wall_and_pins_across_it():
    """Along an endless wall every shift scores alike, so the weights are uniform in x over the
    span's grid: the x variance is the discrete uniform's, n(n+1)/3 · res², uncorrelated with y
    and θ (the sums do not depend on x at all); across the wall and in rotation the points pin
    the match to well under a cell."""
    x = np.arange(-20.0, 20.0, 0.02)
    ref = np.column_stack([x, np.full_like(x, 1.01)])
    cur = ref[np.abs(x) < 5.0][::5]
    # (a margin off whole cells: the wall off a cell boundary, where rounding would decide)
    field = LikelihoodField.build(ref, 0.05, 0.1, margin=2.012)
    cov = match_covariance(field, cur, (0.0, 0.0, 0.0), temperature=2.0, linear_span=1.0)
    n = 20  # cells either side in 1 m
    assert cov[0, 0] == pytest.approx(n * (n + 1) / 3 * 0.05**2, rel=1e-9)
    assert abs(cov[0, 1]) < 1e-12 and abs(cov[0, 2]) < 1e-12
    # across: about σ √(T/N) = 0.1 √(2/100) m (the quadratic fall of the sum near the wall)
    assert 0.005 < np.sqrt(cov[1, 1]) < 0.02 and np.sqrt(cov[2, 2]) < np.deg2rad(0.5)
    # the same weights computed one pose at a time by the field's own score
    offsets = [
        (dx, dy, dth)
        for dx in 0.05 * np.arange(-n, n + 1)
        for dy in 0.05 * np.arange(-n, n + 1)
        for dth in 0.01 * np.arange(-5, 6)
    ]
    sums = np.array([field.score(cur, o) * len(cur) for o in offsets])
    w = np.exp((sums - sums.max()) / 2.0)
    w /= w.sum()
    d = np.array(offsets) - w @ np.array(offsets)
    assert np.allclose(cov, (w[:, None] * d).T @ d, rtol=1e-9, atol=1e-15)


def test_match_covariance_grows_in_a_corridor_and_with_the_temperature():
    """In the cluttered room every direction is pinned; in the corridor of plain walls the
    length is free (variance near the span's uniform one) while across stays pinned. A flatter
    landscape (higher temperature) only widens it."""
    scene = cluttered_room()
    room = match_covariance(
        LikelihoodField.build(points(scene, (0.0, 0.0, 0.0)), 0.05, 0.1, margin=2.0),
        points(scene, (0.3, 0.2, 0.1)),
        (0.3, 0.2, 0.1),
    )
    assert np.all(np.sqrt(np.diag(room)[:2]) < 0.03)
    x = np.arange(-20.0, 20.0, 0.02)  # two plain walls 3 m apart, longer than the view
    walls = np.vstack([np.column_stack([x, np.full_like(x, y)]) for y in (-1.5, 1.5)])
    field = LikelihoodField.build(walls, 0.05, 0.1, margin=2.012)
    cur = walls[np.abs(walls[:, 0]) < 8.0][::3] - [0.3, 0.0]  # seen from x = 0.3
    covs = [match_covariance(field, cur, (0.3, 0.0, 0.0), temperature=t) for t in (1.0, 8.0)]
    for cov in covs:
        assert np.sqrt(cov[0, 0]) > 0.4  # uniform over ± 1 m: 0.59 m
        assert np.sqrt(cov[1, 1]) < 0.03
    assert np.all(np.diag(covs[1]) >= np.diag(covs[0]) * (1.0 - 1e-9))
    with pytest.raises(ValueError, match="no current points"):
        match_covariance(field, np.zeros((0, 2)), (0.0, 0.0, 0.0))
