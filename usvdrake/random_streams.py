"""Seeded, order-independent random numbers for every noise source in a simulation.

Each source draws its k-th sample from ``numpy.random.default_rng([seed, stream, k])``: the
same scenario seed gives the same numbers bit for bit, whatever else ran before and however
often a diagram is re-simulated, and no generator has to live in the Context. Streams:
environment 1-3, lidars 20 and 30, GPS 101-103, IMU 201-202, thrust 301, identification data
401-403, pose 501.
"""

import numpy as np


def generator(seed: int, stream: int, k: int) -> np.random.Generator:
    """The generator of step k of a stream."""
    return np.random.default_rng([seed, stream, k])


def white_vector(seed: int, stream: int, k: int, n: int) -> np.ndarray:
    """n standard-normal samples for step k of a stream."""
    return generator(seed, stream, k).standard_normal(n)


def white_sample(seed: int, stream: int, k: int) -> float:
    """One standard-normal sample for step k of a stream."""
    return float(white_vector(seed, stream, k, 1)[0])
