"""Angle helpers shared by guidance, control, estimation and analysis (plain numpy)."""

import numpy as np


def wrap_angle(a):
    """Wrap to (−π, π] [rad]; works on scalars and arrays."""
    return np.arctan2(np.sin(a), np.cos(a))
