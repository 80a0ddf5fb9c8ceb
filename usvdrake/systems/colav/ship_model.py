"""A ship-scale own ship built from its main dimensions: linear manoeuvring derivatives of
Clarke 1983 (Clarke, Gedling & Hine) as used in the MSS toolbox (`clarke83`; Fossen 2021 App. D
for the prime-system scaling), a propeller on a shaft with speed and acceleration
limits, and a rudder with the limits IMO/SOLAS asks of steering gear. Plain numpy; our code.

State q = [x y ψ u v r δ n]: the first six are usvdrake's vessel convention (x east, y north,
ψ counter-clockwise from +x; body u forward, v to port (left), r counter-clockwise, as in
usvdrake/systems/vessel/vessel_dynamics.py), then the actual rudder angle δ [rad] and shaft
speed n [rev/s]. Command = [δ_c, n_c]. Positive δ gives a positive (counter-clockwise, to port)
yaw moment, so a starboard turn is δ < 0. The sway-yaw equations of Clarke's linear model are
unchanged by flipping v, r and the rudder force together, so the y-starboard derivatives apply
as they are in our y-port frame.

Model (Clarke 1983 via MSS's `clarke83`, with our surge, propeller and rudder parts):

    surge   (m − X_u̇) u̇ = (1 − t) T(n, u) − k_R u|u| + (m − Y_v̇) v r + X_R(δ)
    sway-yaw M [v̇ ṙ]ᵀ + U N' [v r]ᵀ = [Y_R N_R]ᵀ       (M, N' from Clarke's regressions)
    rudder  δ̇ = sat_{±δ̇max}((δ_c − δ)/T_δ),  |δ_c| ≤ 35°
    shaft   ṅ = sat_{±ṅmax}((n_c − n)/T_n),   |n_c| ≤ n_max

Rudder: normal force F_N = ½ ρ A_R U² C_N sin δ with C_N = 6.13 Λ/(Λ + 2.25) and the hull-
interaction factor a_H, the lumped form of Fossen 2021 §9.5.1 as MSS's `shipClarke83` uses it;
A_R = 2.8 % of L·T is an effective area (real rudders are about 1.5-2.5 % of L·T; the extra
stands in for the propeller slipstream's faster inflow, which is not modelled: our assumption,
chosen so that the tactical diameter at 35° is 4-4.5 L, inside MSC.137(76)'s ≤ 5 L). Rudder
limits: ±35° and 2.3°/s, SOLAS II-1/29's steering-gear requirement (35° either side to 30° the
other in ≤ 28 s). Propeller: open-water thrust K_T(J) = K_T0 (1 − J/J_0) (a linear fit of a
typical B-series curve), wake w = 0.5 C_b − 0.05 and thrust deduction t = 0.6 w (classic
single-screw estimates; all three our assumptions, not from a cited source).
The surge resistance k_R u|u| replaces Clarke's linear X_u: it is set so that the design speed
is the steady speed at 85 % of the maximum shaft speed (MSC.137(76) §4.2 takes its test speed
at 85 % of the maximum engine output) with the propeller at J = 0.6.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from usvdrake.angles import wrap_angle

RHO = 1025.0  # sea water [kg/m³]
KNOT = 1852.0 / 3600.0  # [m/s]
DELTA_MAX = np.radians(35.0)  # SOLAS II-1/29: hard over 35° each side
DELTA_RATE = np.radians(65.0 / 28.0)  # 35° to 30° the other side in 28 s ≈ 2.32°/s

# Block coefficient guessed from the AIS / DNV ship type when the situation does not give one
# (typical design values, our assumption).
BLOCK_COEFFICIENT_BY_TYPE = {
    "passenger": 0.60,
    "container": 0.65,
    "cargo": 0.70,
    "tanker": 0.80,
    "bulk": 0.82,
    "fishing": 0.55,
    "tug": 0.55,
    "pleasure": 0.45,
    "sailing": 0.45,
    "high speed": 0.45,
}


def guess_block_coefficient(ship_type: str | None) -> float:
    """C_b from a ship-type string (DNV's `shipType`, AIS type names); 0.7 when unknown."""
    name = (ship_type or "").lower()
    for key, cb in BLOCK_COEFFICIENT_BY_TYPE.items():
        if key in name:
            return cb
    return 0.70


def clarke83_derivatives(length, beam, draught, cb):
    """Clarke 1983 non-dimensional sway-yaw derivatives (prime system).

    Returns (Yv̇', Yṙ', Nv̇', Nṙ', Yv', Yr', Nv', Nr'), the regressions MSS's `clarke83` uses,
    all scaled by S = π (T/L)².
    """
    L, B, T = length, beam, draught
    s = np.pi * (T / L) ** 2
    yvd = -s * (1.0 + 0.16 * cb * B / T - 5.1 * (B / L) ** 2)
    yrd = -s * (0.67 * B / L - 0.0033 * (B / T) ** 2)
    nvd = -s * (1.1 * B / L - 0.041 * B / T)
    nrd = -s * (1.0 / 12.0 + 0.017 * cb * B / T - 0.33 * B / L)
    yv = -s * (1.0 + 0.4 * cb * B / T)
    yr = -s * (-0.5 + 2.2 * B / L - 0.08 * B / T)
    nv = -s * (0.5 + 2.4 * T / L)
    nr = -s * (0.25 + 0.039 * B / T - 0.56 * B / L)
    return yvd, yrd, nvd, nrd, yv, yr, nv, nr


@dataclass(frozen=True, eq=False)
class ShipParams:
    """Everything ship_derivative needs; build it with ShipParams.from_dimensions."""

    length: float
    beam: float
    draught: float
    block_coefficient: float
    design_speed: float  # [m/s]
    mass: float
    m_surge: float  # m − X_u̇
    m_sway: float  # m − Y_v̇ (for the surge coupling (m − Y_v̇) v r)
    sway_yaw_mass: np.ndarray  # 2×2 M of [v̇ ṙ]
    sway_yaw_damping: np.ndarray  # 2×2 N' per unit speed: the force is −U N' [v r]
    resistance: float  # k_R [N s²/m²]
    prop_diameter: float
    kt0: float
    j0: float
    wake: float
    thrust_deduction: float
    n_max: float  # [rev/s]
    n_rate: float  # [rev/s²]
    shaft_time_constant: float
    rudder_area: float
    rudder_cn: float  # dC_N/dδ [1/rad]
    rudder_x: float  # x_R [m] (negative: aft)
    hull_factor: float  # a_H
    hull_x: float  # x_H [m]
    rudder_drag_factor: float  # 1 − t_R
    delta_max: float = DELTA_MAX
    delta_rate: float = DELTA_RATE
    rudder_time_constant: float = 1.0
    assumed: tuple[str, ...] = ()  # which dimensions were guessed, for the report

    @classmethod
    def from_dimensions(
        cls,
        length: float,
        beam: float,
        draught: float | None = None,
        design_speed: float = 12.0 * KNOT,
        block_coefficient: float | None = None,
        ship_type: str | None = None,
        shaft_ramp_time: float = 30.0,
        rudder_area_ratio: float = 0.028,
    ) -> "ShipParams":
        """A ship of length L and beam B [m]; draught T = B/2.6 and C_b from the ship type when
        not given (both recorded in `assumed`). design_speed [m/s] is the speed reached at 85 %
        of the maximum shaft speed; shaft_ramp_time [s] is the time from stop to full shaft
        speed at the shaft-acceleration limit."""
        assumed = []
        if draught is None:
            draught = beam / 2.6  # B/T of merchant ships is typically 2.4-3.0 (our assumption)
            assumed.append(f"draught {draught:.1f} m = beam/2.6")
        if block_coefficient is None:
            block_coefficient = guess_block_coefficient(ship_type)
            assumed.append(f"block coefficient {block_coefficient:.2f} from type {ship_type!r}")
        L, B, T, cb = float(length), float(beam), float(draught), float(block_coefficient)
        mass = RHO * cb * L * B * T
        r66 = (0.27 if L > 100.0 else 0.25) * L  # yaw radius of gyration as in MSS's models
        iz = mass * r66**2
        yvd, yrd, nvd, nrd, yv, yr, nv, nr = clarke83_derivatives(L, B, T, cb)
        # Prime system → dimensional (Fossen 2021 App. D): Y_v̇ = ½ρL³ Y_v̇', Y_ṙ = N_v̇ = ½ρL⁴ (·)',
        # N_ṙ = ½ρL⁵ N_ṙ'; Y_v = ½ρL²U Y_v', Y_r = N_v = ½ρL³U (·)', N_r = ½ρL⁴U N_r'.
        h = 0.5 * RHO
        added = np.array([[h * L**3 * yvd, h * L**4 * yrd], [h * L**4 * nvd, h * L**5 * nrd]])
        m_sy = np.diag([mass, iz]) - added
        damp = -np.array([[h * L**2 * yv, h * L**3 * yr], [h * L**3 * nv, h * L**4 * nr]])
        # Surge: X_u̇ = −0.1 m as in MSS's clarke83.
        m_surge = 1.1 * mass
        # Propeller: D = 0.65 T, linear K_T(J), Taylor wake, thrust deduction 0.6 w.
        dprop = 0.65 * T
        kt0, j0 = 0.45, 1.05
        wake = max(0.5 * cb - 0.05, 0.0)
        tded = 0.6 * wake
        j_design = 0.6
        n_design = (1.0 - wake) * design_speed / (j_design * dprop)
        thrust_design = RHO * dprop**4 * kt0 * n_design**2 * (1.0 - j_design / j0)
        k_r = (1.0 - tded) * thrust_design / design_speed**2
        n_max = n_design / 0.85
        lam = 1.5  # rudder aspect ratio (our assumption)
        return cls(
            length=L,
            beam=B,
            draught=T,
            block_coefficient=cb,
            design_speed=float(design_speed),
            mass=mass,
            m_surge=m_surge,
            m_sway=float(m_sy[0, 0]),
            sway_yaw_mass=m_sy,
            sway_yaw_damping=damp,
            resistance=k_r,
            prop_diameter=dprop,
            kt0=kt0,
            j0=j0,
            wake=wake,
            thrust_deduction=tded,
            n_max=n_max,
            n_rate=n_max / shaft_ramp_time,
            shaft_time_constant=2.0,
            rudder_area=rudder_area_ratio * L * T,
            rudder_cn=6.13 * lam / (lam + 2.25),
            rudder_x=-0.5 * L,
            hull_factor=0.3,
            hull_x=-0.45 * L,
            rudder_drag_factor=1.0 - (1.0 - 0.28 * cb - 0.55),
            assumed=tuple(assumed),
        )


def propeller_thrust(p: ShipParams, n, u):
    """T(n, u) = ρ D⁴ K_T0 (n|n| − |n| u_a/(J_0 D)), u_a = (1 − w) u [N]."""
    ua = (1.0 - p.wake) * u
    return (
        RHO
        * p.prop_diameter**4
        * p.kt0
        * (n * np.abs(n) - np.abs(n) * ua / (p.j0 * p.prop_diameter))
    )


def steady_shaft_speed(p: ShipParams, speed: float) -> float:
    """Shaft speed whose thrust balances the resistance at a steady straight run at `speed`."""
    if speed <= 0.0:
        return 0.0
    a = (1.0 - p.wake) * speed / (p.j0 * p.prop_diameter)
    need = p.resistance * speed**2 / ((1.0 - p.thrust_deduction) * RHO * p.prop_diameter**4 * p.kt0)
    return float(0.5 * (a + np.sqrt(a * a + 4.0 * need)))


def rudder_forces(p: ShipParams, delta, u, v):
    """(X_R, Y_R, N_R) of the rudder at angle δ: positive δ pushes the stern to starboard."""
    fn = 0.5 * RHO * p.rudder_area * (u * u + v * v) * p.rudder_cn * np.sin(delta)
    x = -p.rudder_drag_factor * fn * np.sin(delta)
    y = -(1.0 + p.hull_factor) * fn * np.cos(delta)
    n = -(p.rudder_x + p.hull_factor * p.hull_x) * fn * np.cos(delta)
    return x, y, n


def ship_derivative(p: ShipParams, q, command) -> np.ndarray:
    """q̇ for q = [x y ψ u v r δ n] and command = [δ_c, n_c] (see the module docstring)."""
    _, _, psi, u, v, r, delta, n = q
    dc = np.clip(command[0], -p.delta_max, p.delta_max)
    nc = np.clip(command[1], -p.n_max, p.n_max)
    c, s = np.cos(psi), np.sin(psi)
    speed = np.hypot(u, v)
    xr, yr, nr = rudder_forces(p, delta, u, v)
    thrust = propeller_thrust(p, n, u)
    du = (
        (1.0 - p.thrust_deduction) * thrust - p.resistance * u * abs(u) + p.m_sway * v * r + xr
    ) / p.m_surge
    dvr = np.linalg.solve(
        p.sway_yaw_mass, np.array([yr, nr]) - speed * p.sway_yaw_damping @ np.array([v, r])
    )
    ddelta = np.clip((dc - delta) / p.rudder_time_constant, -p.delta_rate, p.delta_rate)
    dn = np.clip((nc - n) / p.shaft_time_constant, -p.n_rate, p.n_rate)
    return np.array([u * c - v * s, u * s + v * c, r, du, dvr[0], dvr[1], ddelta, dn])


def _rk4(p: ShipParams, q, cmd, dt):
    k1 = ship_derivative(p, q, cmd)
    k2 = ship_derivative(p, q + 0.5 * dt * k1, cmd)
    k3 = ship_derivative(p, q + 0.5 * dt * k2, cmd)
    k4 = ship_derivative(p, q + dt * k3, cmd)
    return q + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)


def rollout(p: ShipParams, q0, commands, dt: float) -> np.ndarray:
    """Fixed-step RK4 with each command held for dt: (N, 2) commands → (N + 1, 8) states."""
    out = [np.asarray(q0, dtype=float)]
    for cmd in np.asarray(commands, dtype=float):
        out.append(_rk4(p, out[-1], cmd, dt))
    return np.array(out)


def simulate(
    p: ShipParams, q0, controller: Callable[[float, np.ndarray], np.ndarray], duration, dt
) -> tuple[np.ndarray, np.ndarray]:
    """Closed loop: command = controller(t, q) held for dt. Returns (times, states)."""
    steps = int(round(duration / dt))
    q = np.asarray(q0, dtype=float)
    qs = [q]
    for k in range(steps):
        q = _rk4(p, q, controller(k * dt, q), dt)
        qs.append(q)
    return dt * np.arange(steps + 1), np.array(qs)


def initial_state(p: ShipParams, x=0.0, y=0.0, psi=0.0, speed=None) -> np.ndarray:
    """A steady straight run at `speed` (default the design speed) with its trim shaft speed."""
    u = p.design_speed if speed is None else float(speed)
    return np.array([x, y, psi, u, 0.0, 0.0, 0.0, steady_shaft_speed(p, u)])


def nomoto(p: ShipParams, speed: float) -> tuple[float, float]:
    """First-order Nomoto (K [1/s], T [s]) of r/δ from the linear sway-yaw model at `speed`.

    G(s) = (b₁ s + b₀)/(s² + a₁ s + a₀) ≈ K/(T s + 1) with K = b₀/a₀, T = a₁/a₀ − b₁/b₀
    (T = T₁ + T₂ − T₃: a first-order fit of the second-order response)."""
    speed = max(float(speed), 1e-3)
    minv = np.linalg.inv(p.sway_yaw_mass)
    a = -speed * minv @ p.sway_yaw_damping
    _, yd, nd = rudder_forces(p, 1.0, speed, 0.0)  # per sin(1 rad)·cos(1 rad): rescale below
    scale = np.sin(1.0) * np.cos(1.0)
    b = minv @ np.array([yd, nd]) / scale  # force per rad of δ at small angles
    a1, a0 = -np.trace(a), np.linalg.det(a)
    b1 = b[1]
    b0 = a[1, 0] * b[0] - a[0, 0] * b[1]
    return float(b0 / a0), float(a1 / a0 - b1 / b0)


@dataclass(frozen=True)
class AutopilotGains:
    """Heading PD by pole placement on the Nomoto model, speed by feed-forward + P."""

    bandwidth: float = 1.0  # ω_n T: closed-loop natural frequency relative to 1/T_nomoto
    damping: float = 1.0
    speed_gain: float = 2.0  # n correction per (speed error / design speed) in units of n_design


def autopilot(
    p: ShipParams, q, course_ref: float, speed_ref: float, gains: AutopilotGains | None = None
) -> np.ndarray:
    """[δ_c, n_c] steering ψ to course_ref and u to speed_ref (stateless: usable per step).

    Heading: with Nomoto T ṙ + r = K δ at the present speed, δ = −(K_p e + K_d r) with
    K_p = T ω²/K, K_d = (2ζωT − 1)/K places both closed-loop poles at ω (ζ = 1), ω = bandwidth/T.
    Speed: the steady shaft speed of speed_ref plus a proportional term; both loops then behave
    approximately first order, which SB-MPC's prediction model assumes.
    """
    g = gains or AutopilotGains()
    _, _, psi, u, _, r, _, _ = q
    k, t = nomoto(p, max(u, 0.3 * p.design_speed))
    w = g.bandwidth / t
    kp = t * w * w / k
    kd = max(2.0 * g.damping * w * t - 1.0, 0.0) / k
    e = wrap_angle(psi - course_ref)
    delta_c = float(np.clip(-(kp * e + kd * r), -p.delta_max, p.delta_max))
    n_ff = steady_shaft_speed(p, max(speed_ref, 0.0))
    n_des = steady_shaft_speed(p, p.design_speed)
    n_c = n_ff + g.speed_gain * n_des * (speed_ref - u) / p.design_speed
    return np.array([delta_c, float(np.clip(n_c, -p.n_max, p.n_max))])


def response_time_constants(
    p: ShipParams, course_step: float = np.radians(30.0), gains: AutopilotGains | None = None
) -> tuple[float, float]:
    """(course, speed) time constants [s] of the ship under `autopilot`: the time to 63 % of a
    course step at design speed, and of a step from design speed to half of it. For a
    first-order prediction model such as SB-MPC's."""
    q0 = initial_state(p)
    t, qs = simulate(
        p, q0, lambda _t, q: autopilot(p, q, course_step, p.design_speed, gains), 900.0, 1.0
    )
    t_course = float(t[np.argmax(qs[:, 2] >= 0.632 * course_step)])
    half = 0.5 * p.design_speed
    t, qs = simulate(p, q0, lambda _t, q: autopilot(p, q, 0.0, half, gains), 1800.0, 1.0)
    t_speed = float(t[np.argmax(qs[:, 3] <= p.design_speed - 0.632 * (p.design_speed - half))])
    return t_course, t_speed
