"""Blue Robotics T200 thrust curve: force [N] ⇄ ESC pulse width [µs] (pure functions, no I/O).

Source of the table
-------------------
Blue Robotics, "T200 Public Performance Data, 10-20 V, September 2019", sheet "16 V":
    https://cad.bluerobotics.com/T200-Public-Performance-Data-10-20V-September-2019.xlsx
(bollard thrust, Basic ESC R3 with BLHeli_S 16.6, 1100-1900 µs; product page
https://bluerobotics.com/store/thrusters/t100-t200-thrusters/t200-thruster-r2-rp/).

The workbook itself could not be opened from this machine (no network). The points below are a
10-point subset of its 16 V sheet, transcribed from a public repository that interpolates them
(``pts_16v_t200``, several copies under the search index's code corpus). They were cross-checked
against an independent summary of the same workbook (16 V: dead band 1472-1528 µs, peak forward
51.4 N = 5.24 kgf, peak reverse -39.9 N = -4.07 kgf) and against the product page's 16 V figures
(5.25 kgf forward, 4.1 kgf reverse). Intermediate values are linear interpolation between these
points, which is within about 0.1-0.2 kgf of the full 4 µs-step table; re-transcribe the full
sheet if better accuracy is needed.

Voltage: 16 V (4S Li-ion/LiPo nominal 14.8 V, fully charged 16.8 V). Roboat II (Table I)
runs at 14.8 V, where the T200 gives roughly 8 % less thrust (14 V sheet: about 4.5 kgf forward,
3.5 kgf reverse); the 16 V curve is used as published, not rescaled.

Conventions
-----------
* Positive force = forward thrust (water expelled aft, the T200's efficient direction).
* The ESC has a ±25 µs dead band around 1500 µs; the published data show zero thrust from 1472
  to 1528 µs. :func:`pwm_to_force` returns 0 N there; :func:`force_to_pwm` returns exactly
  1500 µs for 0 N and jumps to the dead band's edge for any non-zero force.
* Saturation: forces beyond the table's ends give 1100 / 1900 µs, pulse widths outside
  1100-1900 µs are clipped before the look-up.
"""

from __future__ import annotations

import numpy as np

G0 = 9.80665  # [m/s²] standard gravity: kgf → N

SOURCE_URL = "https://cad.bluerobotics.com/T200-Public-Performance-Data-10-20V-September-2019.xlsx"
VOLTAGE = 16.0  # [V] sheet of the workbook the table comes from

PWM_NEUTRAL = 1500  # [µs] zero thrust
ESC_DEADBAND_US = 25  # [µs] Basic ESC dead band half-width around 1500 µs
PWM_MIN = 1100  # [µs] full reverse
PWM_MAX = 1900  # [µs] full forward

# (PWM [µs], thrust [kgf]) from the 16 V sheet (see the module docstring for provenance).
T200_16V_TABLE: tuple[tuple[int, float], ...] = (
    (1100, -4.07),
    (1184, -2.94),
    (1308, -1.35),
    (1472, 0.0),
    (1528, 0.0),
    (1624, 0.87),
    (1728, 2.22),
    (1840, 4.25),
    (1864, 4.71),
    (1900, 5.25),
)

_PWM = np.array([p for p, _ in T200_16V_TABLE], dtype=float)
_FORCE = np.array([k for _, k in T200_16V_TABLE], dtype=float) * G0  # [N]

PWM_DEADBAND_LOW = 1472.0  # [µs] last zero-thrust point of the reverse branch
PWM_DEADBAND_HIGH = 1528.0  # [µs] first zero-thrust point of the forward branch
FORCE_MIN = float(_FORCE[0])  # [N] largest reverse thrust (negative), -39.91 N
FORCE_MAX = float(_FORCE[-1])  # [N] largest forward thrust, 51.48 N

_REV = _PWM <= PWM_DEADBAND_LOW  # reverse branch, force rising from FORCE_MIN to 0
_FWD = _PWM >= PWM_DEADBAND_HIGH  # forward branch, force rising from 0 to FORCE_MAX


def pwm_to_force(pwm_us):
    """Thrust [N] for a pulse width [µs] (scalar or array); clipped to 1100-1900 µs."""
    p = np.clip(np.asarray(pwm_us, dtype=float), PWM_MIN, PWM_MAX)
    f = np.interp(p, _PWM, _FORCE)
    return float(f) if f.ndim == 0 else f


def force_to_pwm(force_n):
    """Pulse width [µs] (float) for a thrust [N] (scalar or array).

    0 N → 1500 µs; f > 0 → on the forward branch (1528-1900 µs); f < 0 → on the reverse branch
    (1100-1472 µs); forces beyond [FORCE_MIN, FORCE_MAX] saturate at 1100 / 1900 µs.
    """
    f = np.clip(np.asarray(force_n, dtype=float), FORCE_MIN, FORCE_MAX)
    fwd = np.interp(f, _FORCE[_FWD], _PWM[_FWD])
    rev = np.interp(f, _FORCE[_REV], _PWM[_REV])
    p = np.where(f > 0.0, fwd, np.where(f < 0.0, rev, float(PWM_NEUTRAL)))
    return float(p) if p.ndim == 0 else p


def force_to_pwm_us(force_n):
    """:func:`force_to_pwm` rounded to whole µs (what goes into the command frame)."""
    p = np.rint(force_to_pwm(force_n)).astype(int)
    return int(p) if p.ndim == 0 else p


def command_to_channels(thrusters, command) -> tuple[list[int], list[int] | None]:
    """A diagram's ``thruster_command`` vector → (PWM µs per thruster, angles [cdeg] or None).

    ``thrusters`` are :class:`usvdrake.vessel.Thruster` objects; the command holds [f] per
    fixed thruster and [f, α] per azimuth (see ``usvdrake.systems.vessel.thrusters``). Angles
    are sent only if some thruster is an azimuth; fixed thrusters then carry angle 0.
    """
    pwm, angles, k = [], [], 0
    for t in thrusters:
        pwm.append(force_to_pwm_us(float(command[k])))
        if t.azimuth:
            a = float(np.rad2deg(float(command[k + 1])))
            a = (a + 180.0) % 360.0 - 180.0  # wrap to [-180, 180) so it fits an int16 in cdeg
            angles.append(int(np.rint(a * 100.0)))
            k += 2
        else:
            angles.append(0)
            k += 1
    return pwm, (angles if any(t.azimuth for t in thrusters) else None)
