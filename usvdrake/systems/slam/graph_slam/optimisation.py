"""Pose-graph optimisation of :class:`GraphSlam` (:class:`OptimisationMixin`): the window's or
the whole graph's problem as plain data (:meth:`_problem`), solved here (:meth:`optimise`)
or, for the full optimisations loops ask for, started on a snapshot in the worker process
and merged later (:meth:`start_full`, :meth:`finish_full`, :meth:`background`,
:meth:`optimise_pending`), and the merge of a solution into the nodes, the GNC rejections,
the current pose and the map (:meth:`_apply`).
"""

import time

import numpy as np

from usvdrake.systems.slam.graph_slam.poses import between, compose
from usvdrake.systems.slam.pose_graph_solve import (
    PoseGraphProblem,
    PoseGraphSolution,
    SolveFailed,
    solve_pose_graph,
    solved,
    worker,
)


class OptimisationMixin:
    """Window and full-graph optimisation of :class:`GraphSlam`."""

    # --- optimisation ---------------------------------------------------------------------------
    def background(self) -> None:
        """The LeafSystem's slower event: merge the full optimisation started at the last
        event (waiting for it if it is still running) and start the next one, if a loop asked
        for it, in the worker process (``full_in_worker``). The result thus lands one event
        after it started, whatever the machine: the simulation stays deterministic."""
        self.finish_full()
        self.start_full()

    def optimise_pending(self) -> bool:
        """Run the full-graph optimisation a loop closure asked for, here and now, after
        merging one still running. Returns whether one ran."""
        merged = self.finish_full()
        if self.start_full(in_worker=False):
            merged = self.finish_full()
        return merged

    @property
    def full_running(self) -> bool:
        """Whether a full optimisation has started and is not merged yet."""
        return self._full_job is not None

    def start_full(self, in_worker: bool | None = None) -> bool:
        """Start the full-graph optimisation a loop closure asked for, on a snapshot of the
        graph: in the worker process (:func:`pose_graph_solve.worker`) or solved here at
        once, as ``in_worker`` says (default: ``cfg.full_in_worker``). Nothing
        starts while one is running or when none is pending. Its result is merged by
        :meth:`finish_full`. Returns whether one started."""
        if not self.full_pending or self._full_job is not None:
            return False
        problem = self._problem(full=True)
        in_worker = self.cfg.full_in_worker if in_worker is None else in_worker
        job = worker().submit(problem) if in_worker else solved(problem)
        self._full_job = (job, problem, len(self.nodes))
        self.full_pending = False
        return True

    def finish_full(self) -> bool:
        """Merge the running full optimisation's result, waiting for it if need be (the wait
        is logged in ``stats["full_wait_ms"]``, its solve and merge in
        ``stats["full_optimisation_ms"]``). Nodes added since it started move with the last
        node it solved for. A job the worker failed is solved here. Returns whether
        one was merged."""
        if self._full_job is None:
            return False
        job, problem, n_nodes = self._full_job
        self._full_job = None
        t0 = time.perf_counter()
        try:
            solution = job.result()
        except SolveFailed:
            solution = solve_pose_graph(problem)
        t1 = time.perf_counter()
        self._apply(solution, n_nodes)
        self.stats["full_wait_ms"].append((t1 - t0) * 1e3)
        merge_ms = (time.perf_counter() - t1) * 1e3
        self.stats["full_optimisation_ms"].append(solution.solve_ms + merge_ms)
        return True

    def optimise(self, full: bool = False) -> None:
        """LM over the window (or the whole graph) with gtsam, here and now; moves nodes and
        re-renders them."""
        problem = self._problem(full)
        self._apply(solve_pose_graph(problem), len(self.nodes))

    def _problem(self, full: bool) -> PoseGraphProblem:
        """The window's (or the whole graph's) pose graph as plain data: the active nodes'
        constraints (a window's are the list's tail), the nodes outside the window that they
        reach held fixed, as is the oldest active node. In a full optimisation with
        ``loop_gnc`` every loop is a GNC candidate with the ``loop_min_sigma`` floor and
        nothing is robustified; otherwise loops GNC rejected last are left out."""
        n = len(self.nodes)
        active = set(range(n)) if full else set(range(max(0, n - self.cfg.window), n))
        gnc = full and self.cfg.loop_gnc
        loop_floor = np.diag(np.square(self.cfg.loop_min_sigma))
        # a window's constraints are the list's tail (Node.first_constraint): not a scan of
        # the whole list per node, which on Intel's raw log (10 700 nodes) cost minutes
        start = 0 if full else self.nodes[min(active)].first_constraint
        rows, ij, robust, covs, loop_ids, used = [], [], [], [], [], set()
        for n_c in range(start, len(self.constraints)):
            c = self.constraints[n_c]
            if not (c.i in active or c.j in active):
                continue
            candidate = c.kind == "loop" and gnc
            if c.kind == "loop" and not gnc and n_c in self._rejected:
                continue
            z, cov = self._measurement(c)
            rows.append(z)
            ij.append((c.i, c.j))
            robust.append(c.robust)
            covs.append(cov + loop_floor if candidate else cov)
            loop_ids.append(n_c if candidate else -1)
            used.update((c.i, c.j))
        anchor = min(active)
        keys = list(used | {anchor})
        problem = PoseGraphProblem(
            keys=np.array(keys, int),
            poses=np.array([self.nodes[k].pose for k in keys], float).reshape(-1, 3),
            fixed=np.array([k not in active or k == anchor for k in keys], bool),
            i=np.array([a for a, _ in ij], int),
            j=np.array([b for _, b in ij], int),
            z=np.array(rows, float).reshape(-1, 3),
            cov=np.array(covs, float).reshape(-1, 3, 3),
            robust=np.array([r and not gnc for r in robust], bool),
            loop_id=np.array(loop_ids, int),
            alpha=self.cfg.alpha,
            c=self.cfg.c,
            max_iterations=self.cfg.max_iterations,
            gnc_step=self.cfg.gnc_step,
        )
        return problem

    def _apply(self, solution: PoseGraphSolution, n_nodes: int) -> None:
        """Take the solved poses of ``solution`` (of the graph's first ``n_nodes`` nodes);
        the nodes added after it was posed keep their pose relative to the last of those
        nodes. Updates the GNC rejections, the current pose and the map."""
        nodes = self.nodes
        later = range(n_nodes, len(nodes))
        rel = [between(nodes[n_nodes - 1].pose, nodes[k].pose) for k in later]
        for k, pose in zip(solution.keys, solution.poses, strict=True):
            nodes[k].pose = pose.copy()
        for k, r in zip(later, rel, strict=True):
            nodes[k].pose = compose(nodes[n_nodes - 1].pose, r)
        if solution.rejected is not None:
            self._rejected = solution.rejected
            self.stats["rejected_loops"] = len(self._rejected)
        moved = sorted(int(k) for k in solution.keys) + list(later)
        self._sync_xy(moved)
        self.pose = compose(nodes[-1].pose, self._rel)
        # only the nodes just solved for (or carried along) can have moved since their last
        # check
        self._rerender_moved(moved)
