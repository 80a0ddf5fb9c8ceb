"""Ship-scale own-ship model (Clarke 1983 derivatives, propeller, rudder, autopilot): sanity
checks against IMO manoeuvring standards (MSC.137(76)) and SOLAS steering-gear limits."""

import numpy as np
import pytest

from usvdrake.angles import wrap_angle
from usvdrake.systems.colav.ship_model import (
    DELTA_MAX,
    DELTA_RATE,
    KNOT,
    ShipParams,
    autopilot,
    initial_state,
    response_time_constants,
    rollout,
    ship_derivative,
    simulate,
)

SHIPS = [(122.0, 20.0, 10.0, "Passenger"), (50.0, 10.0, 12.1, "cargo"), (200.0, 32.0, 18.0, None)]


def _ship(length, beam, knots, kind):
    return ShipParams.from_dimensions(length, beam, design_speed=knots * KNOT, ship_type=kind)


def test_guessed_dimensions_are_reported():
    p = ShipParams.from_dimensions(122.0, 20.0, ship_type="Passenger")
    assert p.draught == pytest.approx(20.0 / 2.6)
    assert p.block_coefficient == pytest.approx(0.60)
    assert len(p.assumed) == 2
    assert ShipParams.from_dimensions(122.0, 20.0, 6.0, block_coefficient=0.6).assumed == ()


@pytest.mark.parametrize("length, beam, knots, kind", SHIPS)
def test_turning_circle_within_imo_standard(length, beam, knots, kind):
    p = _ship(length, beam, knots, kind)
    q0 = initial_state(p)
    t, qs = simulate(p, q0, lambda t, q: np.array([-DELTA_MAX, q0[7]]), 1500.0, 0.5)
    turned = -np.unwrap(qs[:, 2])  # starboard turn: ψ decreases
    i90, i180 = np.argmax(turned >= np.pi / 2), np.argmax(turned >= np.pi)
    advance = qs[i90, 0] / length
    tactical = -qs[i180, 1] / length  # starboard of an eastward start is −y
    assert 2.0 < advance <= 4.5  # MSC.137(76): advance ≤ 4.5 L
    assert 3.0 < tactical <= 5.0  # MSC.137(76): tactical diameter ≤ 5 L
    assert 0.5 < qs[-1, 3] / q0[3] < 0.95  # speed drops in the turn


@pytest.mark.parametrize("length, beam, knots, kind", SHIPS)
def test_design_speed_reached_from_rest(length, beam, knots, kind):
    p = _ship(length, beam, knots, kind)
    q0 = np.zeros(8)
    n_set = 0.85 * p.n_max
    _, qs = simulate(p, q0, lambda t, q: np.array([0.0, n_set]), 3000.0, 1.0)
    assert qs[-1, 3] == pytest.approx(p.design_speed, rel=0.01)
    assert np.abs(qs[:, 1]).max() < 1e-9 and np.abs(qs[:, 2]).max() < 1e-12  # straight


def test_straight_run_stays_straight():
    p = _ship(*SHIPS[0])
    q0 = initial_state(p, psi=0.7)
    qs = rollout(p, q0, np.tile([0.0, q0[7]], (600, 1)), 1.0)
    assert np.allclose(qs[:, 2], 0.7)
    assert np.allclose(qs[:, 3], p.design_speed, rtol=1e-6)
    d = qs[-1, :2] - qs[0, :2]
    assert np.hypot(*d) == pytest.approx(600.0 * p.design_speed, rel=1e-6)
    assert np.arctan2(d[1], d[0]) == pytest.approx(0.7)


def test_rudder_and_shaft_limits_honoured():
    p = _ship(*SHIPS[0])
    q0 = initial_state(p)
    qs = rollout(p, q0, np.tile([np.radians(90.0), 10.0 * p.n_max], (60, 1)), 0.5)
    rates = np.diff(qs[:, 6]) / 0.5
    assert rates.max() <= DELTA_RATE * (1 + 1e-9)
    assert qs[:, 6].max() <= DELTA_MAX + 1e-12
    # hard over to 35° takes at least 35/2.32 ≈ 15 s (SOLAS: 35°→−30° in ≤ 28 s needs ≥ 2.32°/s)
    assert qs[29, 6] < DELTA_MAX
    qn = rollout(p, q0, np.tile([0.0, 10.0 * p.n_max], (600, 1)), 0.5)
    assert np.diff(qn[:, 7]).max() / 0.5 <= p.n_rate * (1 + 1e-9)
    assert qn[:, 7].max() <= p.n_max + 1e-12
    # positive δ turns to port (counter-clockwise, ψ increasing)
    q = q0.copy()
    q[6] = DELTA_MAX
    assert ship_derivative(p, q, [DELTA_MAX, q0[7]])[5] > 0.0


@pytest.mark.parametrize("length, beam, knots, kind", SHIPS)
def test_zigzag_overshoot_plausible(length, beam, knots, kind):
    p = _ship(length, beam, knots, kind)
    q0 = initial_state(p)
    side = {"s": 1.0}

    def zigzag(_t, q):
        if side["s"] > 0 and q[2] >= np.radians(10.0):
            side["s"] = -1.0
        elif side["s"] < 0 and q[2] <= np.radians(-10.0):
            side["s"] = 1.0
        return np.array([side["s"] * np.radians(10.0), q0[7]])

    _, qs = simulate(p, q0, zigzag, 600.0, 0.5)
    psi = np.degrees(qs[:, 2])
    i = np.argmax(psi >= 10.0)
    j = i + np.argmax(psi[i:] < 10.0)
    overshoot = psi[i:j].max() - 10.0
    l_over_u = length / p.design_speed
    imo_limit = 10.0 if l_over_u < 10 else min(20.0, 5.0 + 0.5 * l_over_u)  # MSC.137(76) 10/10
    assert 0.5 < overshoot <= imo_limit


def test_autopilot_course_and_speed():
    p = _ship(*SHIPS[0])
    q0 = initial_state(p)
    t, qs = simulate(
        p, q0, lambda t, q: autopilot(p, q, np.radians(-60.0), p.design_speed), 400, 0.5
    )
    err = np.degrees(wrap_angle(qs[:, 2] + np.radians(60.0)))
    assert np.abs(err[t > 200]).max() < 1.0
    assert np.degrees(np.abs(qs[:, 6])).max() <= 35.0 + 1e-9
    t, qs = simulate(p, q0, lambda t, q: autopilot(p, q, 0.0, 0.5 * p.design_speed), 900, 1.0)
    assert qs[-1, 3] == pytest.approx(0.5 * p.design_speed, rel=0.02)
    assert np.abs(qs[:, 1]).max() < 1e-6


def test_response_time_constants_for_sbmpc():
    tc, ts = response_time_constants(_ship(*SHIPS[0]))
    assert 10.0 < tc < 90.0  # a 122 m ferry settles on a new course in about half a minute
    assert 60.0 < ts < 400.0  # and loses half its speed over minutes, not seconds
