"""Barron's kernel against its named special cases, finite differences, gtsam's own kernels, an
IRLS line fit with gross outliers and a Pose2 graph with a wrong loop closure."""

import gtsam
import numpy as np
import pytest

from usvdrake.systems.slam.robust_kernel import barron_loss, barron_weight, gtsam_barron, irls

X = np.linspace(-12.0, 12.0, 241)
C = 0.7

NAMED = {  # α: closed form of Barron (2019) §1, u = x/c
    2.0: lambda u: 0.5 * u**2,  # L2
    1.0: lambda u: np.sqrt(u**2 + 1.0) - 1.0,  # pseudo-Huber / Charbonnier
    0.0: lambda u: np.log(0.5 * u**2 + 1.0),  # Cauchy / Lorentzian
    -2.0: lambda u: 2.0 * u**2 / (u**2 + 4.0),  # Geman-McClure
    -np.inf: lambda u: 1.0 - np.exp(-0.5 * u**2),  # Welsch / Leclerc
}


@pytest.mark.parametrize("alpha", list(NAMED))
def test_named_special_cases(alpha):
    np.testing.assert_allclose(barron_loss(X, alpha, C), NAMED[alpha](X / C), rtol=0, atol=1e-9)


@pytest.mark.parametrize("alpha", [2.0, 1.5, 1.0, 0.5, 0.0, -0.5, -2.0, -7.0, -np.inf])
def test_weight_is_derivative_over_x(alpha):
    x = X[np.abs(X) > 1e-3]
    h = 1e-6
    dloss = (barron_loss(x + h, alpha, C) - barron_loss(x - h, alpha, C)) / (2 * h)
    np.testing.assert_allclose(barron_weight(x, alpha, C), dloss / x, rtol=1e-6, atol=1e-10)
    # At x = 0 every kernel is the L2 bowl: w = 1/c².
    assert barron_weight(0.0, alpha, C) == pytest.approx(1.0 / C**2)


@pytest.mark.parametrize(("limit", "nearby"), [(2.0, [2 - 1e-7, 2 - 1e-12]), (0.0, [1e-7, -1e-7])])
def test_continuous_near_finite_limits(limit, nearby):
    for a in nearby:
        np.testing.assert_allclose(
            barron_loss(X, a, C), barron_loss(X, limit, C), rtol=1e-5, atol=1e-9
        )
        np.testing.assert_allclose(
            barron_weight(X, a, C), barron_weight(X, limit, C), rtol=1e-5, atol=1e-9
        )


def test_continuous_towards_minus_infinity():
    # The gap to Welsch shrinks like 1/|α|.
    gaps = [np.max(np.abs(barron_loss(X, a, C) - barron_loss(X, -np.inf, C))) for a in (-1e3, -1e6)]
    assert gaps[1] < 1e-5 and gaps[1] < gaps[0] / 100
    assert np.max(np.abs(barron_weight(X, -1e8, C) - barron_weight(X, -np.inf, C))) < 1e-6


def test_vectorised_and_shapes():
    x = np.arange(12.0).reshape(3, 4)
    assert barron_loss(x, 0.5).shape == (3, 4)
    assert barron_weight(x, 2.0).shape == (3, 4)
    assert np.all(np.diff(barron_loss(np.linspace(0, 50, 100), -3.0)) > 0)  # monotone in |x|
    with pytest.raises(ValueError):
        barron_loss(1.0, 0.0, c=0.0)


@pytest.mark.parametrize(
    ("alpha", "scale", "theirs"),
    [
        (0.0, 1 / np.sqrt(2), gtsam.noiseModel.mEstimator.Cauchy.Create(1.0)),
        (-2.0, 0.5, gtsam.noiseModel.mEstimator.GemanMcClure.Create(1.0)),
        (-np.inf, 1 / np.sqrt(2), gtsam.noiseModel.mEstimator.Welsch.Create(1.0)),
    ],
)
def test_gtsam_adapter_equals_gtsams_kernels(alpha, scale, theirs):
    ours = gtsam_barron(alpha, scale)
    for e in [0.0, 0.1, 0.5, 1.0, 3.0, 20.0]:
        assert ours.loss(e) == pytest.approx(theirs.loss(e), rel=1e-12, abs=1e-15)
        assert ours.weight(e) == pytest.approx(theirs.weight(e), rel=1e-12, abs=1e-15)


def _line_problem():
    rng = np.random.default_rng(6)
    t = np.linspace(0.0, 10.0, 100)
    y = 2.0 * t - 1.0 + rng.normal(0.0, 0.05, t.size)
    bad = rng.choice(t.size, 30, replace=False)  # 30 % gross outliers, all on one side
    y[bad] += rng.uniform(5.0, 20.0, bad.size)
    A = np.column_stack([t, np.ones_like(t)])
    return A, y, bad


@pytest.mark.parametrize("alpha", [1.0, 0.0, -2.0, -np.inf])
def test_irls_line_fit_rejects_gross_outliers(alpha):
    A, y, bad = _line_problem()

    def fit(alpha, start):
        return irls(lambda p: A @ p - y, lambda p: A, start, alpha=alpha, c=0.3, iterations=200)

    least_squares = fit(2.0, np.zeros(2))
    assert np.linalg.norm(least_squares.x - [2.0, -1.0]) > 0.5  # L2 is dragged away
    # Convex-ish kernels start from least squares; redescending ones (α < 0) are non-convex and
    # start from the Cauchy fit, the usual graduated schedule (Barron 2019 §3).
    start = least_squares.x if alpha >= 0 else fit(0.0, least_squares.x).x
    robust = fit(alpha, start)
    assert robust.x == pytest.approx([2.0, -1.0], abs=0.06)
    assert np.max(robust.weights[bad]) < 0.1 * np.median(robust.weights)


def _square_graph(noise_model_for_loops):
    """Eight poses around a 4 m square; exact odometry, two true closures and one false one."""
    truth = [gtsam.Pose2(0, 0, 0)]
    moves = [gtsam.Pose2(2.0, 0.0, 0.0), gtsam.Pose2(2.0, 0.0, np.pi / 2)] * 4
    for m in moves[:-1]:
        truth.append(truth[-1].compose(m))
    graph = gtsam.NonlinearFactorGraph()
    prior = gtsam.noiseModel.Diagonal.Sigmas([1e-3, 1e-3, 1e-4])
    odo = gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.05, 0.01])
    graph.add(gtsam.PriorFactorPose2(0, truth[0], prior))
    for i in range(len(truth) - 1):
        graph.add(gtsam.BetweenFactorPose2(i, i + 1, truth[i].between(truth[i + 1]), odo))
    loop = noise_model_for_loops
    graph.add(gtsam.BetweenFactorPose2(7, 0, truth[7].between(truth[0]), loop))
    graph.add(gtsam.BetweenFactorPose2(6, 0, truth[6].between(truth[0]), loop))
    # The wrong closure: claims pose 4 sits 1 m from pose 0 (it is 4√2 m away).
    graph.add(gtsam.BetweenFactorPose2(4, 0, gtsam.Pose2(1.0, 0.0, 0.3), loop))
    initial = gtsam.Values()
    for i, p in enumerate(truth):
        initial.insert(i, p.compose(gtsam.Pose2(0.05 * i, -0.03 * i, 0.01 * i)))
    result = gtsam.LevenbergMarquardtOptimizer(graph, initial).optimize()
    return max(
        np.linalg.norm(result.atPose2(i).translation() - p.translation())
        for i, p in enumerate(truth)
    )


def test_gtsam_pose_graph_with_wrong_loop_closure():
    base = gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.05, 0.01])
    gaussian_error = _square_graph(base)
    robust = gtsam.noiseModel.Robust.Create(gtsam_barron(alpha=0.0, c=1.0), base)
    barron_error = _square_graph(robust)
    assert gaussian_error > 0.5
    assert barron_error < 0.05
