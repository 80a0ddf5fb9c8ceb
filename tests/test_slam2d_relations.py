"""bench/slam2d_relations.py's bookkeeping (its ICP, open3d's, is a bench dependency): which
pairs become relations, and each trajectory's error on them, with a registration whose answer
is known."""

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))
from slam2d_relations import candidate_pairs, relation_errors, summary  # noqa: E402

from usvdrake.systems.slam.graph_slam.poses import between  # noqa: E402


def _square(n: int = 40) -> np.ndarray:
    """Poses round a 4 m square, twice (the second lap over the first)."""
    s = np.linspace(0.0, 2.0, n, endpoint=False) % 1.0 * 16.0
    side = (s // 4).astype(int)
    along = s % 4
    x = np.choose(side, [along, np.full_like(s, 4.0), 4.0 - along, np.zeros_like(s)])
    y = np.choose(side, [np.zeros_like(s), along, np.full_like(s, 4.0), 4.0 - along])
    return np.column_stack([x, y, side * np.pi / 2])


def _settled_by(truth):
    """A registration the scans settle: the true relation wherever it starts."""
    return lambda i, j, guess: (between(truth[i], truth[j]), 1.0, 0.01)


def test_each_trajectory_is_scored_on_the_relations_and_a_wrong_pose_shows():
    truth = _square()
    times = np.arange(len(truth)) * 2.0
    ref = truth.copy()
    ref[10] += [0.1, 0.0, 0.0]  # the reference off by 10 cm at one scan
    local, loop = candidate_pairs(times, truth, ref, loop_gap=30.0)
    assert local[:2] == [(0, 1), (1, 2)] and len(local) == len(truth) - 1
    assert (0, 20) in loop and (5, 25) in loop  # the same place a lap later
    assert all(times[j] - times[i] >= 30.0 for i, j in loop)
    rows = relation_errors(local, truth, ref, _settled_by(truth))
    assert len(rows) == len(local)
    assert np.allclose(rows[:, 2:4], 0.0, atol=1e-12)  # ours is the truth
    off = rows[rows[:, 4] > 1e-9]
    assert sorted(off[:, :2].astype(int).tolist()) == [[9, 10], [10, 11]]
    assert np.allclose(off[:, 4], 0.1)
    s = summary(rows, "local")
    assert s["relations_local"] == len(local) and s["ours_local_m"] < 1e-12
    assert s["reference_worse_local"] == 2 and s["ours_worse_local"] == 0


def test_pairs_the_scans_do_not_settle_or_fit_badly_give_no_verdict():
    truth = _square()
    ref = truth + [0.05, 0.0, 0.0]  # a shifted whole: its relative poses are the truth's ...
    ref[3] += [0.3, 0.0, 0.0]  # ... but at scan 3
    pairs = [(2, 3), (3, 4), (6, 7)]
    # ICP that stays where it starts (a corridor's length): the two starts end apart at scan 3
    stays = relation_errors(pairs, truth, ref, lambda i, j, guess: (guess, 1.0, 0.01))
    assert stays[:, :2].astype(int).tolist() == [[6, 7]]
    loose = relation_errors(
        pairs, truth, ref, lambda i, j, g: (between(truth[i], truth[j]), 0.5, 0.01)
    )
    assert len(loose) == 0  # half the points paired
    assert summary(loose, "loop") == {"relations_loop": 0}
