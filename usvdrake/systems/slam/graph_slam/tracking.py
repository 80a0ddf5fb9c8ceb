"""Per-scan tracking of :class:`GraphSlam` (:class:`TrackingMixin`): :meth:`process` matches
each scan to the latest node by PLICP from the constant-velocity (or odometry) guess,
re-seeds a poor match by the correlative search (optionally refined on its likelihood field,
Hector's Gauss-Newton), coasts through failed matches and decides when a scan becomes a node;
with it the match scores, the consecutive constraints' covariances (Censi's or the tracking
field's spread, above the ``min_sigma`` floor) and the log of every tracked scan's pose
relative to its node behind :meth:`final_trajectory`.
"""

import time

import numpy as np

from usvdrake.systems.slam.censi_covariance import plicp_covariance
from usvdrake.systems.slam.correlative import correlative_match, lateral_motion, match_covariance
from usvdrake.systems.slam.graph_slam.graph import Node, _AppendLog
from usvdrake.systems.slam.graph_slam.poses import between, compose
from usvdrake.systems.slam.hector import match_scan
from usvdrake.systems.slam.plicp import PlicpResult, plicp, plicp_at


class TrackingMixin:
    """Scan-to-node tracking and the tracking covariances of :class:`GraphSlam`."""

    # --- per scan -----------------------------------------------------------------------------
    def process(
        self,
        points: np.ndarray,
        ranges: np.ndarray,
        angles: np.ndarray,
        t: float,
        odometry=None,
    ) -> np.ndarray:
        """Track one scan; returns the current pose (x, y, θ). ``odometry``: the sensor's pose
        (x, y, θ) by wheel odometry when the scan was taken, in the odometry's own frame (only
        its steps are used), or None. Its steps between nodes, scaled by what the scans
        measured (:attr:`odometry_scale`), become constraints (``odometry_span``,
        ``odometry_sigma``); with ``odometry_seed`` its step since the previous scan also seeds
        a tracking match."""
        t0 = time.perf_counter()
        odometry_step = self._odometry_step(odometry)
        if odometry_step is not None:
            odometry_step = self._calibrated(odometry_step)
        motion = self._last_step if odometry_step is None else odometry_step
        if len(points) < self.cfg.min_link_points:
            # too few returns to match (blinded, NaN): coast on the odometry or the constant
            # velocity
            self.stats["failed_matches"] += 1
            if self.nodes:
                self._rel = compose(self._rel, motion)
                self.pose = compose(self.nodes[-1].pose, self._rel)
                self._last_t = t  # the next step is measured from this coasted pose
                self._record(t)
            return self.pose.copy()
        if not self.nodes:
            self._add_node(self.pose.copy(), points, ranges, angles, t)
            self._record(t)
            self.stats["tracking_ms"].append((time.perf_counter() - t0) * 1e3)
            return self.pose.copy()
        last = self.nodes[-1]
        guess = compose(self._rel, self._last_step)  # constant velocity
        res = plicp(last.points, points, initial=tuple(guess), tree=last.tree, trim=self.cfg.trim)
        if odometry_step is not None and self.cfg.odometry_seed:
            # the odometry's guess, preferred unless the constant velocity's fits clearly better
            guess = compose(self._rel, odometry_step)
            by_odometry = plicp(
                last.points, points, initial=tuple(guess), tree=last.tree, trim=self.cfg.trim
            )
            if by_odometry.n_valid >= self.cfg.min_link_points and (
                res.n_valid < self.cfg.min_link_points
                or self._score(last, points, res)
                <= self._score(last, points, by_odometry) + self.cfg.search_prior_margin
            ):
                res = by_odometry
        trigger = self.cfg.correlative_trigger * self.cfg.max_link_residual
        if res.n_valid < self.cfg.min_link_points or res.residual > trigger:
            # a failed match from the constant-velocity guess: seed PLICP by a correlative search
            # over rotations × translations (Olson 2009) and keep the better of the two
            centre = self._rel if self.cfg.search_from_rest else guess
            linear, angular = self.cfg.search_linear_window, self.cfg.search_angular_window
            if odometry_step is not None and min(self.cfg.odometry_search_window) > 0:
                centre = compose(self._rel, odometry_step)
                linear, angular = self.cfg.odometry_search_window
            seed = correlative_match(
                last.field(self.cfg),
                points,
                centre,
                linear,
                angular,
                prior_from=self._rel,
                lateral_weight=self.cfg.lateral_weight,
            ).pose
            # the seed is good to a grid cell: refine it locally, PLICP must not wander off
            retry = plicp(
                last.points,
                points,
                initial=tuple(seed),
                tree=last.tree,
                max_distance=self.cfg.refine_max_distance,
                trim=self.cfg.trim,
            )
            if self.cfg.field_refine_unconverged and not retry.converged:
                alt = self._field_refine(last, points, seed)
                if alt.n_valid >= 3 and self._score(last, points, alt) > self._score(
                    last, points, retry
                ):
                    retry = alt
            # no time since the last scan (identical stamps): no motion model to favour
            timed = self._last_t is not None and t > self._last_t
            margin = self.cfg.search_prior_margin if timed else 0.0
            if retry.n_valid >= self.cfg.min_link_points and (
                res.n_valid < self.cfg.min_link_points
                or self._score(last, points, retry) > self._score(last, points, res) + margin
            ):
                res = retry
        failed = (
            res.n_valid < self.cfg.min_link_points
            or not np.isfinite(res.theta)
            or not res.residual <= self.cfg.max_track_residual
            or (
                self.cfg.min_track_score > 0
                and last.field(self.cfg).score(points, res.pose) < self.cfg.min_track_score
            )
        )
        if failed:
            self.stats["failed_matches"] += 1
            self._fail_streak += 1
            rel = guess
        else:
            self._fail_streak = 0
            rel = res.pose
        self._last_step = between(self._rel, rel)
        self._last_dt = t - self._last_t if self._last_t is not None else 0.0
        self._last_t = t
        if self._last_dt > 0:  # the sensor's twist, smoothed over ~5 scans (PLICP's step noise)
            twist = self._last_step / self._last_dt
            self._twist = (
                twist if self._twist is None else self._twist + 0.2 * (twist - self._twist)
            )
        self._rel = rel
        self.pose = compose(last.pose, rel)
        if not failed and (
            np.hypot(rel[0], rel[1]) > self.cfg.node_translation
            or abs(rel[2]) > self.cfg.node_rotation
        ):
            cov = (
                self._tracking_covariance(last, points, res)
                if res.n_valid >= self.cfg.min_link_points
                else None
            )
            self._new_node(points, ranges, angles, t, rel, cov)
        elif failed and self._fail_streak >= self.cfg.reanchor_after:
            # the last node itself may be the problem (e.g. a garbage first scan): start a new
            # reference here, at the coasted pose, tied to the last by a weak constraint
            self._new_node(points, ranges, angles, t, rel, None)
            self._fail_streak = 0
        self._record(t)
        self.stats["tracking_ms"].append((time.perf_counter() - t0) * 1e3)
        return self.pose.copy()

    def _odometry_step(self, odometry) -> np.ndarray | None:
        """The odometry step since the last tracked scan (None without odometry now or then),
        and ``odometry`` kept for the next scan and the next node."""
        previous = self._odometry
        self._odometry = None
        if odometry is None:
            return None
        odometry = np.asarray(odometry, float).reshape(-1)
        if odometry.shape != (3,):
            raise ValueError(f"GraphSlam.process: odometry must be (x, y, θ), got {odometry}")
        if not np.all(np.isfinite(odometry)):
            return None  # a broken reading: as if there were none
        self._odometry = odometry
        return None if previous is None else between(previous, odometry)

    def _field_refine(self, node: Node, points: np.ndarray, seed) -> PlicpResult:
        """``points`` matched to ``node``'s scan by Gauss-Newton on its tracking likelihood
        field (values in [0, 1], 1 on the surfaces: the map M of Kohlbrecher 2011 eqs. 4-11,
        bilinearly interpolated, :func:`hector.match_scan`) from ``seed``, as a
        :class:`PlicpResult` at that pose (:func:`plicp_at`). The field is the objective the
        correlative search maximised on its grid, so this ascends to its maximum between the
        grid's cells instead of sliding to PLICP's distant fixed point."""
        field = node.field(self.cfg)
        pose = match_scan(
            field.fine, tuple(field.origin), field.resolution, points, seed, iterations=20
        )[0]
        return plicp_at(
            node.points,
            points,
            pose,
            max_distance=self.cfg.refine_max_distance,
            trim=self.cfg.trim,
            tree=node.tree,
        )

    def _score(self, node: Node, points: np.ndarray, res) -> float:
        """Likelihood score of ``points`` at a match result in ``node``'s field, less the
        sideways-motion penalty (``lateral_weight``) of the step from the previous scan."""
        pose = res.pose
        penalty = self.cfg.lateral_weight * lateral_motion(self._rel, pose) ** 2
        return node.field(self.cfg).score(points, pose) - penalty

    def _record(self, t: float) -> None:
        if len(self._anchors.items) != self._n_anchors:  # another copy appended: fork
            self._anchors = _AppendLog(self._anchors.items[: self._n_anchors])
        self._anchors.items.append((t, len(self.nodes) - 1, self._rel.copy()))
        self._n_anchors += 1

    def final_trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """(times, poses n × 3) of every tracked scan, re-expressed from its node's current
        (optimised) pose — the SLAM's final trajectory estimate, as benchmarks score it."""
        items = self._anchors.items[: self._n_anchors]
        if not items:
            return np.zeros(0), np.zeros((0, 3))
        t = np.array([i[0] for i in items])
        return t, np.array([compose(self.nodes[k].pose, rel) for _, k, rel in items])

    @property
    def _floor(self) -> np.ndarray:
        """The constraints' covariance floor, diag(``min_sigma``²)."""
        return np.diag(np.square(self.cfg.min_sigma))

    def _tracking_covariance(self, node: Node, points: np.ndarray, res) -> np.ndarray:
        """The consecutive constraint's covariance: Censi's, or with ``landscape_temperature``
        the spread of ``node``'s tracking field (:func:`match_covariance`) above the
        ``min_sigma`` floor."""
        if self.cfg.landscape_temperature <= 0:
            return self._covariance(node.points, points, res)
        pose = res.pose
        field = node.field(self.cfg)
        spread = match_covariance(field, points, pose, self.cfg.landscape_temperature)
        return spread + self._floor

    def _covariance(self, ref, cur, res) -> np.ndarray:
        try:
            cov = plicp_covariance(ref, cur, res, self.cfg.range_sigma)
        except np.linalg.LinAlgError:
            cov = self._floor * 100.0
        if not np.all(np.isfinite(cov)):
            return self._floor * 100.0
        return cov + self._floor
