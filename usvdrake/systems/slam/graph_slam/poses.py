"""Planar pose algebra shared by the graph SLAM and its callers: :func:`compose` (a ⊕ b),
:func:`between` (a⁻¹ ⊕ b, also row by row for stacks), :func:`compose_covariance` (first-
order compounding of two uncertain poses), :func:`body_pose` (the vessel's pose from its
sensor's) and :func:`deskew_scan` (a scan's points moved to its last beam's frame under a
constant twist).
"""

import numpy as np

from usvdrake.systems.slam.scan_registration3d import deskew


def compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a ⊕ b for planar poses (x, y, θ)."""
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def deskew_scan(points: np.ndarray, age: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """2D points (n × 2) [m], each measured ``age`` [s] before the scan's time in the sensor
    frame of its firing instant, expressed in the frame at the scan's time, the sensor moving
    with the constant twist (v_x, v_y [m/s], ω [rad/s]) of its own frame: the planar case of
    :func:`usvdrake.systems.slam.scan_registration3d.deskew`."""
    vx, vy, w = np.asarray(twist, float)
    p3 = np.column_stack([points, np.zeros(len(points))])
    return deskew(p3, age, np.array([0.0, 0.0, w]), np.array([vx, vy, 0.0]))[:, :2]


def body_pose(sensor_pose: np.ndarray, mount: np.ndarray) -> np.ndarray:
    """The vessel's pose (x, y, θ) from its sensor's, the sensor mounted at ``mount`` = (x, y,
    θ) in the body frame: sensor ⊕ mount⁻¹."""
    return compose(np.asarray(sensor_pose, float), between(np.asarray(mount, float), np.zeros(3)))


def compose_covariance(a, cov_a, b, cov_b) -> tuple[np.ndarray, np.ndarray]:
    """(a ⊕ b, its covariance) to first order for independent planar poses a, b with
    covariances ``cov_a``, ``cov_b`` (each in its own earlier frame): J_a Σ_a J_aᵀ + J_b Σ_b
    J_bᵀ, J_a = ∂(a ⊕ b)/∂a = [[1, 0, −(R_a b)_y], [0, 1, (R_a b)_x], [0, 0, 1]], J_b =
    diag(R_a, 1) (Smith, Self & Cheeseman 1990's compounding)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c, s = np.cos(a[2]), np.sin(a[2])
    rb = np.array([c * b[0] - s * b[1], s * b[0] + c * b[1]])
    j_a = np.array([[1.0, 0.0, -rb[1]], [0.0, 1.0, rb[0]], [0.0, 0.0, 1.0]])
    j_b = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cov = j_a @ np.asarray(cov_a, float) @ j_a.T + j_b @ np.asarray(cov_b, float) @ j_b.T
    return compose(a, b), cov


def between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a⁻¹ ⊕ b: b expressed in a's frame; for stacks of poses (… × 3) row by row."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    c, s = np.cos(a[..., 2]), np.sin(a[..., 2])
    dx, dy = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]
    dth = np.angle(np.exp(1j * (b[..., 2] - a[..., 2])))
    return np.stack([c * dx + s * dy, -s * dx + c * dy, dth], axis=-1)
