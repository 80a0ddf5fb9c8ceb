"""A loop candidate's field is built once and kept while its submap is the same
(``LoopMixin._loop_field``): reused only for the same scans at the same poses, never across
copies whose nodes differ, bounded in number, and a run with it equals a run without."""

import copy
import pickle
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

import usvdrake.systems.slam.graph_slam.loops as loops
from usvdrake.run.slam2d import LOG_CONFIG, run_slam2d
from usvdrake.systems.slam.graph_slam import GraphSlam, GraphSlamConfig, Node
from usvdrake.systems.slam.likelihood_field import LikelihoodField

DATA = Path(__file__).parent / "data" / "carmen"


def _slam(n: int = 6, seed: int = 0) -> GraphSlam:
    """n nodes 0.2 m apart along x, each with its own random 'room' of points."""
    cfg = GraphSlamConfig(loop_linear_window=1.0, loop_submap=1)
    slam = GraphSlam(cfg)
    rng = np.random.default_rng(seed)
    for k in range(n):
        pts = rng.uniform(-4.0, 4.0, (300, 2))
        node = Node(np.array([0.2 * k, 0.0, 0.01 * k]), pts, np.ones(300), np.zeros(300), k)
        node.tree = cKDTree(pts)
        slam.nodes.append(node)
    return slam


def _fresh(slam: GraphSlam, i: int) -> LikelihoodField:
    cfg, h = slam.cfg, slam.cfg.loop_submap
    return LikelihoodField.build(
        slam._submap(i, range(i - h, i + h + 1)),
        cfg.search_resolution,
        cfg.search_sigma,
        margin=cfg.loop_linear_window + 1.0,
    )


def test_the_same_submap_is_built_once_and_equals_a_fresh_build():
    slam = _slam()
    submap, field = slam._loop_field(2)
    again_submap, again = slam._loop_field(2)
    assert again is field and again_submap is submap
    assert slam.stats["loop_fields_reused"] == 1
    fresh = _fresh(slam, 2)
    np.testing.assert_array_equal(field.fine, fresh.fine)
    np.testing.assert_array_equal(field.top2, fresh.top2)


def test_a_moved_neighbour_or_another_copys_scans_rebuild_it():
    slam = _slam()
    _, field = slam._loop_field(2)
    slam.nodes[3].pose[0] += 0.01  # moved in place, as an optimisation's merge may
    _, moved = slam._loop_field(2)
    assert moved is not field
    np.testing.assert_array_equal(moved.fine, _fresh(slam, 2).fine)

    other = copy.deepcopy(slam)  # shares the cache
    assert other._loop_fields is slam._loop_fields
    twin = copy.copy(other.nodes[1])  # same pose, other scan: a copy that went its own way
    twin.points = twin.points[::-1] * 0.9
    other.nodes[1] = twin
    _, theirs = other._loop_field(2)
    assert theirs is not moved
    np.testing.assert_array_equal(theirs.fine, _fresh(other, 2).fine)
    assert slam._loop_field(2)[1] is moved  # the original's field is still its own


def test_a_pickled_slam_rebuilds_rather_than_trusting_stale_ids():
    slam = _slam()
    _, field = slam._loop_field(2)
    loaded = pickle.loads(pickle.dumps(slam))
    # the same scans at the same poses: a key built from the old ids must not be trusted
    for key in list(loaded._loop_fields):
        entry = loaded._loop_fields.pop(key)
        ids = tuple(id(n.points) for n in loaded.nodes[1:4])
        loaded._loop_fields[(key[0], key[1], ids)] = ([p.copy() for p in entry[0]], *entry[1:])
    before = loaded.stats["loop_fields_reused"]
    _, rebuilt = loaded._loop_field(2)
    assert loaded.stats["loop_fields_reused"] == before
    np.testing.assert_array_equal(rebuilt.fine, field.fine)


def test_the_cache_keeps_the_last_used_only(monkeypatch):
    monkeypatch.setattr(loops, "LOOP_FIELDS", 2)
    slam = _slam(8)
    for i in (1, 2, 3, 1):
        slam._loop_field(i)
    assert len(slam._loop_fields) == 2
    assert slam.stats["loop_fields_reused"] == 0  # 1 was evicted by 3 before it came again
    slam._loop_field(1)
    assert slam.stats["loop_fields_reused"] == 1


def test_a_run_reusing_fields_equals_one_building_each(monkeypatch, tmp_path):
    """Intel's first 200 raw scans on LOG_CONFIG (loops searched from node 15 on): the same
    trajectory, to the bit, with every field built afresh."""
    cfg = replace(LOG_CONFIG, full_in_worker=False)
    trajectories = {}
    for kept in (0, 16):
        monkeypatch.setattr(loops, "LOOP_FIELDS", kept)
        out = tmp_path / str(kept)
        m = run_slam2d(DATA / "intel-first200.clf.bz2", out, progress=False, config=cfg)
        assert (m["loop_fields_reused"] > 0) == (kept > 0)
        trajectories[kept] = (out / "trajectory.tum").read_bytes()
    assert trajectories[16] == trajectories[0]
