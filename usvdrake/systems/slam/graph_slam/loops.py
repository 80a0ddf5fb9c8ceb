"""Links and loop closure of :class:`GraphSlam` (:class:`LoopMixin`): the node positions'
array the candidates are searched in, the loop candidates (optionally one per pass), the
submaps of neighbouring scans and :meth:`_link`, which matches a new node to an older one
(PLICP, after a correlative search for loops with ``loop_linear_window``) and adds the
constraint if the match passes the link or loop checks; with ``loop_confirm_nodes``, a loop is
held until a second loop between the same passes agrees with it (:meth:`_confirm_loops`).
"""

import numpy as np
from scipy.spatial import cKDTree

from usvdrake.systems.slam.correlative import correlative_match
from usvdrake.systems.slam.graph_slam.graph import Constraint
from usvdrake.systems.slam.graph_slam.poses import between, compose
from usvdrake.systems.slam.likelihood_field import LikelihoodField
from usvdrake.systems.slam.plicp import plicp, rot

# loop candidates' fields kept for reuse (LoopMixin._loop_field): two new nodes' candidates (up
# to loop_max_chains each); a 700 x 700-cell field with its four bound tables is ~20 MB
LOOP_FIELDS = 16


class LoopMixin:
    """Dense links and loop closures of :class:`GraphSlam`."""

    def _sync_xy(self, changed=()) -> None:
        """Bring the node positions' array up to date: rows for the nodes added since (by
        ``_add_node`` or behind its back), and the nodes ``changed`` that got a new pose. The
        loop candidates' search reads it instead of gathering every node's pose per new node."""
        n = len(self._xy)
        if n < len(self.nodes):
            self._xy = np.vstack([self._xy, [node.pose[:2] for node in self.nodes[n:]]])
        if len(changed):
            self._xy[list(changed)] = [self.nodes[k].pose[:2] for k in changed]

    def _loop_candidates(self, k: int) -> list[int]:
        """Older nodes (index gap > ``loop_index_gap``) within ``loop_radius`` of node k; with
        ``loop_per_chain``, only the nearest of each run of consecutive such nodes (one pass
        of the vessel), at most ``loop_max_chains`` of them, nearest first."""
        return self._near(
            k,
            self.cfg.loop_index_gap,
            self.cfg.loop_radius,
            self.cfg.loop_max_chains if self.cfg.loop_per_chain else None,
        )

    def _near(self, k: int, gap: int, radius: float, chains: int | None) -> list[int]:
        """Nodes whose index is more than ``gap`` below k within ``radius`` [m] of node k; with
        ``chains``, only the nearest of each run of consecutive such nodes (one pass of the
        vessel), at most ``chains`` of them, nearest first."""
        old = np.arange(max(0, k - gap))
        if not len(old):
            return []
        self._sync_xy()
        d = np.hypot(*(self._xy[old] - self.nodes[k].pose[:2]).T)
        near = old[d <= radius]
        if chains is None or not len(near):
            return list(near)
        runs = np.split(near, np.flatnonzero(np.diff(near) > 1) + 1)
        best = [int(run[np.argmin(d[run])]) for run in runs]
        best.sort(key=lambda i: d[i])
        return best[:chains]

    def _submap(self, k: int, indices) -> np.ndarray:
        """The scans of the nodes ``indices`` (those that exist) in node k's frame."""
        base = self.nodes[k].pose
        parts = []
        for j in indices:
            if 0 <= j < len(self.nodes):
                x, y, th = between(base, self.nodes[j].pose)
                parts.append(self.nodes[j].points @ rot(th).T + (x, y))
        return np.vstack(parts)

    def _loop_field(self, i: int) -> tuple[np.ndarray, LikelihoodField]:
        """Loop candidate i's submap (``loop_submap`` nodes either side, in its frame) and its
        likelihood field, kept for the next searches (the last ``LOOP_FIELDS`` used) while
        those nodes' poses and scans are the same: the same field, built once. Consecutive new
        nodes often search the same candidate (turning on the spot, an earlier pass driven more
        slowly): raw Freiburg 079 asked for 15 822 fields, 10 083 of them distinct."""
        h = self.cfg.loop_submap
        nodes = self.nodes[max(0, i - h) : i + h + 1]
        # the scans by identity (the entry holds them, so their ids stay theirs): a copy of the
        # SLAM, sharing this cache, may have other scans there at the same poses
        poses = np.array([n.pose for n in nodes]).tobytes()
        key = (i, poses, tuple(id(n.points) for n in nodes))
        kept = self._loop_fields.get(key)
        # (ids alone could coincide after a pickled SLAM is loaded elsewhere: check the scans)
        if kept is not None and all(a is n.points for a, n in zip(kept[0], nodes, strict=True)):
            self._loop_fields.move_to_end(key)
            self.stats["loop_fields_reused"] += 1
            return kept[1], kept[2]
        submap = self._submap(i, range(i - h, i + h + 1))
        field = LikelihoodField.build(
            submap,
            self.cfg.search_resolution,
            self.cfg.search_sigma,
            margin=self.cfg.loop_linear_window + 1.0,
        )
        self._loop_fields[key] = ([n.points for n in nodes], submap, field)
        while len(self._loop_fields) > LOOP_FIELDS:
            self._loop_fields.popitem(last=False)
        return submap, field

    def _confirm_loops(self, k: int, found: list[Constraint]) -> bool:
        """Admit the loops node k ``found`` that a loop held or admitted within the last
        ``loop_confirm_nodes`` nodes agrees with (:meth:`_loops_agree`), with the held ones
        they confirm; hold the others. Held loops older than that are dropped
        (``stats["unconfirmed_loops"]``). Returns whether any loop joined the graph."""
        span = self.cfg.loop_confirm_nodes
        held = [(n, c) for n, c in self._held if k - n <= span]
        self.stats["unconfirmed_loops"] += len(self._held) - len(held)
        admitted = [c for c in self._admitted if k - c.j <= span]
        joined = []
        for c in found:
            partners = [h for h in held if self._loops_agree(c, h[1])]
            if partners or any(self._loops_agree(c, a) for a in admitted):
                held = [h for h in held if not any(h is p for p in partners)]
                joined += [h[1] for h in partners] + [c]
                admitted += [h[1] for h in partners] + [c]
            else:
                held.append((k, c))
        self.constraints.extend(joined)
        self._held, self._admitted = tuple(held), tuple(admitted)
        return bool(joined)

    def _loops_agree(self, a: Constraint, b: Constraint) -> bool:
        """Whether loops a and b, between nearby nodes (≤ 50 apart) of the same two passes, put
        b's newer node at the same pose in a's older node's frame, each way round the short
        cycle they make with the graph's own chains, within ``loop_confirm_tolerance``."""
        if abs(a.i - b.i) > 50 or (a.i, a.j) == (b.i, b.j):
            return False
        nodes = self.nodes
        via_a = compose(a.z, between(nodes[a.j].pose, nodes[b.j].pose))
        via_b = compose(between(nodes[a.i].pose, nodes[b.i].pose), b.z)
        d = between(via_b, via_a)  # (its heading wrapped)
        tol = self.cfg.loop_confirm_tolerance
        return bool(np.hypot(d[0], d[1]) <= tol[0] and abs(d[2]) <= tol[1])

    def _link(
        self, i: int, k: int, robust: bool, kind: str, search: bool = False, into=None
    ) -> bool:
        """Match node k to node i (see the module); if it passes, add the constraint to the
        graph, or to the list ``into`` when given. Returns whether it passed."""
        a, b = self.nodes[i], self.nodes[k]
        guess = between(a.pose, b.pose)
        rotation_search, pairing = search, 1.0  # PLICP's own rotation search, default pairing
        reference, tree, searched = a.points, a.tree, False
        if search and self.cfg.loop_linear_window > 0:
            h = self.cfg.loop_submap
            submap, candidate = self._loop_field(i)
            match = correlative_match(
                candidate,
                self._submap(k, range(k - h, k + 1)),
                guess,
                self.cfg.loop_linear_window,
                self.cfg.loop_angular_window,
                distinct=self.cfg.loop_distinct,
                # only whether a rival comes that close matters, not its score or the best one
                rival_above=min(max(self.cfg.max_loop_ambiguity, 0.0), 1.0),
                first_rival=True,
                # nor any pose that scores below a loop's least: that search fails sooner
                min_score=min(max(self.cfg.min_loop_score, 0.0), 1.0),
            )
            guess = match.pose
            # a weak fit, or one the scene repeats (a corridor): not a loop
            if (
                match.score < self.cfg.min_loop_score
                or match.runner_up > self.cfg.max_loop_ambiguity * match.score
            ):
                self.stats["failed_matches"] += 1
                return False
            if self.cfg.loop_rematch_window > 0:
                guess = correlative_match(
                    candidate,
                    b.points,
                    guess,
                    self.cfg.loop_rematch_window,
                    self.cfg.loop_rematch_angle,
                ).pose
            rotation_search, pairing, searched = False, self.cfg.refine_max_distance, True
            if self.cfg.loop_refine_submap:
                # the new scan refined against the candidate's whole submap (each of its scans
                # in beam order, so PLICP's scan-order neighbours stay on one scan; the jumps
                # between scans exceed max_segment): far more overlap than its single scan
                reference, tree = submap, cKDTree(submap)
        res = plicp(
            reference,
            b.points,
            initial=tuple(guess),
            tree=tree,
            rotation_search=rotation_search,
            max_distance=pairing,
        )
        loop = kind == "loop"
        need = self.cfg.min_loop_points if loop else self.cfg.min_link_points
        limit = self.cfg.max_loop_residual if loop else self.cfg.max_link_residual
        # a searched loop starts in the right basin: PLICP cycling between two correspondence
        # sets at the end (not converged) still leaves a good pose, which the residual checks
        settled = res.converged or (searched and self.cfg.loop_refine_submap)
        if not (settled and res.n_valid >= need and res.residual <= limit):
            self.stats["failed_matches"] += 1
            return False
        z = res.pose
        # (against a submap, Censi's covariance takes every reference point's range noise along
        # its bearing from node i, though its neighbours' points were ranged from elsewhere)
        constraint = Constraint(i, k, z, self._covariance(reference, b.points, res), robust, kind)
        (self.constraints if into is None else into).append(constraint)
        return True
