"""LOS guidance and the baseline heading/speed law."""

import numpy as np
import pytest

from usvdrake.angles import wrap_angle
from usvdrake.scenario import ControlConfig
from usvdrake.systems.control.heading_speed_law import heading_speed_tau
from usvdrake.systems.guidance.line_of_sight import advance_index, los_reference
from usvdrake.vessel import load_vessel

WPS = np.array([[10.0, 0.0], [10.0, 10.0]])


def test_los_steers_back_to_the_path():
    ref = los_reference(WPS, 0, np.array([2.0, 2.0]), np.zeros(2), 1.0, 4.0, 1.0, 5.0)
    assert ref.cross_track == pytest.approx(2.0)  # left of the path (y left of an eastward line)
    assert ref.heading == pytest.approx(np.arctan2(-2.0, 4.0))  # turn right, towards the line
    assert ref.speed == 1.0 and not ref.complete


def test_waypoint_switching_and_completion():
    assert advance_index(WPS, 0, np.array([9.5, 0.2]), 1.0) == 1
    assert advance_index(WPS, 0, np.array([5.0, 0.2]), 1.0) == 0
    assert advance_index(WPS, 1, np.array([9.0, 9.5]), 1.0) == 1  # last stays last
    ref = los_reference(WPS, 1, np.array([10.0, 9.5]), np.zeros(2), 1.0, 4.0, 1.0, 5.0)
    assert ref.complete and ref.speed == 0.0
    ref = los_reference(WPS, 1, np.array([10.0, 7.5]), np.zeros(2), 1.0, 4.0, 1.0, 5.0)
    assert ref.speed == pytest.approx(0.5)  # 2.5 m from the goal, 5 m slowdown radius
    closed = np.array([[10.0, 0.0], [0.0, 0.0]])  # a route back to its start
    assert (
        los_reference(closed, 0, np.array([0.5, 0.0]), np.zeros(2), 1.0, 4.0, 1.0, 5.0).speed == 1.0
    )


def test_wrap_angle():
    assert wrap_angle(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    assert wrap_angle(-3 * np.pi / 2) == pytest.approx(np.pi / 2)


def test_heading_law_closed_loop_poles():
    """On the nominal model the heading error obeys ë + 2ζω ė + ω² e = 0."""
    xi = load_vessel("roboat2").hydrodynamics
    g = ControlConfig(heading_natural_frequency=0.7, heading_damping=0.9)
    q = np.array([0, 0, 0.1, 0.0, 0.0, 0.05])
    tau = heading_speed_tau(xi, g, q, 0.0, 0.0)
    r_dot = (tau[2] - xi.Nr * q[5]) / xi.m33
    assert r_dot == pytest.approx(-(0.7**2) * 0.1 - 2 * 0.9 * 0.7 * 0.05)


def test_speed_law_holds_trim():
    xi = load_vessel("roboat2").hydrodynamics
    tau = heading_speed_tau(xi, ControlConfig(), np.array([0, 0, 0, 0.8, 0, 0]), 0.0, 0.8)
    np.testing.assert_allclose(tau, [xi.Xu * 0.8, 0, 0], atol=1e-12)
