"""Thruster layouts: per-thruster commands → generalised force τ (Roboat II eq. 3 and its kin).

A thruster at body position (x, y) pushing with force f along the body-frame angle α contributes
    τ = f [cos α,  sin α,  x sin α − y cos α]ᵀ
(Fossen 2011 §12.3, yaw moment = x F_y − y F_x with y to port). For Roboat II's layout this is
the B of Roboat II eq. (3) (yaw row mirrored for the y-left frame, see ``vessels/roboat2.yaml``).

The thruster command vector holds, thruster by thruster, [f] for a fixed thruster and [f, α] for
an azimuth thruster (force [N], angle [rad]). Everything here works on float, AutoDiffXd and
symbolic Expression scalars.
"""

import numpy as np
import pydrake.math as dm

from usvdrake.vessel import Thruster


def command_size(thrusters: list[Thruster]) -> int:
    """Length of the thruster command vector (1 per fixed thruster, 2 per azimuth)."""
    return sum(2 if t.azimuth else 1 for t in thrusters)


def command_names(thrusters: list[Thruster]) -> list[str]:
    names = []
    for t in thrusters:
        names += [f"{t.name}.force", f"{t.name}.angle"] if t.azimuth else [f"{t.name}.force"]
    return names


def split_command(thrusters: list[Thruster], command) -> list[tuple]:
    """[(force, angle)] per thruster; a fixed thruster's angle is its mounting angle."""
    out, k = [], 0
    for t in thrusters:
        if t.azimuth:
            out.append((command[k], command[k + 1]))
            k += 2
        else:
            out.append((command[k], np.deg2rad(t.angle_deg)))
            k += 1
    return out


def saturate(thrusters: list[Thruster], command) -> np.ndarray:
    """Clip each force to its limits (fixed: [min, max]; azimuth: [0, max]); angles pass."""
    out, k = [], 0
    for t in thrusters:
        lo = 0.0 if t.azimuth else t.min_force
        out.append(dm.max(dm.min(command[k], t.max_force), lo))
        if t.azimuth:
            out.append(command[k + 1])
        k += 2 if t.azimuth else 1
    return np.array(out)


def mix(thrusters: list[Thruster], command) -> np.ndarray:
    """τ = Σ_i f_i [cos α_i, sin α_i, x_i sin α_i − y_i cos α_i] (eq. 3 generalised)."""
    tau = [0.0, 0.0, 0.0]
    for t, (f, a) in zip(thrusters, split_command(thrusters, command), strict=True):
        c, s = np.cos(a), np.sin(a)
        tau[0] = tau[0] + f * c
        tau[1] = tau[1] + f * s
        tau[2] = tau[2] + f * (t.x * s - t.y * c)
    return np.array(tau)


def thrust_envelope(thrusters: list[Thruster]) -> np.ndarray:
    """[X, Y, N] bounds [N, N, N m] on any generalised force the thrusters can produce
    together: Σ f_max in surge and sway, Σ f_max · (distance from the origin) in yaw (each
    thruster at full force, pointing the most useful way; loose for fixed thrusters)."""
    f = np.array([max(t.max_force, -t.min_force) for t in thrusters], float)
    r = np.array([np.hypot(t.x, t.y) for t in thrusters], float)
    return np.array([f.sum(), f.sum(), float((f * r).sum())])


def configuration_matrix(thrusters: list[Thruster]) -> np.ndarray:
    """B (3 × n) for fixed thrusters at their mounting angles: τ = B f (Roboat II eq. 3)."""
    cols = []
    for t in thrusters:
        a = np.deg2rad(t.angle_deg)
        cols.append([np.cos(a), np.sin(a), t.x * np.sin(a) - t.y * np.cos(a)])
    return np.array(cols).T


def extended_matrix(thrusters: list[Thruster]) -> np.ndarray:
    """B_e for the extended thrust vector z: one column per fixed thruster (its force), two per
    azimuth (its body-frame force components F_x, F_y), so that τ = B_e z is linear (Fossen 2011
    §12.3.2, extended thrust formulation)."""
    cols = []
    for t in thrusters:
        if t.azimuth:
            cols += [[1.0, 0.0, -t.y], [0.0, 1.0, t.x]]
        else:
            a = np.deg2rad(t.angle_deg)
            cols.append([np.cos(a), np.sin(a), t.x * np.sin(a) - t.y * np.cos(a)])
    return np.array(cols).T


def extended_to_command(thrusters: list[Thruster], z: np.ndarray) -> np.ndarray:
    """Extended vector z → thruster command (azimuth: force = |F|, angle = atan2(F_y, F_x))."""
    out, k = [], 0
    for t in thrusters:
        if t.azimuth:
            fx, fy = z[k], z[k + 1]
            out += [float(np.hypot(fx, fy)), float(np.arctan2(fy, fx))]
            k += 2
        else:
            out.append(float(z[k]))
            k += 1
    return np.array(out)
