"""Brute-force correlative scan matching (Olson, "Real-time correlative scan matching",
ICRA 2009), used to seed PLICP when the motion between scans is too large for its basin.

The reference points are rasterised into a grid whose cells hold the distance to the nearest
reference point (``scipy.ndimage.distance_transform_edt``); every candidate pose of a grid of
rotations × translations around the guess is scored by the mean capped distance of the
transformed current points, looked up in that field (vectorised over all candidates and points).
The best candidate seeds PLICP; the search itself is only as accurate as its grid.
"""

import numpy as np
from scipy.ndimage import distance_transform_edt


def distance_field(points: np.ndarray, resolution: float, margin: float):
    """(field, origin): distance [m] from each cell centre to the nearest point."""
    lo = points.min(axis=0) - margin
    hi = points.max(axis=0) + margin
    shape = np.ceil((hi - lo) / resolution).astype(int) + 1
    occupied = np.ones(shape[::-1], bool)  # rows = y, cols = x; True where no point
    cells = np.floor((points - lo) / resolution).astype(int)
    occupied[cells[:, 1], cells[:, 0]] = False
    return distance_transform_edt(occupied) * resolution, lo


def correlative_search(
    reference: np.ndarray,
    current: np.ndarray,
    guess=(0.0, 0.0, 0.0),
    linear_window: float = 1.2,
    linear_step: float = 0.1,
    angular_window: float = np.deg2rad(40.0),
    angular_step: float = np.deg2rad(2.0),
    resolution: float = 0.05,
    cap: float = 0.5,
    max_points: int = 200,
) -> tuple[np.ndarray, float]:
    """Best (t_x, t_y, θ) of ``current`` in ``reference``'s frame on the search grid around
    ``guess`` [m, m, rad], and its score (mean capped distance [m]; lower is better)."""
    field, lo = distance_field(reference, resolution, linear_window + cap)
    pts = current[:: max(1, len(current) // max_points)]
    thetas = guess[2] + np.arange(-angular_window, angular_window + 1e-9, angular_step)
    offs = np.arange(-linear_window, linear_window + 1e-9, linear_step)
    tx, ty = np.meshgrid(guess[0] + offs, guess[1] + offs, indexing="ij")
    tx, ty = tx.ravel(), ty.ravel()
    best, best_score = np.array(guess, float), np.inf
    rows, cols = field.shape
    for th in thetas:  # a loop over rotations only; points × translations are vectorised
        c, s = np.cos(th), np.sin(th)
        rx = c * pts[:, 0] - s * pts[:, 1]
        ry = s * pts[:, 0] + c * pts[:, 1]
        gx = np.floor((rx[None, :] + tx[:, None] - lo[0]) / resolution).astype(int)
        gy = np.floor((ry[None, :] + ty[:, None] - lo[1]) / resolution).astype(int)
        inside = (gx >= 0) & (gx < cols) & (gy >= 0) & (gy < rows)
        d = np.full(gx.shape, cap)
        d[inside] = np.minimum(field[gy[inside], gx[inside]], cap)
        score = d.mean(axis=1)
        k = int(np.argmin(score))
        if score[k] < best_score:
            best_score, best = float(score[k]), np.array([tx[k], ty[k], th])
    return best, best_score
