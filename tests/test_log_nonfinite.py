"""A non-finite value reaching the mission log is logged as such (JSON null, read back as NaN),
never a crash of the run (JSON has no NaN: the writer used to raise "Out of range float values
are not JSON compliant")."""

import math

import numpy as np

from usvdrake.logs.mission_log import MissionLogWriter, read_log_states, read_log_vectors


def test_nan_and_inf_are_logged_and_read_back_as_nan(tmp_path):
    path = tmp_path / "log.mcap"
    with MissionLogWriter(path) as writer:
        writer.write_state("/ground_truth", 0.0, [0.0, math.nan, 1.0, math.inf, 0.0, 0.0])
        writer.write_state("/ground_truth", 0.1, [0.1, 0.2, 1.0, 0.5, 0.0, 0.0])
        writer.write_vector("/reference", 0.0, [math.inf, 0.5, -math.inf], ("psi_d", "u_d", "e"))
        writer.write_vector("/reference", 0.1, [0.1, 0.5, 0.2], ("psi_d", "u_d", "e"))
    t, q = read_log_states(path)
    assert np.allclose(t, [0.0, 0.1])
    assert math.isnan(q[0, 1]) and math.isnan(q[0, 3]) and q[0, 2] == 1.0
    np.testing.assert_array_equal(q[1], [0.1, 0.2, 1.0, 0.5, 0.0, 0.0])
    t, v, names = read_log_vectors(path, "/reference")
    assert names == ["psi_d", "u_d", "e"]
    assert math.isnan(v[0, 0]) and v[0, 1] == 0.5 and math.isnan(v[0, 2])
    np.testing.assert_array_equal(v[1], [0.1, 0.5, 0.2])
