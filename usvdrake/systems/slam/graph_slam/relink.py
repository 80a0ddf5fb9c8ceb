"""The offline relink pass of :class:`GraphSlam` (:class:`RelinkMixin`): after the last scan,
:meth:`relink` matches every node by PLICP to the older nodes within ``relink_radius``,
adds the matches that pass its checks as loops and optimises the whole graph once more.
"""

import time

import numpy as np
from tqdm import tqdm

from usvdrake.systems.slam.graph_slam.graph import Constraint
from usvdrake.systems.slam.graph_slam.poses import between
from usvdrake.systems.slam.plicp import plicp


class RelinkMixin:
    """The offline relink pass of :class:`GraphSlam`."""

    def relink(self, progress: bool = False) -> int:
        """Link every node to the older nodes within ``relink_radius`` (index gap ≥ 2, at most
        ``relink_max_links`` of them, evenly spread over their indices) by PLICP from the
        graph's current relative pose, and optimise the whole graph (after merging a full
        optimisation still running; with ``relink_radius`` 0 nothing happens). The
        final estimate is already consistent to a few centimetres where the tracking and the
        loops reach; the links then tie every pass to its neighbours several metres away, which
        the chain of ~1 m steps and the few 4 m loops constrain only through their noise. A
        match is kept if it converges within ``relink_max_correction`` [m] of the current
        relative pose, with ``min_link_points`` pairs, an RMS residual within
        ``max_link_residual`` and a likelihood score of at least ``min_loop_score``; it joins
        as a loop, so GNC may reject it. ``progress``: a progress bar over the nodes matched
        against. Returns the links added."""
        if self.cfg.relink_radius <= 0 or len(self.nodes) < 3:
            return 0
        t0 = time.perf_counter()
        self.finish_full()  # the links are matched from the latest estimate
        linked = {(c.i, c.j) for c in self.constraints}
        pairs: dict[int, list[int]] = {}  # reference node -> the nodes matched to it
        for k in range(2, len(self.nodes)):
            near = self._near(k, 1, self.cfg.relink_radius, None)
            most = self.cfg.relink_max_links
            if 0 < most < len(near):  # evenly over the older nodes' indices: every pass keeps some
                near = [
                    near[j]
                    for j in np.unique(np.linspace(0, len(near) - 1, most).round().astype(int))
                ]
            for i in near:
                if (i, k) not in linked:
                    pairs.setdefault(i, []).append(k)
        added = 0
        last = self.nodes[-1]
        order = sorted(pairs)
        if progress:
            order = tqdm(order, unit="node", desc="relink")
        for i in order:
            a = self.nodes[i]
            for k in pairs[i]:
                b = self.nodes[k]
                guess = between(a.pose, b.pose)
                res = plicp(
                    a.points,
                    b.points,
                    initial=tuple(guess),
                    tree=a.tree,
                    max_distance=self.cfg.refine_max_distance,
                    trim=self.cfg.trim,
                )
                z = res.pose
                if not (
                    res.converged
                    and res.n_valid >= self.cfg.min_link_points
                    and res.residual <= self.cfg.max_link_residual
                    and np.hypot(*(z[:2] - guess[:2])) <= self.cfg.relink_max_correction
                    and a.field(self.cfg).score(b.points, z) >= self.cfg.min_loop_score
                ):
                    continue
                cov = self._tracking_covariance(a, b.points, res)
                self.constraints.append(Constraint(i, k, z, cov, False, "loop"))
                added += 1
            if a is not last:  # one field at a time (megabytes each); tracking keeps the last's
                a._field = None
        self.stats["relinks"] = added
        if added:
            self.full_pending = True
            self.optimise_pending()
        self.stats["relink_ms"] = (time.perf_counter() - t0) * 1e3
        return added
