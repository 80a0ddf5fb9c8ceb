"""AIS reports (ITU-R M.1371 class A intervals) and the constant-velocity target tracker."""

import numpy as np
import pytest

from usvdrake.systems.colav.ais import (
    KNOT,
    AisNoise,
    AisReport,
    AisTransmitter,
    class_a_interval,
    cog_from_true_course,
)
from usvdrake.systems.colav.tracking import AisTracker, TargetTracker


def test_class_a_intervals():
    assert class_a_interval(10 * KNOT) == 10.0
    assert class_a_interval(10 * KNOT, changing_course=True) == pytest.approx(10.0 / 3.0)
    assert class_a_interval(18 * KNOT) == 6.0
    assert class_a_interval(18 * KNOT, changing_course=True) == 2.0
    assert class_a_interval(30 * KNOT) == 2.0
    assert class_a_interval(1 * KNOT, moored=True) == 180.0
    assert cog_from_true_course(0.0) == pytest.approx(np.pi / 2)  # north
    assert cog_from_true_course(90.0) == pytest.approx(0.0)  # east


COURSE = np.radians(200.0)


def _straight(t, speed=12.0 * KNOT, course=COURSE, p0=(3000.0, 5000.0)):
    v = speed * np.array([np.cos(course), np.sin(course)])
    return np.asarray(p0) + t * v, v


def _run(transmitter, tracker, truth, duration, dt=0.5):
    times, errors, reports = [], [], []
    for t in np.arange(0.0, duration, dt):
        p, v, rot = truth(t)
        rep = transmitter.report(t, p[0], p[1], v[0], v[1], rot)
        if rep is not None:
            reports.append(rep)
            tracker.update(rep)
        if tracker.state is not None:
            tr = tracker.track(t)
            times.append(t)
            errors.append((np.linalg.norm(tr.position - p), np.linalg.norm(tr.velocity - v)))
    return np.array(times), np.array(errors), reports


def test_reports_are_reproducible_and_spaced_as_class_a():
    reps = []
    for _ in range(2):
        tx = AisTransmitter(7, seed=3)
        reps.append([tx.report(t, 0.0, 0.0, 5.0, 0.0) for t in np.arange(0, 120, 0.5)])
    assert reps[0] == reps[1]
    got = [r for r in reps[0] if r is not None]
    gaps = np.diff([r.t_s for r in got])
    assert 9.0 < np.median(gaps) < 11.0  # ~9.7 kn: every 10 s


def test_tracker_converges_on_a_straight_target():
    tx = AisTransmitter(1, seed=11)
    kf = TargetTracker()

    def truth(t):
        p, v = _straight(t)
        return p, v, 0.0

    t, err, reports = _run(tx, kf, truth, 600.0)
    late = t > 300.0
    assert err[late, 0].max() < 12.0  # position: better than one report's 10 m noise
    assert np.sqrt(np.mean(err[late, 1] ** 2)) < 0.12  # velocity RMS [m/s] (one report: ~0.13)
    assert err[late, 1].max() < 0.35
    assert kf.track(t[-1]).age_s <= 11.0
    assert 9.0 < np.median(np.diff([r.t_s for r in reports])) < 11.0  # 12 kn: every 10 s


def test_tracker_predicts_through_missing_reports():
    tx = AisTransmitter(1, seed=5)
    kf = TargetTracker()
    for t in np.arange(0.0, 300.0, 0.5):
        p, v = _straight(t)
        rep = tx.report(t, p[0], p[1], v[0], v[1])
        if rep is not None:
            kf.update(rep)
    # 60 s without a report (six missed at 12 kn)
    tr = kf.track(360.0)
    p, _ = _straight(360.0)
    assert np.linalg.norm(tr.position - p) < 20.0
    assert tr.age_s > 55.0
    assert np.trace(tr.covariance[:2, :2]) > np.trace(kf.cov[:2, :2])  # uncertainty grows


def test_outlier_report_is_gated():
    kf = TargetTracker()
    for k in range(30):
        p, v = _straight(10.0 * k)
        kf.update(AisReport(1, 10.0 * k, p[0], p[1], float(np.arctan2(v[1], v[0])), 12 * KNOT))
    p, v = _straight(300.0)
    bad = AisReport(1, 300.0, p[0] + 800.0, p[1], float(np.arctan2(v[1], v[0])), 12 * KNOT)
    assert not kf.update(bad)
    assert np.linalg.norm(kf.track(300.0).position - p) < 5.0


def test_turning_target_followed_with_bounded_lag():
    speed, rate, radius = 12.0 * KNOT, np.radians(0.5), 12.0 * KNOT / np.radians(0.5)

    def truth(t):
        a = -np.pi / 2 + rate * t  # counter-clockwise circle, heading = a + 90°
        p = radius * np.array([np.cos(a), np.sin(a)])
        v = speed * np.array([-np.sin(a), np.cos(a)])
        return p, v, rate

    tx = AisTransmitter(2, seed=1)
    kf = TargetTracker()
    t, err, reports = _run(tx, kf, truth, 900.0)
    later = t > 120.0
    assert err[later, 0].max() < 30.0  # m, a 0.5°/s turn at 12 kn
    assert err[later, 1].max() < 0.5  # m/s
    gaps = np.diff([r.t_s for r in reports])
    assert np.median(gaps) < 4.0  # "changing course": 3⅓ s


def test_multi_target_tracker_drops_stale_tracks():
    trk = AisTracker(max_age_s=60.0)
    trk.update(AisReport(1, 0.0, 0.0, 0.0, 0.0, 5.0))
    trk.update(AisReport(2, 50.0, 100.0, 0.0, np.pi, 5.0))
    tracks = trk.tracks(70.0)
    assert [tr.target_id for tr in tracks] == [2]
    assert tracks[0].position == pytest.approx([100.0 - 100.0, 0.0])
    assert tracks[0].course == pytest.approx(np.pi)


def test_lossy_link_still_tracks():
    tx = AisTransmitter(3, seed=2, noise=AisNoise(loss_probability=0.3))
    kf = TargetTracker()

    def truth(t):
        p, v = _straight(t)
        return p, v, 0.0

    t, err, _ = _run(tx, kf, truth, 600.0)
    assert err[t > 300, 0].max() < 20.0
