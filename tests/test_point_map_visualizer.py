"""The 3D SLAM map (KeyframeMap) and its Meshcat drawing (KeyframeMapVisualizer)."""

import copy

import numpy as np
import pytest
from pydrake.geometry import Meshcat

from usvdrake.systems.slam.lidar_inertial import KeyframeMap
from usvdrake.viz.point_map_visualizer import KeyframeMapVisualizer, height_colors


def shifted(x: float) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = x
    return T


def two_keyframes() -> KeyframeMap:
    clouds = [np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 2.0]]), np.array([[0.0, 0.0, 5.0]])]
    return KeyframeMap(np.stack([shifted(0.0), shifted(10.0)]), clouds)


def test_keyframe_map_points_and_cheap_copies():
    m = two_keyframes()
    np.testing.assert_allclose(m.points(), [[1, 0, 0], [0, 1, 2], [10, 0, 5]])
    c = copy.deepcopy(m)
    assert c.clouds is m.clouds  # the clouds are shared ...
    c.poses[1] = shifted(20.0)  # ... the poses are not
    assert m.poses[1][0, 3] == 10.0 and len(KeyframeMap()) == 0
    assert KeyframeMap().points().shape == (0, 3)


def test_height_colors_run_blue_to_yellow():
    rgb = height_colors(np.array([-5.0, 3.5, 20.0]))
    assert rgb.shape == (3, 3) and rgb.dtype == np.uint8
    np.testing.assert_array_equal(rgb[:, 0], [0, 0, 255])
    np.testing.assert_array_equal(rgb[:, 2], [255, 255, 0])


def test_visualizer_draws_each_keyframe_once_and_moves_only_what_moved():
    meshcat = Meshcat()
    viz = KeyframeMapVisualizer(meshcat, path="/test/map3d")
    ctx = viz.CreateDefaultContext()
    m = two_keyframes()
    viz.GetInputPort("map").FixValue(ctx, m)
    viz.ForcedPublish(ctx)
    assert meshcat.HasPath("/test/map3d/0") and meshcat.HasPath("/test/map3d/1")
    before = [meshcat._GetPackedTransform(f"/test/map3d/{i}") for i in (0, 1)]
    moved = KeyframeMap(np.stack([shifted(0.001), shifted(10.5)]), m.clouds)  # 1 mm, 0.5 m
    viz.GetInputPort("map").FixValue(ctx, moved)
    viz.ForcedPublish(ctx)
    after = [meshcat._GetPackedTransform(f"/test/map3d/{i}") for i in (0, 1)]
    assert after[0] == before[0]  # below the tolerance: not re-sent
    assert after[1] != before[1]


def test_visualizer_rejects_a_bad_rate():
    with pytest.raises(ValueError, match="rate_hz"):
        KeyframeMapVisualizer(Meshcat(), rate_hz=0.0)
