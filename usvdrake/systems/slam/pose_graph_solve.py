"""The planar pose graph's solve as plain data in, plain data out, so that the full-graph
optimisation a loop closure asks for can run in a worker process while the scans keep being
tracked (Pham et al. §II-C runs it in its own thread; gtsam holds Python's lock while it solves, so
here it is a process).

:class:`PoseGraphProblem` is what :class:`graph_slam.GraphSlam` hands over (node poses,
constraints, which loops GNC may reject); :func:`solve_pose_graph` builds the gtsam graph in
the same order every time and solves it by Levenberg-Marquardt (gtsam, at most
``max_iterations`` steps, Pham et al. §V-A) or, with loop candidates, by graduated non-convexity
with the truncated least squares loss (Yang et al. 2020, gtsam's ``GncLMOptimizer``). The same
problem gives the same solution to the bit whether solved here or in :func:`worker`'s process.
"""

import atexit
import os
import pickle
import queue
import struct
import subprocess
import sys
import threading
import time
from dataclasses import dataclass

import gtsam
import numpy as np

from usvdrake.systems.slam.robust_kernel import gtsam_barron

# a prior that holds a node where it is (the window's boundary nodes, the graph's anchor)
FIXED_SIGMAS = (1e-6, 1e-6, 1e-7)


@dataclass(frozen=True)
class PoseGraphProblem:
    """A pose graph to solve. ``keys``: the nodes in it, in the order their values (and the
    fixing priors) are added; ``poses`` (len(keys) × 3) their initial poses; ``fixed`` which of
    them a tight prior holds in place. Constraint r says node ``j[r]`` is at ``z[r]`` in node
    ``i[r]``'s frame with covariance ``cov[r]``; ``robust[r]``: Barron-robustified (``alpha``,
    ``c``); ``loop_id[r]`` ≥ 0: a loop candidate GNC may reject (its id comes back in
    :attr:`PoseGraphSolution.rejected`), −1: a known inlier. GNC runs when any constraint is a
    candidate; ``gnc_step`` the factor its μ moves by between steps."""

    keys: np.ndarray
    poses: np.ndarray
    fixed: np.ndarray
    i: np.ndarray
    j: np.ndarray
    z: np.ndarray
    cov: np.ndarray
    robust: np.ndarray
    loop_id: np.ndarray
    alpha: float = 0.0
    c: float = 1.0
    max_iterations: int = 100
    gnc_step: float = 1.4  # the factor GNC's μ moves by per step (gtsam's default)


@dataclass(frozen=True)
class PoseGraphSolution:
    """``poses`` (len(keys) × 3) of the problem's ``keys`` after the solve; ``rejected`` the
    loop ids GNC left with weight < 0.5 (None: no GNC ran); ``solve_ms`` its wall time."""

    keys: np.ndarray
    poses: np.ndarray
    rejected: frozenset | None
    solve_ms: float


def solve_pose_graph(problem: PoseGraphProblem) -> PoseGraphSolution:
    """Solve ``problem`` (see :class:`PoseGraphProblem`): LM, or GNC-TLS over its loop
    candidates with every other factor a known inlier."""
    t0 = time.perf_counter()
    p = problem
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    robust = gtsam_barron(p.alpha, p.c) if np.any(p.robust) else None
    inliers, loops = [], []
    for r in range(len(p.i)):
        noise = gtsam.noiseModel.Gaussian.Covariance(p.cov[r])
        if p.loop_id[r] >= 0:
            loops.append((int(p.loop_id[r]), graph.size()))
        else:
            inliers.append(graph.size())
            if p.robust[r]:
                noise = gtsam.noiseModel.Robust.Create(robust, noise)
        z = gtsam.Pose2(*p.z[r])
        graph.add(gtsam.BetweenFactorPose2(int(p.i[r]), int(p.j[r]), z, noise))
    fixed = gtsam.noiseModel.Diagonal.Sigmas(np.array(FIXED_SIGMAS))
    for k, pose, hold in zip(p.keys, p.poses, p.fixed, strict=True):
        values.insert(int(k), gtsam.Pose2(*pose))
        if hold:
            inliers.append(graph.size())
            graph.add(gtsam.PriorFactorPose2(int(k), gtsam.Pose2(*pose), fixed))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(p.max_iterations)
    rejected = None
    if loops:
        # graduated non-convexity with the truncated least squares loss (Yang et al. 2020):
        # the loop candidates may be outliers, everything else is a known inlier
        gnc_params = gtsam.GncLMParams(params)
        gnc_params.setLossType(gtsam.GncLossType.TLS)
        gnc_params.setLambdaStep(p.gnc_step)
        gnc_params.setKnownInliers(inliers)
        optimiser = gtsam.GncLMOptimizer(graph, values, gnc_params)
        result = optimiser.optimize()
        weights = np.asarray(optimiser.getWeights())
        rejected = frozenset(n_c for n_c, f in loops if weights[f] < 0.5)
    else:
        result = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    poses = np.empty((len(p.keys), 3))
    for row, k in enumerate(p.keys):
        pose = result.atPose2(int(k))
        poses[row] = pose.x(), pose.y(), pose.theta()
    return PoseGraphSolution(np.asarray(p.keys), poses, rejected, (time.perf_counter() - t0) * 1e3)


class SolveFailed(RuntimeError):
    """The worker process could not return a solution (it died, or the solve raised there)."""


class _Solved:
    """A solution at hand, behind the same ``result()`` as a worker's job."""

    def __init__(self, solution: PoseGraphSolution):
        self._solution = solution

    def result(self) -> PoseGraphSolution:
        return self._solution


def solved(problem: PoseGraphProblem) -> _Solved:
    """``problem`` solved here and now, behind the ``result()`` of a worker's job."""
    return _Solved(solve_pose_graph(problem))


class _WorkerJob:
    """A problem handed to the :class:`PoseGraphWorker`; ``result()`` waits for its solution
    (and keeps it: copies of a SLAM state that share the job may all ask)."""

    def __init__(self, worker: "PoseGraphWorker", job_id: int):
        self._worker, self._id, self._solution = worker, job_id, None

    def result(self) -> PoseGraphSolution:
        if self._solution is None:
            self._solution = self._worker.wait(self._id)
        return self._solution


class PoseGraphWorker:
    """A Python process (running :func:`_serve`) that solves the problems it is sent, in
    order. A plain child process rather than ``multiprocessing``:
    ``spawn`` re-runs the caller's script in the child (every script would need a
    ``__main__`` guard) and ``fork`` copies a process running numba's and gtsam's threads.
    Problems and solutions travel pickled, length-prefixed, over its stdin and stdout, each way
    by a thread of ours, so :meth:`submit` never blocks the caller."""

    def __init__(self):
        self._proc = subprocess.Popen(
            # run by import, not as __main__: its solutions must pickle as this module's classes
            [sys.executable, "-c", f"from {__name__} import _serve; _serve()"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )
        self._outbox: queue.Queue = queue.Queue()
        self._done: dict[int, object] = {}
        self._cv = threading.Condition()
        self._next = 0
        self._alive = True  # until its answers' pipe closes
        threading.Thread(target=self._send, daemon=True).start()
        threading.Thread(target=self._receive, daemon=True).start()

    def submit(self, problem: PoseGraphProblem) -> _WorkerJob:
        with self._cv:
            job_id, self._next = self._next, self._next + 1
        self._outbox.put(pickle.dumps((job_id, problem), pickle.HIGHEST_PROTOCOL))
        return _WorkerJob(self, job_id)

    def wait(self, job_id: int) -> PoseGraphSolution:
        with self._cv:
            self._cv.wait_for(lambda: job_id in self._done or not self._alive)
            answer = self._done.pop(job_id, None)
        if not isinstance(answer, PoseGraphSolution):
            raise SolveFailed(answer or "the pose graph worker process exited")
        return answer

    def close(self) -> None:
        self._outbox.put(None)

    def _send(self) -> None:
        pipe = self._proc.stdin
        try:
            while (frame := self._outbox.get()) is not None:
                _write_frame(pipe, frame)
            pipe.close()
        except OSError:
            self._dead()

    def _receive(self) -> None:
        pipe = self._proc.stdout
        try:  # until the pipe closes or breaks off mid-frame (the worker died)
            while (frame := _read_frame(pipe)) is not None:
                job_id, answer = pickle.loads(frame)
                with self._cv:
                    self._done[job_id] = answer
                    self._cv.notify_all()
        finally:
            self._dead()

    def _dead(self) -> None:
        with self._cv:
            self._alive = False
            self._cv.notify_all()

    @property
    def alive(self) -> bool:
        """Whether it still serves: its process runs and its answers' pipe is open."""
        return self._alive and self._proc.poll() is None


def _write_frame(pipe, frame: bytes) -> None:
    """One message on a pipe: its length (8 bytes, little-endian), then its bytes."""
    pipe.write(struct.pack("<Q", len(frame)) + frame)
    pipe.flush()


def _read_frame(pipe) -> bytes | None:
    """The next message :func:`_write_frame` put on ``pipe``; None when the pipe closed,
    even mid-message (its writer died)."""
    head = pipe.read(8)
    if len(head) != 8:
        return None
    size = struct.unpack("<Q", head)[0]
    frame = pipe.read(size)
    return frame if len(frame) == size else None


_WORKER: PoseGraphWorker | None = None


def worker() -> PoseGraphWorker:
    """The one worker process full optimisations run in, started on first use (~1.5 s to
    import) and replaced if it died; closed at exit."""
    global _WORKER
    if _WORKER is None or not _WORKER.alive:
        _WORKER = PoseGraphWorker()
    return _WORKER


@atexit.register
def _close_worker() -> None:
    if _WORKER is not None:
        _WORKER.close()


def _serve() -> None:
    """The worker's loop: solve each problem read from stdin, answer on stdout (the real
    one: anything printed while solving goes to stderr), until stdin closes."""
    out = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    while (frame := _read_frame(sys.stdin.buffer)) is not None:
        job_id, problem = pickle.loads(frame)
        try:
            answer = solve_pose_graph(problem)
        except Exception as error:  # sent back: the caller solves it itself and sees it
            answer = f"{type(error).__name__}: {error}"
        _write_frame(out, pickle.dumps((job_id, answer), pickle.HIGHEST_PROTOCOL))
