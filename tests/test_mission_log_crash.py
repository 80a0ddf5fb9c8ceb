"""A mission log survives its writer being killed: all but (at most) the last second is on disk.

The child writes small messages stamped with the wall clock (20 per second, ~1.5 kB/s: far less
than Python's 8 kB file buffer, so without the writer's own flushing nothing would reach the
file in the 2 s before the kill)."""

import json
import os
import signal
import subprocess
import sys
import time

from mcap.reader import make_reader

from usvdrake.logs.mission_log import MissionLogWriter, log_summary, read_mission_log

CHILD = """
import sys, time
from usvdrake.logs.mission_log import MissionLogWriter

path, burst = sys.argv[1], int(sys.argv[2])
w = MissionLogWriter(path)
print("ready", flush=True)
k = 0
while True:
    if burst == 0 or k < burst:  # burst > 0: write that many messages, then stay quiet
        w.write_vector("/tick", time.time(), [k], ["k"])
        k += 1
    time.sleep(0.05)
"""


def _run_and_kill(path, burst: int, seconds: float) -> float:
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path), str(burst)],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert child.stdout.readline().strip() == "ready"
        time.sleep(seconds)
        killed_at = time.time()
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.kill()
        child.wait(timeout=10)
    assert child.returncode == -signal.SIGKILL
    return killed_at


def test_sigkill_while_writing_loses_at_most_the_last_second(tmp_path):
    log = tmp_path / "log.mcap"
    killed_at = _run_and_kill(log, burst=0, seconds=2.0)
    ticks = [(t, m["k"]) for _, t, m in read_mission_log(log)]
    assert ticks, "nothing reached the file"
    assert [k for _, k in ticks] == list(range(len(ticks)))  # every message up to the cut
    assert ticks[-1][0] >= killed_at - 1.0  # ... and the cut is less than a second old
    assert ticks[-1][0] <= killed_at
    s = log_summary(log)
    assert not s["complete"] and s["messages"] == len(ticks)
    assert s["topics"]["/tick"]["schema"] == "usvdrake.Vector.tick"


def test_sigkill_after_a_quiet_second_loses_nothing(tmp_path):
    """The last messages before a pause are flushed by the writer's timer, not the next write."""
    log = tmp_path / "log.mcap"
    killed_at = _run_and_kill(log, burst=10, seconds=2.0)
    ticks = [(t, m["k"]) for _, t, m in read_mission_log(log)]
    assert [k for _, k in ticks] == list(range(10))
    assert ticks[-1][0] <= killed_at - 1.0
    assert not log_summary(log)["complete"]


def _mcap_package_messages(log) -> list[tuple[float, int]]:
    """(log time, k) of every message, read by the ``mcap`` package's own reader (it seeks to
    the footer first: a file cut mid-record makes it raise)."""
    with open(log, "rb") as f:
        return [
            (m.log_time * 1e-9, json.loads(m.data)["k"])
            for _, _, m in make_reader(f).iter_messages()
        ]


def test_the_mcap_package_reads_a_killed_log_up_to_the_last_second(tmp_path):
    log = tmp_path / "log.mcap"
    killed_at = _run_and_kill(log, burst=0, seconds=2.0)
    ticks = _mcap_package_messages(log)
    assert ticks and [k for _, k in ticks] == list(range(len(ticks)))
    assert killed_at - 1.0 <= ticks[-1][0] <= killed_at
    assert len(ticks) == len(list(read_mission_log(log)))  # ours reads the same


def test_a_closed_log_is_complete_and_indexed(tmp_path):
    log = tmp_path / "log.mcap"
    with MissionLogWriter(log) as w:
        for k in range(5):
            w.write_vector("/tick", 0.1 * k, [k], ["k"])
    assert log_summary(log)["complete"]
    with open(log, "rb") as f:
        reader = make_reader(f)
        assert reader.get_summary().statistics.message_count == 5
    assert [k for _, k in _mcap_package_messages(log)] == list(range(5))
