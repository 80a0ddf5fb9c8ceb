"""The graph's data: :class:`Node` (a node's pose, its scan's points, rays and KD-tree, its
odometry and its lazily built likelihood field), :class:`Constraint` (a relative-pose
measurement between two nodes with its covariance, robustness and kind) and
:class:`_AppendLog` (the per-scan anchor log copies of a :class:`GraphSlam` share).
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from usvdrake.systems.slam.graph_slam.config import GraphSlamConfig
from usvdrake.systems.slam.likelihood_field import LikelihoodField


class _AppendLog:
    """An append-only list shared by copies of a :class:`GraphSlam`; each copy remembers how
    many entries are its own and forks the list if another copy appended first."""

    def __init__(self, items=None):
        self.items = [] if items is None else items


@dataclass
class Node:
    pose: np.ndarray  # (x, y, θ) in the map frame
    points: np.ndarray  # (n, 2) scan points, sensor frame
    ranges: np.ndarray  # for the map
    angles: np.ndarray
    time: float
    rendered_pose: np.ndarray | None = None  # the pose its scan is in the map with
    # index in GraphSlam.constraints of its first constraint: every constraint is added with
    # its newest node as ``j``, so the constraints touching nodes ≥ k are those from node k's on
    first_constraint: int = 0
    tree: cKDTree | None = None
    odometry: np.ndarray | None = None  # the odometry pose its scan came with, if any
    _field: LikelihoodField | None = None

    def field(self, cfg: "GraphSlamConfig") -> LikelihoodField:
        """The likelihood field of its scan for the tracking search (built on first use,
        shared by copies, dropped once a newer node takes over; loops search fields of
        submaps)."""
        if self._field is None:
            self._field = LikelihoodField.build(
                self.points,
                cfg.search_resolution,
                cfg.search_sigma,
                margin=cfg.search_linear_window + 1.0,
            )
        return self._field


@dataclass
class Constraint:
    i: int
    j: int
    z: np.ndarray  # (x, y, θ) of node j in node i's frame
    cov: np.ndarray  # 3 × 3
    robust: bool
    kind: str  # "consecutive", "odometry", "link", "loop"
    # an odometry constraint's step as the wheels measured it, before the calibration: each
    # optimisation scales it by the calibration of the moment (GraphSlam._measurement); its z
    # and cov are as tied (and gated), in the calibration of that moment
    raw: np.ndarray | None = None
