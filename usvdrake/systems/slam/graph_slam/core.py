"""The graph SLAM object :class:`GraphSlam`, composed of the per-job mixins (tracking,
odometry, loops, relink, optimisation): its state (nodes, constraints, current pose,
statistics, the log-odds map), the creation of nodes with their consecutive, odometry, link
and loop constraints, the scan-SLAM backend protocol of ``LidarSlam2D``, the map's
rendering and re-rendering of moved nodes, and the structural ``copy.deepcopy``.
"""

import copy
import time
from collections import OrderedDict

import numpy as np
from scipy.spatial import cKDTree

from usvdrake.systems.slam.graph_slam.config import GraphSlamConfig
from usvdrake.systems.slam.graph_slam.graph import Constraint, Node, _AppendLog
from usvdrake.systems.slam.graph_slam.loops import LoopMixin
from usvdrake.systems.slam.graph_slam.odometry import OdometryMixin
from usvdrake.systems.slam.graph_slam.optimisation import OptimisationMixin
from usvdrake.systems.slam.graph_slam.poses import between, deskew_scan
from usvdrake.systems.slam.graph_slam.relink import RelinkMixin
from usvdrake.systems.slam.graph_slam.tracking import TrackingMixin
from usvdrake.systems.slam.occupancy_mapping import LogOddsGrid
from usvdrake.systems.slam.robust_kernel import gtsam_barron


class GraphSlam(TrackingMixin, OdometryMixin, LoopMixin, RelinkMixin, OptimisationMixin):
    def __init__(self, cfg: GraphSlamConfig, initial_pose=(0.0, 0.0, 0.0)):
        self.cfg = cfg
        self.nodes: list[Node] = []
        self.constraints: list[Constraint] = []
        self.pose = np.asarray(initial_pose, float)
        self._rel = np.zeros(3)  # current scan relative to the last node
        self._last_step = np.zeros(3)
        self._odometry: np.ndarray | None = None  # odometry pose of the last tracked scan
        self._odometry_from: int | None = None  # the node the next odometry constraint is from
        # (scan distance, odometry distance, scan turn, odometry turn) summed over the steps the
        # scans measured well: the odometry's calibration (_calibrate_odometry)
        self._odometry_sums = np.zeros(4)
        # (pose, covariance) of the scans' consecutive steps since the odometry span started
        self._odometry_chain: tuple[np.ndarray, np.ndarray] | None = None
        self._last_t: float | None = None  # [s] time of the last tracked scan
        self._last_dt = 0.0  # [s] between the last two tracked scans
        self._twist: np.ndarray | None = None  # (v_x, v_y, ω) of the sensor, smoothed
        self._fail_streak = 0  # tracking matches failed in a row
        self._loop_from: int | None = None  # the last node that looked for loops (loop_spacing)
        self._rejected: frozenset[int] = frozenset()  # loop constraints GNC called outliers
        # (node that found it, loop) not yet confirmed, and the loops admitted lately: tuples,
        # replaced and never changed in place, so copies may share them (loop_confirm_nodes)
        self._held: tuple = ()
        self._admitted: tuple = ()
        # [m] (x, y) of every node, kept with Node.pose: the loop candidates' distances
        self._xy = np.zeros((0, 2))
        # loop candidates' (scans, submap, field) by (node, submap poses, scans' ids), least
        # recently used first: shared by copies, which the scans' identity keeps apart
        # (LoopMixin._loop_field)
        self._loop_fields: OrderedDict = OrderedDict()
        res = cfg.map_resolution
        shape = (int(cfg.map_size[1] / res), int(cfg.map_size[0] / res))
        self.map = LogOddsGrid(tuple(cfg.map_origin), res, shape)
        self.stats = {
            "tracking_ms": [],
            "optimisation_ms": [],
            "full_optimisation_ms": [],
            "full_wait_ms": [],  # the scans' waits for a full optimisation still solving
            "loops": 0,
            "failed_matches": 0,
            "odometry_rejected": 0,  # odometry constraints left out by odometry_gate
            "unconfirmed_loops": 0,  # loops dropped for want of a second (loop_confirm_nodes)
            "loop_fields_reused": 0,  # loop searches whose field was kept from an earlier one
        }
        self.full_pending = False
        self._full_job = None  # (job, problem, node count) of the running full optimisation
        self._anchors, self._n_anchors = _AppendLog(), 0  # (time, node, pose relative to it)
        gtsam_barron(cfg.alpha, cfg.c)  # a bad α or c fails here, not at the first solve

    # --- nodes and constraints ----------------------------------------------------------------
    def _add_node(self, pose, points, ranges, angles, t) -> Node:
        node = Node(pose, points, ranges, angles, t, tree=cKDTree(points))
        node.odometry = self._odometry
        node.first_constraint = len(self.constraints)
        self.nodes.append(node)
        self._sync_xy()
        self._render(node)
        return node

    def _new_node(self, points, ranges, angles, t, rel, cov) -> None:
        prev = len(self.nodes) - 1
        # only the latest node is searched by tracking: its predecessor's likelihood field
        # (megabytes per scan) goes, or a long log's fields fill the memory
        self.nodes[prev]._field = None
        node = self._add_node(self.pose.copy(), points, ranges, angles, t)
        k = len(self.nodes) - 1
        if cov is None:
            cov = self._floor * 100.0
        self.constraints.append(Constraint(prev, k, rel.copy(), cov, True, "consecutive"))
        self._calibrate_odometry(prev, k, rel, cov)
        self._odometry_constraint(prev, k, rel, cov)
        self._rel = np.zeros(3)
        lo = max(0, k - self.cfg.window)
        for i in range(lo, prev):
            other = self.nodes[i]
            if np.hypot(*(other.pose[:2] - node.pose[:2])) <= self.cfg.link_radius:
                self._link(i, k, robust=False, kind="link")
        loop, found = False, [] if self.cfg.loop_confirm_nodes > 0 else None
        for i in self._loop_candidates(k) if self._loop_due(k) else ():
            loop |= self._link(
                i, k, robust=self.cfg.loop_robust, kind="loop", search=True, into=found
            )
        if found is not None:
            loop = self._confirm_loops(k, found)
        t0 = time.perf_counter()
        self.optimise(full=False)
        self.stats["optimisation_ms"].append((time.perf_counter() - t0) * 1e3)
        if loop:
            self.stats["loops"] += 1
            self.full_pending = True  # the whole graph, at the caller's pace (optimise_pending)

    def _loop_due(self, k: int) -> bool:
        """Whether node ``k`` looks for loops: always, or with ``loop_spacing`` once the graph
        has gone that far (or turned 1 rad) since the last node that looked."""
        if self.cfg.loop_spacing <= 0:
            return True
        last = self._loop_from
        if last is not None:
            d = between(self.nodes[last].pose, self.nodes[k].pose)
            if np.hypot(d[0], d[1]) < self.cfg.loop_spacing and abs(d[2]) < 1.0:
                return False
        self._loop_from = k
        return True

    # --- the scan-SLAM backend protocol of ``LidarSlam2D`` ------------------------------------
    def process_scan(self, scan, max_range: float | None = None, odometry=None) -> None:
        a, r = scan.angles, np.asarray(scan.ranges, float)
        with np.errstate(invalid="ignore"):  # NaN ranges (a broken driver): not returns
            v = np.asarray(scan.valid, bool) & np.isfinite(r) & (r > 0)
        r = np.where(v, r, np.inf)  # what the map renders: no return
        points = np.column_stack([r[v] * np.cos(a[v]), r[v] * np.sin(a[v])])
        if self.cfg.deskew and scan.time_increment > 0 and self._twist is not None:
            age = (len(r) - 1 - np.flatnonzero(v)) * scan.time_increment
            points = deskew_scan(points, age, self._twist)
            # the rays the map renders follow the points (r, a are this call's own arrays)
            r[v], a[v] = (
                np.hypot(points[:, 0], points[:, 1]),
                np.arctan2(points[:, 1], points[:, 0]),
            )
        self.process(points, r, a, scan.time, odometry)

    @property
    def sensor_pose(self) -> np.ndarray:
        return self.pose

    def pose_covariance(self) -> np.ndarray:
        """The covariance of the latest node's consecutive constraint (Censi's, or the
        tracking field's spread with ``landscape_temperature``)."""
        for c in reversed(self.constraints):
            if c.kind == "consecutive":
                return c.cov
        return self._floor

    def occupancy(self):
        return self.map.to_occupancy_grid()

    # --- map ------------------------------------------------------------------------------------
    def _render(self, node: Node) -> None:
        if self.cfg.live_map:  # else render_map() draws it at its final pose
            self._draw(node)

    def _draw(self, node: Node) -> None:
        self.map.insert_scan(node.pose, node.ranges, node.angles, self.cfg.max_range)
        node.rendered_pose = node.pose.copy()

    def render_map(self) -> None:
        """The map drawn afresh: every node's scan at its present pose (what ``live_map`` =
        False leaves to the end of a run)."""
        self.map = LogOddsGrid(self.map.origin, self.map.resolution, self.map.shape)
        for node in self.nodes:
            self._draw(node)

    def _rerender_moved(self, indices) -> None:
        """Re-render the scans of the nodes ``indices`` whose pose has moved from the one they
        were rendered at by more than ``rerender_translation`` / ``rerender_rotation``."""
        if not len(indices) or not self.cfg.live_map:
            return
        nodes = [self.nodes[k] for k in indices]
        d = between([n.rendered_pose for n in nodes], [n.pose for n in nodes])
        moved = (np.hypot(d[:, 0], d[:, 1]) > self.cfg.rerender_translation) | (
            np.abs(d[:, 2]) > self.cfg.rerender_rotation
        )
        for node in (n for n, m in zip(nodes, moved, strict=True) if m):
            self.map.remove_scan(node.rendered_pose, node.ranges, node.angles, self.cfg.max_range)
            self._render(node)

    def trajectory(self) -> np.ndarray:
        """Node poses (n × 3)."""
        return np.array([n.pose for n in self.nodes])

    def __deepcopy__(self, memo) -> "GraphSlam":
        """A structural copy: node scans (points, ranges, angles, KD-tree) and constraints never
        change after creation, so copies share them; poses, the map's arrays and the statistics
        are copied. Drake copies a Context's abstract state on every update, so this keeps a
        LeafSystem's state independent per Context; the map's arrays are copied on write."""
        other = copy.copy(self)
        other.nodes = [copy.copy(n) for n in self.nodes]
        for n in other.nodes:
            n.pose = n.pose.copy()
            n.rendered_pose = None if n.rendered_pose is None else n.rendered_pose.copy()
        other.constraints = list(self.constraints)
        other._xy = self._xy.copy()
        other.pose, other._rel, other._last_step = (
            self.pose.copy(),
            self._rel.copy(),
            self._last_step.copy(),
        )
        other.map = self.map.shared_copy()
        other.stats = {k: (list(v) if isinstance(v, list) else v) for k, v in self.stats.items()}
        return other
